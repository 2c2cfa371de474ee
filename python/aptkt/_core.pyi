"""Type stubs of the compiled extension ``aptkt._core`` (Rust). Use the Python wrappers
(:mod:`aptkt.features`, :mod:`aptkt.gp`, :mod:`aptkt.skin`) rather than these functions."""

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__version__: str
TEXTURE_DIM: int

class AptktError(Exception): ...
class KernelNotPositiveDefiniteError(AptktError): ...
class ProblemTooLargeError(AptktError): ...
class NonFiniteResultError(AptktError): ...

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

class FitSettings:
    modalities: list[list[int]]
    signal_variance: float
    length_scales: list[float]
    weights: list[float]
    free_signal_variance: bool
    free_length_scales: bool
    free_weights: bool
    free_lambda: bool
    signal_variance_bounds: tuple[float, float]
    length_scale_bounds: tuple[float, float]
    optimize: bool
    n_restarts: int
    seed: int
    max_iter: int
    optimizer_tol: float
    newton_max_iter: int
    newton_tol: float
    max_jitter: float
    approximation: str
    n_threads: int
    prior_signal_variance: tuple[float, float] | None
    prior_length_scale: tuple[float, float] | None
    prior_weight_logit: float | None
    latent_mean: str
    def __init__(
        self,
        *,
        modalities: Sequence[Sequence[int]],
        signal_variance: float,
        length_scales: Sequence[float],
        weights: Sequence[float],
        free_signal_variance: bool,
        free_length_scales: bool,
        free_weights: bool,
        free_lambda: bool,
        signal_variance_bounds: tuple[float, float],
        length_scale_bounds: tuple[float, float],
        optimize: bool,
        n_restarts: int,
        seed: int,
        max_iter: int,
        optimizer_tol: float,
        newton_max_iter: int,
        newton_tol: float,
        max_jitter: float,
        approximation: str,
        n_threads: int,
        prior_signal_variance: tuple[float, float] | None = None,
        prior_length_scale: tuple[float, float] | None = None,
        prior_weight_logit: float | None = None,
        latent_mean: str = "zero",
    ) -> None: ...

def fit_gpc(
    x: NDArray[np.float64],
    labels: NDArray[np.int64],
    n_classes: int,
    sources: Sequence[Sequence[tuple[NDArray[np.float64], NDArray[np.float64], float]]],
    settings: FitSettings,
    thetas: NDArray[np.float64] | None = None,
    starts: Sequence[Sequence[float] | None] | None = None,
) -> GpcModel: ...
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

class StreamParser:
    def __init__(self) -> None: ...
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
def _encode_sensor_packets(
    cell_id: NDArray[np.int64],
    proximity: NDArray[np.int64],
    acc: NDArray[np.int64],
    temp: NDArray[np.int64],
    force: NDArray[np.int64],
) -> bytes: ...
def encode_packet_bytes(header: int, payload: bytes) -> bytes: ...

# --- simulated world (aptkt-sim) ---------------------------------------------------------
_Chunk = tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]
_Frames = tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]
_Trace = tuple[NDArray, NDArray, NDArray]

def _flush_subnormals(on: bool, previous: int | None = None) -> int: ...

class SimThermal:
    def __init__(self, nodes: int) -> None: ...
    def __len__(self) -> int: ...

class SimContact:
    def __init__(
        self,
        clock_rate: NDArray[np.float64],
        clock_phase: NDArray[np.float64],
        sensor_height: NDArray[np.float64],
        sensor_xy: NDArray[np.float64],
        centre: tuple[float, float],
        rotation: float,
        surface_z: float,
        tilt: tuple[float, float],
        crown_radius: float,
        waves: NDArray[np.float64],
        size: tuple[float, float],
        law_delta: NDArray[np.float64],
        law_sigma: NDArray[np.float64],
        skin_stiffness: float,
        relax_weights: list[float],
        relax_times: list[float],
        sensor_area: float,
        noise_key: tuple[int, int],
        force_gain: NDArray[np.float64],
        force_offset: NDArray[np.float64],
        force_noise: float,
        latency_ns: int,
        jitter_s: float,
        readout: dict[str, Any],
        thermal: SimThermal,
        make: Callable[[int, int], tuple[NDArray, NDArray, NDArray, NDArray, NDArray]],
        sources: tuple[float, float, float],
    ) -> None: ...
    def mechanics(
        self,
        state: Any,
        seg_t0: NDArray[np.int64],
        seg_p0: NDArray[np.float64],
        seg_v0: NDArray[np.float64],
        seg_a: NDArray[np.float64],
        t_end_ns: int,
    ) -> _Chunk: ...
    def finish(
        self,
        state: Any,
        cells: NDArray[np.int64],
        ks: NDArray[np.int64],
        t_s: NDArray[np.float64],
        t_ns: NDArray[np.int64],
        pos: NDArray[np.float64],
        vel: NDArray[np.float64],
        acc: NDArray[np.float64],
        sigma: NDArray[np.float64],
        detail: bool,
    ) -> tuple[_Frames, _Trace]: ...
    def step(
        self,
        state: Any,
        seg_t0: NDArray[np.int64],
        seg_p0: NDArray[np.float64],
        seg_v0: NDArray[np.float64],
        seg_a: NDArray[np.float64],
        t_end_ns: int,
        detail: bool,
    ) -> tuple[_Frames, _Trace]: ...
    def noise(
        self, ks: NDArray[np.int64], cells: NDArray[np.int64], t_ns: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]: ...
    def force_ticks(
        self,
        state: Any,
        seg_t0: NDArray[np.int64],
        seg_p0: NDArray[np.float64],
        seg_v0: NDArray[np.float64],
        seg_a: NDArray[np.float64],
        queue_t: NDArray[np.int64],
        queue_c: NDArray[np.int64],
        queue_f: NDArray[np.float64],
        latest: NDArray[np.float64],
        cal_gain: NDArray[np.float64],
        cal_offset: NDArray[np.float64],
        control: tuple[float, float, float, float, float, int, float],
        phase: tuple[Any, ...],
        samples: int,
    ) -> tuple[Any, ...]: ...

def sim_heat(
    u: NDArray[np.float64],
    mu: NDArray[np.float64],
    t_ss: NDArray[np.float64],
    sqrt_c: NDArray[np.float64],
    cells: NDArray[np.int64],
    t_s: NDArray[np.float64],
    config: NDArray[np.int64],
    state: NDArray[np.float64],
    state_t: NDArray[np.float64],
) -> NDArray[np.float64]: ...
def sim_texture(
    kvec: NDArray[np.float64],
    amplitude: NDArray[np.float64],
    phase: NDArray[np.float64],
    constants: list[float],
    u: NDArray[np.float64],
    w: NDArray[np.float64],
    pressure: NDArray[np.float64],
) -> NDArray[np.float64]: ...
def sim_slip(
    params: list[float],
    key: tuple[int, int],
    load: float,
    threshold: float,
    events: int,
    ring: NDArray[np.float64],
    t: NDArray[np.float64],
    path: NDArray[np.float64],
    force: NDArray[np.float64],
    speed: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float, float, int, NDArray[np.float64]]: ...
