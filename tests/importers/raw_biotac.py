"""A small synthetic data set in the raw format of the public BioTac sliding set (one CSV of
100 Hz frames per trial under raw_data/matX/), for the importer's tests: the real set has no
licence and is never part of the repository."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aptkt.importers.biotac_slide import COLUMNS, PAC_PER_FRAME


def trial_frames(material: int, trial: int, n_frames: int = 80) -> np.ndarray:
    """Frames of one trial: each material has its own pressure, vibration, heat flow and
    electrode pattern; trials differ by noise."""
    rng = np.random.default_rng(1000 * material + trial)
    t = 1581072654.2 + 0.01 * np.arange(n_frames) + rng.uniform(0, 1e-4, n_frames)
    tdc = 1.0 + 0.3 * material * (t - t[0]) + rng.normal(0, 0.2, n_frames)
    tac = 20.0 + 5.0 * material + rng.normal(0, 3, n_frames)
    pdc = 30.0 + 4.0 * material + rng.normal(0, 2 + material, n_frames)
    k = np.arange(n_frames * PAC_PER_FRAME)
    pac = (10 + 5 * material) * np.sin(2 * np.pi * k * (0.02 + 0.01 * material))
    pac = pac + rng.normal(0, 3, k.size)
    electrodes = 10 + material * np.arange(1, 20) % 7 + rng.normal(0, 1, (n_frames, 19))
    return np.column_stack([t, tdc, tac, pdc, pac.reshape(n_frames, PAC_PER_FRAME), electrodes])


def write_trial(path: Path, frames: np.ndarray) -> Path:
    """As the data set writes it: a header, then one line per frame ending in a comma."""
    lines = [",".join(COLUMNS)]
    for row in frames:
        lines.append(
            ",".join(f"{row[0]:.9f}" if i == 0 else f"{v:g}" for i, v in enumerate(row)) + ","
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def write_raw_set(root: Path, materials: int = 4, trials: int = 6) -> Path:
    """``root``/raw_data/matX/matX_N_bio.csv for X in 1..materials, N in 1..trials."""
    for m in range(1, materials + 1):
        for n in range(1, trials + 1):
            write_trial(root / "raw_data" / f"mat{m}" / f"mat{m}_{n}_bio.csv", trial_frames(m, n))
    return root
