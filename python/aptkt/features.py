"""Tactile feature kernels (paper §3.2, docs/design.md §4), computed in Rust.

Every function accepts float64, float32 and int16 arrays (raw sensor samples), contiguous or
strided, without copying them; other numeric dtypes are converted to float64 first. NaN or
infinity anywhere in the input raises :class:`ValueError` naming the input and the index; finite
input whose result overflows float64 (values near 1e308, whose squares or differences are
infinite) raises :class:`~aptkt.errors.NonFiniteResultError` instead of returning infinity or
NaN.

=========================  ==================================================================
stiffness                  :func:`mean_force` — mean over force sensors, cells and time steps
texture                    :func:`texture_descriptor` — ``[A, M, C, L]`` (12 values), built on
                           :func:`hjorth` and :func:`axis_pair_correlation`
thermal                    :func:`thermal_curve` — ``[T̄, ∇T̄]``, built on
                           :func:`temperature_gradient` (reduced by PCA in the pipeline)
=========================  ==================================================================
"""

from __future__ import annotations

from typing import Any

import numpy as np

from aptkt import _core
from aptkt.errors import InvalidInputError, InvalidTypeError

__all__ = [
    "hjorth",
    "axis_pair_correlation",
    "texture_descriptor",
    "mean_force",
    "temperature_gradient",
    "thermal_curve",
    "TEXTURE_DIM",
    "TEXTURE_NAMES",
    "MAX_MAGNITUDE",
]

#: Largest magnitude of a feature value, or of a raw reading, that aptkt computes with.
#: Statistics square their inputs and sum them (a variance, a distance, a kernel): values up to
#: 1e100 keep every such number finite with room to spare, and no sensor's reading in any unit
#: comes near it. A larger value is refused where it enters (a feature table, an importer),
#: naming its row and column, rather than turning into an overflow and a NaN in a report.
MAX_MAGNITUDE = 1e100

#: Length of the texture descriptor.
TEXTURE_DIM: int = _core.TEXTURE_DIM
#: Names of the texture descriptor's entries, in order.
TEXTURE_NAMES: tuple[str, ...] = (
    "activity_x",
    "activity_y",
    "activity_z",
    "mobility_x",
    "mobility_y",
    "mobility_z",
    "complexity_x",
    "complexity_y",
    "complexity_z",
    "correlation_xy",
    "correlation_yz",
    "correlation_xz",
)

_NATIVE = (np.dtype(np.float64), np.dtype(np.float32), np.dtype(np.int16))


def _samples(x: Any, name: str) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype in _NATIVE:
        return arr
    if arr.dtype.kind not in "biuf":
        raise InvalidTypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def _scalar_or_array(a: np.ndarray) -> Any:
    return float(a) if a.ndim == 0 else a


def hjorth(x: Any, axis: int = -1) -> tuple[Any, Any, Any]:
    """Hjorth activity, mobility and complexity of ``x`` along ``axis``.

    With first differences ``dx`` and ``ddx`` and population variances:
    activity = var(x), mobility = sqrt(var(dx) / var(x)),
    complexity = sqrt(var(ddx) / var(dx)) / mobility — the definitions of antropy's
    ``hjorth_params`` (which returns mobility and complexity only). A constant lane gives NaN
    mobility and complexity (undefined); a variance that overflows raises
    :class:`~aptkt.errors.NonFiniteResultError`. Needs at least 3 samples along ``axis``.

    Returns floats for 1-D input, otherwise three arrays shaped like ``x`` without ``axis``.
    """
    arr = _samples(x, "x")
    if arr.ndim == 0:
        raise InvalidInputError("x must have at least one dimension")
    a, m, c = _core.hjorth(arr, axis, "x")
    return _scalar_or_array(a), _scalar_or_array(m), _scalar_or_array(c)


def axis_pair_correlation(acc: Any, axis: int = -1, channel_axis: int = -2) -> np.ndarray:
    """Pearson correlation of the acceleration axis pairs (x, y), (y, z), (x, z).

    ``acc`` holds the 3 axes along ``channel_axis`` and time along ``axis``. The result drops
    both axes and appends one of length 3 in the order xy, yz, xz. A constant axis gives NaN.
    """
    return _core.axis_pair_correlations(_samples(acc, "acc"), channel_axis, axis, "acc")


def texture_descriptor(acc: Any) -> np.ndarray:
    """The texture descriptor ``TD = [A, M, C, L]`` of one sliding recording.

    ``acc`` has shape (cells, 3, time). Hjorth activity, mobility, complexity of each axis and
    the axis-pair correlations are averaged over cells; see :data:`TEXTURE_NAMES` for the order.
    """
    return _core.texture_descriptor(_samples(acc, "acc"), "acc")


def mean_force(force: Any) -> float:
    """Stiffness feature F̄: mean normal force over every sensor, cell and time step."""
    return _core.mean_all(_samples(force, "force"), "force")


def temperature_gradient(temp: Any, axis: int = -1) -> np.ndarray:
    """Gradient per time step with ``numpy.gradient``'s rule (central inside, one-sided ends)."""
    arr = _samples(temp, "temp")
    if arr.ndim == 0:
        raise InvalidInputError("temp must have at least one dimension")
    return _core.gradient(arr, axis, "temp")


def thermal_curve(temp: Any, axis: int = -1) -> np.ndarray:
    """The thermal observation ``[T̄, ∇T̄]`` before PCA.

    ``T̄`` is the mean over all temperature sensors (every axis but ``axis``) at each time step
    and ``∇T̄`` its :func:`temperature_gradient`; the result has ``2 * n_steps`` values.
    """
    arr = _samples(temp, "temp")
    if arr.ndim == 0:
        raise InvalidInputError("temp must have at least one dimension")
    return _core.thermal_curve(arr, axis, "temp")
