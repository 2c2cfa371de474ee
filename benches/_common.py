"""Helpers shared by the benchmark scripts: timing, machine description, result files."""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).parent / "results"


def best_of(fn: Callable[[], Any], repeat: int = 3, min_time: float = 0.0) -> float:
    """Best wall time of `repeat` runs (each run repeated until `min_time` has passed)."""
    times = []
    for _ in range(repeat):
        loops, start = 0, time.perf_counter()
        while True:
            fn()
            loops += 1
            elapsed = time.perf_counter() - start
            if elapsed >= min_time:
                break
        times.append(elapsed / loops)
    return min(times)


def median_of(fn: Callable[[], Any], repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


#: The reference workload's version: its figures compare only with those of the same version.
REFERENCE_VERSION = 1


def reference_workload() -> float:
    """A fixed CPU workload, independent of aptkt, to express a CPU time as a ratio to: CPU-ms
    differ between machines by 1.3-1.7x, and by 10-20 % on one machine with its load, a ratio to
    work run beside it in the same process much less. Half compiled numerics (eigen-decompositions
    of a 24x24 matrix, elementwise float64 over 4,096 values), half the interpreter (a dict loop,
    numpy calls on 16-value slices): the mix of a simulated trial, whose cost is the compiled
    core's time steps and the Python and numpy glue around them, so that both answer alike to
    what differs between machines (clock, caches, vector units, the interpreter's build). Run it
    under one BLAS thread, as trials are: idle BLAS threads spin and count as CPU time.
    About 40 CPU-ms on the 2-core VM of benches/README.md. Never change it without raising
    REFERENCE_VERSION."""
    import numpy as np

    rng = np.random.default_rng(20261128)
    a = rng.standard_normal((24, 24))
    sym = a @ a.T
    x = rng.standard_normal(4096)
    acc = 0.0
    for _ in range(80):
        acc += float(np.linalg.eigh(sym)[0][0])
    y = x
    for _ in range(400):
        y = np.tanh(y * 0.9 + 0.1)
    counts: dict[int, int] = {}
    for i in range(80_000):
        k = i & 255
        counts[k] = counts.get(k, 0) + i
    for i in range(4000):
        acc += float(x[i : i + 16].sum())
    return acc + float(y[0]) + len(counts)


def spread(values: list[float]) -> dict[str, float]:
    """Median and range."""
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def machine() -> dict[str, Any]:
    return {
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
    }


def save(name: str, payload: dict[str, Any]) -> Path:
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}.json"
    payload = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M"), **payload}
    path.write_text(json.dumps(payload, indent=2))
    return path


def table(rows: list[dict[str, Any]], columns: list[str]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c, "")) for c in columns) + " |")
    return "\n".join(lines)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
    return str(v)
