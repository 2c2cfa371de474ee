"""Feature kernels vs antropy (Hjorth) and numpy, side by side.

Usage: python benches/bench_features.py

Throughput of aptkt.features.hjorth against antropy.hjorth_params on a (7 cells x 3 axes x 5000)
float64 array (what one 20 s slide at 250 Hz records), plus the texture descriptor against the
equivalent numpy/antropy composition.
"""

from __future__ import annotations

import antropy
import numpy as np
from _common import best_of, save, table

from aptkt import features


def numpy_texture(acc: np.ndarray) -> np.ndarray:
    mob, com = antropy.hjorth_params(acc, axis=-1)
    corr = np.array(
        [[np.corrcoef(c)[0, 1], np.corrcoef(c)[1, 2], np.corrcoef(c)[0, 2]] for c in acc]
    )
    return np.concatenate([np.var(acc, axis=-1).mean(0), mob.mean(0), com.mean(0), corr.mean(0)])


def main() -> None:
    rng = np.random.default_rng(0)
    rows = []
    for shape in [(7, 3, 5000), (7, 3, 250), (7, 3, 50_000)]:
        x = rng.normal(size=shape) * 0.01 + 1.0
        mb = x.nbytes / 1e6
        t_ours = best_of(lambda x=x: features.hjorth(x), repeat=5, min_time=0.2)
        t_ref = best_of(lambda x=x: antropy.hjorth_params(x, axis=-1), repeat=5, min_time=0.2)
        rows.append(
            {
                "kernel": "hjorth",
                "shape": "x".join(map(str, shape)),
                "aptkt MB/s": mb / t_ours,
                "antropy MB/s": mb / t_ref,
                "ratio": t_ref / t_ours,
                "aptkt us": t_ours * 1e6,
                "reference us": t_ref * 1e6,
            }
        )
        t_ours = best_of(lambda x=x: features.texture_descriptor(x), repeat=5, min_time=0.2)
        t_ref = best_of(lambda x=x: numpy_texture(x), repeat=5, min_time=0.2)
        rows.append(
            {
                "kernel": "texture_descriptor",
                "shape": "x".join(map(str, shape)),
                "aptkt MB/s": mb / t_ours,
                "antropy MB/s": mb / t_ref,
                "ratio": t_ref / t_ours,
                "aptkt us": t_ours * 1e6,
                "reference us": t_ref * 1e6,
            }
        )
    print(
        table(
            rows,
            ["kernel", "shape", "ratio", "aptkt MB/s", "antropy MB/s", "aptkt us", "reference us"],
        )
    )
    print("saved", save("features", {"rows": rows}))


if __name__ == "__main__":
    main()
