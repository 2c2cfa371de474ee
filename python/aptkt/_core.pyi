"""Type stubs of the compiled extension ``aptkt._core`` (Rust). Use the Python wrappers
(:mod:`aptkt.features`, :mod:`aptkt.gp`, :mod:`aptkt.skin`) rather than these functions."""

from typing import Sequence

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
    newton_max_iter: int
    newton_tol: float
    max_jitter: float
    approximation: str
    n_threads: int
    prior_signal_variance: tuple[float, float] | None
    prior_length_scale: tuple[float, float] | None
    def __init__(
        self,
        *,
        modalities: Sequence[Sequence[int]],
        signal_variance: float = 1.0,
        length_scales: Sequence[float],
        weights: Sequence[float],
        free_signal_variance: bool = True,
        free_length_scales: bool = True,
        free_weights: bool = True,
        free_lambda: bool = False,
        signal_variance_bounds: tuple[float, float] = (1e-5, 1e5),
        length_scale_bounds: tuple[float, float] = (1e-5, 1e5),
        optimize: bool = True,
        n_restarts: int = 2,
        seed: int = 0,
        max_iter: int = 200,
        newton_max_iter: int = 100,
        newton_tol: float = 1e-10,
        max_jitter: float = 1e-6,
        approximation: str = "erf",
        n_threads: int = 0,
        prior_signal_variance: tuple[float, float] | None = None,
        prior_length_scale: tuple[float, float] | None = None,
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
