"""First-order linear recurrences ``y[k] = a y[k-1] + x[k]`` evaluated without a Python loop.

Used for the viscoelastic relaxation states. The closed form
``y[k] = a^k (y[0] + Σ_{j<=k} a^-j x[j])`` is evaluated in blocks short enough that ``a^-j``
cannot overflow; the rounding error stays at ``eps |x| / (1 - a)`` whatever the block length.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["linear_recurrence"]


def linear_recurrence(a: float, x: np.ndarray, y0: np.ndarray | float) -> np.ndarray:
    """``y[k] = a * y[k-1] + x[k]`` for k = 0..n-1 with ``y[-1] = y0``; x has shape (n, ...)."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    y_prev = np.broadcast_to(np.asarray(y0, dtype=np.float64), x.shape[1:]).copy()
    out = np.empty_like(x)
    if n == 0:
        return out
    if not (0.0 < a <= 1.0):
        raise ValueError(f"decay factor must be in (0, 1], got {a}")
    if a == 1.0:
        out[:] = y_prev + np.cumsum(x, axis=0)
        return out
    block = max(1, min(n, int(600.0 / -math.log(a))))
    extra = (1,) * (x.ndim - 1)
    for start in range(0, n, block):
        seg = x[start:start + block]
        m = seg.shape[0]
        k = np.arange(1, m + 1, dtype=np.float64)
        grow = np.power(a, -k).reshape(m, *extra)  # a^-k
        shrink = np.power(a, k).reshape(m, *extra)  # a^k
        # a^k * (y_prev + Σ_{j=1..k} a^-j x_j): the -j and k exponents meet inside the block.
        out[start:start + m] = shrink * (y_prev + np.cumsum(seg * grow, axis=0))
        y_prev = out[start + m - 1]
    return out
