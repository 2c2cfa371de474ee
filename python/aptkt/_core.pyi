"""Type stubs of the compiled extension ``aptkt._core`` (Rust). Use the Python wrappers
(:mod:`aptkt.features`, :mod:`aptkt.gp`, :mod:`aptkt.skin`) rather than these functions."""

from collections.abc import Callable, Sequence
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from typing_extensions import Self

# The names pyo3 added to the module, in the order they were added.
__all__ = [
    "__version__",
    "hjorth",
    "axis_pair_correlations",
    "texture_descriptor",
    "mean_all",
    "gradient",
    "thermal_curve",
    "TEXTURE_DIM",
    "KernelStart",
    "FreeHyperparameters",
    "Search",
    "Laplace",
    "HyperPriors",
    "FitSettings",
    "GpcModel",
    "fit_gpc",
    "fit_gpc_shared",
    "kernel_matrix",
    "available_memory",
    "PatchCells",
    "SurfaceShape",
    "ContactLaw",
    "ForceSensors",
    "TextureField",
    "ContactVibration",
    "TextureCoupling",
    "TextureResponse",
    "Ringing",
    "SlipParams",
    "Surface",
    "CellFrames",
    "Accelerometers",
    "Thermometers",
    "Proximity",
    "ContactHeat",
    "Readout",
    "ForceControl",
    "PhysicsState",
    "MechChunk",
    "Segments",
    "SimThermal",
    "ThermalSystem",
    "ThermalContact",
    "SimContact",
    "ForcePhase",
    "LeanQueue",
    "TickOutcome",
    "HeatKernel",
    "SlipState",
    "sim_texture",
    "sim_slip",
    "_flush_subnormals",
    "StreamParser",
    "_quantize",
    "_to_physical",
    "_encode_sensor_packets",
    "encode_packet_bytes",
    "PACKET_LEN",
    "SENSOR_FIELDS",
    "PACKET_TYPES",
]

__version__: str
TEXTURE_DIM: int

# -- feature kernels --------------------------------------------------------------------------
def hjorth(
    x: NDArray[np.float64] | NDArray[np.float32] | NDArray[np.int16], axis: int, name: str = "x"
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]: ...
def axis_pair_correlations(
    acc: NDArray[np.float64] | NDArray[np.float32] | NDArray[np.int16],
    channel_axis: int,
    time_axis: int,
    name: str = "acc",
) -> NDArray[np.float64]: ...
def texture_descriptor(
    acc: NDArray[np.float64] | NDArray[np.float32] | NDArray[np.int16], name: str = "acc"
) -> NDArray[np.float64]: ...
def mean_all(
    x: NDArray[np.float64] | NDArray[np.float32] | NDArray[np.int16], name: str = "x"
) -> float: ...
def gradient(
    x: NDArray[np.float64] | NDArray[np.float32] | NDArray[np.int16], axis: int, name: str = "x"
) -> NDArray[np.float64]: ...
def thermal_curve(
    temp: NDArray[np.float64] | NDArray[np.float32] | NDArray[np.int16],
    axis: int,
    name: str = "temp",
) -> NDArray[np.float64]: ...

