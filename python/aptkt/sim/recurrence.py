"""First-order linear recurrences ``y[k] = a y[k-1] + x[k]`` evaluated without a Python loop.

Used for the viscoelastic relaxation states. The closed form
``y[k] = a^k (y[0] + Σ_{j<=k} a^-j x[j])`` is evaluated in blocks short enough that ``a^-j``
cannot overflow; the rounding error stays at ``eps |x| / (1 - a)`` whatever the block length.
"""

from __future__ import annotations

import math

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = ["linear_recurrence", "linear_recurrence_rows"]


def linear_recurrence(a: float, x: np.ndarray, y0: np.ndarray | float) -> np.ndarray:
    """``y[k] = a * y[k-1] + x[k]`` for k = 0..n-1 with ``y[-1] = y0``; x has shape (n, ...)."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    y_prev = np.broadcast_to(np.asarray(y0, dtype=np.float64), x.shape[1:]).copy()
    out = np.empty_like(x)
    if n == 0:
        return out
    if not (0.0 < a <= 1.0):
        raise InvalidInputError(f"decay factor must be in (0, 1], got {a}")
    if a == 1.0:
        out[:] = y_prev + np.cumsum(x, axis=0)
        return out
    block = max(1, min(n, int(600.0 / -math.log(a))))
    extra = (1,) * (x.ndim - 1)
    for start in range(0, n, block):
        seg = x[start : start + block]
        m = seg.shape[0]
        k = np.arange(1, m + 1, dtype=np.float64)
        grow = np.power(a, -k).reshape(m, *extra)  # a^-k
        shrink = np.power(a, k).reshape(m, *extra)  # a^k
        # a^k * (y_prev + Σ_{j=1..k} a^-j x_j): the -j and k exponents meet inside the block.
        out[start : start + m] = shrink * (y_prev + np.cumsum(seg * grow, axis=0))
        y_prev = out[start + m - 1]
    return out


def linear_recurrence_rows(a: np.ndarray, x: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """Row-wise ``y[r, k] = a[r] * y[r, k-1] + x[r, k]`` with ``y[r, -1] = y0[r]``.

    ``a`` (R,) in (0, 1]; ``x`` (R, L, ...); ``y0`` (R, ...). Short sequences run as a loop over
    k (vectorised over rows); long ones in overflow-safe blocks as :func:`linear_recurrence`.
    """
    a = np.asarray(a, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    rows, length = x.shape[0], x.shape[1]
    extra = (1,) * (x.ndim - 2)
    ar = a.reshape(rows, *extra)
    out = np.empty_like(x)
    y = np.array(np.broadcast_to(y0, (rows, *x.shape[2:])), dtype=np.float64)
    if length <= 8:
        for step in range(length):
            y = ar * y + x[:, step]
            out[:, step] = y
        return out
    if np.any((a <= 0) | (a > 1)):
        raise InvalidInputError("decay factors must be in (0, 1]")
    worst = float(np.min(a))
    block = length if worst == 1.0 else max(1, min(length, int(600.0 / -math.log(worst))))
    for start in range(0, length, block):
        seg = x[:, start : start + block]
        m = seg.shape[1]
        k = np.arange(1, m + 1, dtype=np.float64)
        logs = np.log(a)[:, None] * k[None, :]  # (R, m)
        grow = np.exp(-logs).reshape(rows, m, *extra)
        shrink = np.exp(logs).reshape(rows, m, *extra)
        out[:, start : start + m] = shrink * (y[:, None] + np.cumsum(seg * grow, axis=1))
        y = out[:, start + m - 1]
    return out
