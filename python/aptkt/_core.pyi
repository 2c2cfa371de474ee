"""Type stubs of the compiled extension ``aptkt._core`` (Rust). Use the Python wrappers
(:mod:`aptkt.features`, :mod:`aptkt.gp`, :mod:`aptkt.skin`) rather than these functions."""

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__version__: str
TEXTURE_DIM: int

class AptktError(Exception): ...
class KernelNotPositiveDefiniteError(AptktError): ...

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
    def latent(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
    def log_marginal_likelihood(
        self, theta: NDArray[np.float64], gradient: bool
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]: ...
    @property
    def theta(self) -> NDArray[np.float64]: ...
    @property
    def log_marginal_likelihood_value(self) -> NDArray[np.float64]: ...
    @property
    def jitter(self) -> NDArray[np.float64]: ...
    @property
    def optimizer_converged(self) -> list[bool]: ...
    @property
    def newton_converged(self) -> list[bool]: ...
    @property
    def evaluations(self) -> list[int]: ...
    @property
    def n_classifiers(self) -> int: ...
    @property
    def transfer(self) -> bool: ...

def fit_gpc(
    x: NDArray[np.float64],
    labels: NDArray[np.int64],
    n_classes: int,
    sources: Sequence[tuple[NDArray[np.float64], float] | None],
    modalities: Sequence[Sequence[int]],
    signal_variance: float,
    length_scales: Sequence[float],
    weights: Sequence[float],
    free: tuple[bool, bool, bool, bool],
    signal_variance_bounds: tuple[float, float],
    length_scale_bounds: tuple[float, float],
    optimize: bool,
    n_restarts: int,
    seed: int,
    max_iter: int,
    newton_max_iter: int,
    newton_tol: float,
    max_jitter: float,
    predictive: str,
    n_threads: int,
    thetas: NDArray[np.float64] | None = None,
) -> GpcModel: ...
def kernel_matrix(
    x: NDArray[np.float64],
    theta: Sequence[float],
    modalities: Sequence[Sequence[int]],
    n_source: int = 0,
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