# -- Laplace GPC ------------------------------------------------------------------------------
@final
class GpcModel:
    def predict_proba(self, x: NDArray[np.float64]) -> NDArray[np.float64]: ...
    def predict_proba_binary(self, x: NDArray[np.float64]) -> NDArray[np.float64]: ...
    def latent(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def log_marginal_likelihood(
        self, theta: NDArray[np.float64], gradient: bool, include_prior: bool = False
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]: ...
    @property
    def theta(self) -> NDArray[np.float64]: ...
    @property
    def log_marginal_likelihood_value(self) -> NDArray[np.float64]: ...
    @property
    def latent_offset(self) -> NDArray[np.float64]: ...
    @property
    def log_hyper_prior(self) -> NDArray[np.float64]: ...
    @property
    def jitter(self) -> NDArray[np.float64]: ...
    @property
    def optimizer_converged(self) -> list[bool]: ...
    @property
    def newton_converged(self) -> list[bool]: ...
    @property
    def evaluations(self) -> list[int]: ...
    @property
    def iterations(self) -> list[int]: ...
    @property
    def n_classifiers(self) -> int: ...
    @property
    def transfer(self) -> bool: ...
    @property
    def n_lambdas(self) -> int: ...

@final
class KernelStart:
    def __new__(
        cls,
        modalities: Sequence[Sequence[int]],
        signal_variance: float,
        length_scales: Sequence[float],
        weights: Sequence[float],
    ) -> Self: ...

@final
class FreeHyperparameters:
    def __new__(
        cls,
        signal_variance: bool,
        length_scales: bool,
        weights: bool,
        transfer_lambda: bool,
        tie_length_scales: bool = False,
    ) -> Self: ...

@final
class Search:
    def __new__(
        cls,
        optimize: bool,
        n_restarts: int,
        seed: int,
        max_iter: int,
        optimizer_tol: float,
        signal_variance_bounds: tuple[float, float],
        length_scale_bounds: tuple[float, float],
    ) -> Self: ...

@final
class Laplace:
    def __new__(
        cls,
        newton_max_iter: int,
        newton_tol: float,
        max_jitter: float,
        approximation: str,
        latent_mean: str,
    ) -> Self: ...

@final
class HyperPriors:
    def __new__(
        cls,
        signal_variance: tuple[float, float] | None,
        length_scale: tuple[float, float] | None,
        weight_logit: float | None,
    ) -> Self: ...

@final
class FitSettings:
    def __new__(
        cls,
        *,
        start: KernelStart,
        free: FreeHyperparameters,
        search: Search,
        laplace: Laplace,
        n_threads: int,
        hyper_prior: HyperPriors | None = None,
    ) -> Self: ...

def fit_gpc(
    x: NDArray[np.float64],
    labels: NDArray[np.int64],
    n_classes: int,
    sources: Sequence[Sequence[tuple[NDArray[np.float64], NDArray[np.float64], float]]],
    settings: FitSettings,
    thetas: NDArray[np.float64] | None = None,
    starts: Sequence[Sequence[float] | None] | None = None,
) -> GpcModel: ...
def fit_gpc_shared(
    tasks: Sequence[
        tuple[
            NDArray[np.float64],
            NDArray[np.int64],
            int,
            Sequence[Sequence[tuple[NDArray[np.float64], NDArray[np.float64], float]]],
        ]
    ],
    target: int,
    settings: FitSettings,
) -> GpcModel: ...
def available_memory() -> int | None: ...
def kernel_matrix(
    x: NDArray[np.float64],
    theta: Sequence[float],
    modalities: Sequence[Sequence[int]],
    source_sizes: Sequence[int] = ...,
) -> NDArray[np.float64]: ...

# -- skin protocol ----------------------------------------------------------------------------
PACKET_LEN: int
PACKET_TYPES: dict[str, int]
#: (name, numpy dtype, vector field, ((min, max, scale, offset) per column)) per sensor field
SENSOR_FIELDS: list[tuple[str, str, bool, list[tuple[int, int, float, float]]]]

@final
class StreamParser:
    def __new__(cls) -> Self: ...
    def feed(
        self, data: bytes | bytearray | memoryview, *, raw: bool = False
    ) -> dict[str, NDArray]: ...
    @property
    def stats(self) -> dict[str, int | dict[str, int]]: ...
    @property
    def pending(self) -> int: ...
    def discard_pending(self) -> None: ...
    def reset(self) -> None: ...

def _quantize(
    cell_id: NDArray[np.int64],
    proximity: NDArray[np.float64],
    acc_g: NDArray[np.float64],
    temp_c: NDArray[np.float64],
    force_norm: NDArray[np.float64],
) -> dict[str, NDArray]: ...
def _to_physical(name: str, raw: NDArray[np.uint16] | NDArray[np.int16]) -> NDArray[np.float64]: ...
def _encode_sensor_packets(
    cell_id: NDArray[np.int64],
    proximity: NDArray[np.int64],
    acc: NDArray[np.int64],
    temp: NDArray[np.int64],
    force: NDArray[np.int64],
) -> bytes: ...
def encode_packet_bytes(header: int, payload: bytes) -> bytes: ...

# --- simulated world (aptkt-sim) ---------------------------------------------------------
_Rows = Sequence[Sequence[float]]

def _flush_subnormals(on: bool, previous: int | None = None) -> int: ...

# Settings of one trial's physics (frozen; by keyword or position).
@final
class PatchCells:
    def __new__(
        cls,
        clock_rate: Sequence[float],
        clock_phase: Sequence[float],
        sensor_height: _Rows,
        sensor_xy: Sequence[_Rows],
    ) -> Self: ...

@final
class SurfaceShape:
    def __new__(
        cls,
        centre: tuple[float, float],
        rotation: float,
        surface_z: float,
        tilt: tuple[float, float],
        crown_radius: float,
        waves: _Rows,
        size: tuple[float, float],
    ) -> Self: ...

@final
class ContactLaw:
    def __new__(
        cls,
        delta: Sequence[float],
        sigma: Sequence[float],
        skin_stiffness: float,
        relax_weights: Sequence[float],
        relax_times: Sequence[float],
        sensor_area: float,
    ) -> Self: ...

@final
class ForceSensors:
    def __new__(
        cls,
        noise_key: tuple[int, int],
        gain: _Rows,
        offset: _Rows,
        force_noise: float,
        latency_ns: int,
        jitter_s: float,
    ) -> Self: ...

@final
class TextureField:
    def __new__(cls, kvec: _Rows, amplitude: Sequence[float], phase: Sequence[float]) -> Self: ...

@final
class ContactVibration:
    def __new__(
        cls,
        cover_contact_length: float,
        contact_resonance: float,
        contact_damping: float,
        acc_bandwidth: float,
    ) -> Self: ...

@final
class TextureCoupling:
    def __new__(
        cls,
        coupling_modulus: float,
        coupling_pressure: float,
        tangential_coupling: float,
        lateral_coupling: float,
    ) -> Self: ...

@final
class TextureResponse:
    def __new__(
        cls,
        vibration: ContactVibration,
        coupling: TextureCoupling,
        top_modulus: float,
        mu_kinetic: float,
    ) -> Self: ...

@final
class Ringing:
    def __new__(
        cls, coupling: float, omega: float, decay: float, gain: float, lag: float
    ) -> Self: ...

@final
class SlipParams:
    def __new__(
        cls,
        mu_s: float,
        mu_k: float,
        tangential_stiffness: float,
        tangential_mass: float,
        threshold_sd: float,
        rate_hz: float,
        ring: Ringing,
    ) -> Self: ...

@final
class Surface:
    def __new__(
        cls,
        texture: TextureField,
        response: TextureResponse,
        slip: SlipParams,
        slip_keys: Sequence[tuple[int, int]],
    ) -> Self: ...

@final
class CellFrames:
    def __new__(
        cls,
        centres: _Rows,
        axes: Sequence[_Rows],
        acc_bias: _Rows,
        cell_ids: Sequence[int],
    ) -> Self: ...

@final
class Accelerometers:
    def __new__(
        cls, gravity: float, acc_noise: float, arm_vibration: float, arm_modes: _Rows
    ) -> Self: ...

@final
class Thermometers:
    def __new__(cls, die_self_heating: float, die_temp_noise: float, temp_noise: float) -> Self: ...

@final
class Proximity:
    def __new__(
        cls,
        prox_dark: float,
        prox_gain: float,
        prox_distance: float,
        prox_noise: float,
        reflectivity: float,
        table_reflectivity: float,
    ) -> Self: ...

@final
class ContactHeat:
    def __new__(
        cls,
        contact_pressure_half: float,
        conductance_scale: float,
        contact_steps: float,
        speed_step: float,
    ) -> Self: ...

@final
class Readout:
    def __new__(
        cls,
        cells: CellFrames,
        acc: Accelerometers,
        temp: Thermometers,
        prox: Proximity,
        heat: ContactHeat,
    ) -> Self: ...

@final
class SimThermal:
    def __new__(cls, nodes: int) -> Self: ...
    def __len__(self) -> int: ...

@final
class ThermalSystem:
    def __new__(
        cls,
        u: NDArray[np.float64],
        mu: NDArray[np.float64],
        ss_heater: NDArray[np.float64],
        ss_ambient: NDArray[np.float64],
        ss_object: NDArray[np.float64],
    ) -> Self: ...

@final
class ThermalContact:
    def __new__(
        cls,
        network: SimThermal,
        make: Callable[[int, int], ThermalSystem],
        sqrt_c: Sequence[float],
        heater_power: float,
        ambient: float,
        object_temperature: float,
    ) -> Self: ...

# A trial's state, its samples, its trajectory.
@final
class PhysicsState:
    def copy(self) -> PhysicsState: ...
    @property
    def t_ns(self) -> int: ...
    @property
    def next_k(self) -> NDArray[np.int64]: ...
    @property
    def relax_h(self) -> NDArray[np.float64]: ...
    @property
    def relax_last(self) -> NDArray[np.float64]: ...
    @property
    def latest_force(self) -> NDArray[np.float64]: ...
    @property
    def thermal(self) -> NDArray[np.float64]: ...
    @property
    def thermal_t(self) -> NDArray[np.float64]: ...
    @property
    def last_xy(self) -> NDArray[np.float64]: ...
    @property
    def slip_load(self) -> NDArray[np.float64]: ...
    @property
    def slip_threshold(self) -> NDArray[np.float64]: ...
    @property
    def slip_events(self) -> NDArray[np.int64]: ...
    @property
    def slip_ringing(self) -> list[list[tuple[float, float]]]: ...

@final
class MechChunk:
    @staticmethod
    def concat(chunks: Sequence[MechChunk]) -> MechChunk: ...
    def __len__(self) -> int: ...
    @property
    def size(self) -> int: ...
    @property
    def cells(self) -> NDArray[np.int64]: ...
    @property
    def ks(self) -> NDArray[np.int64]: ...
    @property
    def t_s(self) -> NDArray[np.float64]: ...
    @property
    def t_ns(self) -> NDArray[np.int64]: ...
    @property
    def pos(self) -> NDArray[np.float64]: ...
    @property
    def vel(self) -> NDArray[np.float64]: ...
    @property
    def acc(self) -> NDArray[np.float64]: ...
    @property
    def sigma(self) -> NDArray[np.float64]: ...

@final
class Segments:
    def __new__(
        cls,
        t0: NDArray[np.int64],
        p0: NDArray[np.float64],
        v0: NDArray[np.float64],
        a: NDArray[np.float64],
    ) -> Self: ...
    def __len__(self) -> int: ...
    @property
    def t0(self) -> NDArray[np.int64]: ...
    @property
    def p0(self) -> NDArray[np.float64]: ...
    @property
    def v0(self) -> NDArray[np.float64]: ...
    @property
    def a(self) -> NDArray[np.float64]: ...

# The force loop.
@final
class ForceControl:
    def __new__(
        cls,
        target: float,
        gain: float,
        max_vz: float,
        contact_z: float,
        max_depth: float,
        tick_ns: int,
        wrench_limit: float,
    ) -> Self: ...

@final
class ForcePhase:
    @staticmethod
    def settle(t_limit_ns: int) -> ForcePhase: ...
    @staticmethod
    def ramp(
        t_start_ns: int, t_stop_ns: int, v: float, acc: float, direction: tuple[float, float]
    ) -> ForcePhase: ...
    @staticmethod
    def guard(t_end_ns: int, threshold: float, window_ns: int) -> ForcePhase: ...
    @property
    def guarded(self) -> bool: ...

@final
class LeanQueue:
    samples: int
    def __new__(
        cls,
        cal_gain: NDArray[np.float64],
        cal_offset: NDArray[np.float64],
        latest: NDArray[np.float64],
    ) -> Self: ...
    def push(
        self, t_ns: NDArray[np.int64], cells: NDArray[np.int64], force_norm: NDArray[np.float64]
    ) -> None: ...
    def deliver(self, t_ns: int) -> None: ...
    def reading(self) -> float: ...
    @property
    def latest(self) -> NDArray[np.float64]: ...
    def __len__(self) -> int: ...

@final
class TickOutcome:
    status: str
    error: float
    segment: Segments
    chunk: MechChunk

_Arrays = dict[str, NDArray[Any]]

@final
class SimContact:
    def __new__(
        cls,
        cells: PatchCells,
        shape: SurfaceShape,
        law: ContactLaw,
        sensors: ForceSensors,
        surface: Surface,
        readout: Readout,
        thermal: ThermalContact,
    ) -> Self: ...
    def rest_state(
        self,
        t_ns: int,
        next_k: Sequence[int],
        thermal: Sequence[float],
        last_xy: _Rows,
    ) -> PhysicsState: ...
    def mechanics(self, state: PhysicsState, segments: Segments, t_end_ns: int) -> MechChunk: ...
    def finish(
        self, state: PhysicsState, chunk: MechChunk, detail: bool
    ) -> tuple[_Arrays, _Arrays]: ...
    def step(
        self, state: PhysicsState, segments: Segments, t_end_ns: int, detail: bool
    ) -> tuple[_Arrays, _Arrays]: ...
    def noise(
        self, ks: NDArray[np.int64], cells: NDArray[np.int64], t_ns: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]: ...
    def force_ticks(
        self,
        state: PhysicsState,
        segments: Segments,
        queue: LeanQueue,
        control: ForceControl,
        phase: ForcePhase,
    ) -> TickOutcome: ...

# The loops on their own (the tests compare them with numpy).
@final
class HeatKernel:
    def __new__(
        cls,
        u: NDArray[np.float64],
        mu: NDArray[np.float64],
        t_ss: NDArray[np.float64],
        sqrt_c: NDArray[np.float64],
    ) -> Self: ...
    def heat(
        self,
        cells: NDArray[np.int64],
        t_s: NDArray[np.float64],
        config: NDArray[np.int64],
        state: NDArray[np.float64],
        state_t: NDArray[np.float64],
    ) -> NDArray[np.float64]: ...

def sim_texture(
    texture: TextureField,
    response: TextureResponse,
    u: NDArray[np.float64],
    w: NDArray[np.float64],
    pressure: NDArray[np.float64],
) -> NDArray[np.float64]: ...

@final
class SlipState:
    load: float
    threshold: float
    events: int
    ring: list[tuple[float, float]]
    def __new__(
        cls, load: float, threshold: float, events: int, ring: Sequence[tuple[float, float]]
    ) -> Self: ...

def sim_slip(
    params: SlipParams,
    key: tuple[int, int],
    cell: SlipState,
    t: NDArray[np.float64],
    path: NDArray[np.float64],
    force: NDArray[np.float64],
    speed: NDArray[np.float64],
) -> NDArray[np.float64]: ...
