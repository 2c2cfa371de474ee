"""Feature observations from skin recordings (paper §3.2, Table 2; docs/design.md §4).

=================  ==========================================================================
modality           raw observation of one recording
=================  ==========================================================================
``force``          F̄: mean calibrated normal force over every force sensor, cell and sample
``texture``        TD = [A, M, C, L] of the accelerometers (12 values), from each cell's samples
                   in arrival order
``thermal``        [T̄, ∇T̄] of the LM71 temperature sensors: the cells' mean temperature,
                   averaged in 0.1 s bins (the signal is slow and the LM71 quantises at
                   0.03125 °C; bin means lower the noise the gradient would amplify), and its
                   gradient per bin. Reduced to 10 dimensions by PCA in the pipeline.
=================  ==========================================================================

Which modalities an action yields follows its movement (``ExploratoryAction.modalities``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from aptkt import features
from aptkt.actions import ExploratoryAction
from aptkt.errors import InvalidInputError
from aptkt.learning.observations import Observations
from aptkt.learning.pipeline import SKIN_EXTRACTION
from aptkt.skin.protocol import PACKET_RATE_HZ
from aptkt.skin.samples import Recording

__all__ = ["ExtractionSettings", "observe_recording", "observations_from_recordings"]

#: Index of the LM71 in ``SkinSamples.temp`` (index 0 is the accelerometer's die temperature).
LM71 = 1


class ExtractionSettings:
    """Sampling choices of the extraction (documented defaults)."""

    def __init__(self, rate_hz: float = PACKET_RATE_HZ, thermal_bin_s: float = 0.1) -> None:
        if rate_hz <= 0 or thermal_bin_s <= 0:
            raise InvalidInputError("rates and bin widths must be > 0")
        self.rate_hz = float(rate_hz)
        self.thermal_bin_s = float(thermal_bin_s)

    def to_dict(self) -> dict[str, float]:
        """The settings as stored with extracted features (their cache key)."""
        return {"rate_hz": self.rate_hz, "thermal_bin_s": self.thermal_bin_s}

    def thermal_bins(self, action: ExploratoryAction) -> int:
        return max(int(round(action.duration / self.thermal_bin_s)), 2)


def _thermal(rec: Recording, action: ExploratoryAction, settings: ExtractionSettings) -> np.ndarray:
    n_bins = settings.thermal_bins(action)
    per_bin = max(int(round(settings.thermal_bin_s * settings.rate_hz)), 1)
    # Resample every cell on the nominal grid of exactly n_bins * per_bin steps so that every
    # recording of the action yields the same length, whatever the true packet timing.
    grid = rec.grid("temp", n_steps=n_bins * per_bin)[:, :, LM71]  # (cells, steps)
    binned = grid.reshape(grid.shape[0], n_bins, per_bin).mean(axis=2)
    return features.thermal_curve(binned, axis=-1)


def _acc_per_cell(rec: Recording) -> np.ndarray:
    """Accelerations as (cells, 3, T) in each cell's own sample order. Hjorth parameters only
    need the sequence; interpolating onto a grid would low-pass the vibration near Nyquist.
    Cells are cut to the shortest cell's sample count."""
    per_cell = [rec.samples.acc[rec.samples.cell_id == c] for c in rec.cells]
    n = min(len(a) for a in per_cell)
    if n < 3:
        raise InvalidInputError(f"a texture descriptor needs at least 3 samples per cell, got {n}")
    return np.ascontiguousarray(np.stack([a[:n].T for a in per_cell]))


def observe_recording(
    rec: Recording, action: ExploratoryAction, settings: ExtractionSettings | None = None
) -> dict[str, np.ndarray]:
    """The raw feature observation (modality -> vector) of one recording of ``action``."""
    settings = settings or ExtractionSettings()
    if len(rec.samples) == 0:
        raise InvalidInputError(f"the recording of {action.name!r} holds no samples")
    if rec.silent_cells:
        raise InvalidInputError(
            f"the recording of {action.name!r} has silent cells {list(rec.silent_cells)}: "
            "its features would silently differ from complete recordings"
        )
    out: dict[str, np.ndarray] = {}
    for modality in action.modalities:
        if modality == "force":
            out["force"] = np.array([features.mean_force(rec.samples.force)])
        elif modality == "texture":
            out["texture"] = features.texture_descriptor(_acc_per_cell(rec))
        elif modality == "thermal":
            out["thermal"] = _thermal(rec, action, settings)
        else:
            raise InvalidInputError(f"no extractor for modality {modality!r}")
    return out


def observations_from_recordings(
    action: ExploratoryAction,
    recordings: Iterable[tuple[str, int, Recording]],
    settings: ExtractionSettings | None = None,
) -> Observations:
    """Observations of one action from ``(object, trial, recording)`` triples."""
    rows: list[Mapping[str, np.ndarray]] = []
    objects, trials = [], []
    for obj, trial, rec in recordings:
        rows.append(observe_recording(rec, action, settings))
        objects.append(obj)
        trials.append(trial)
    if not rows:
        raise InvalidInputError(f"no recordings of action {action.name!r}")
    mods = {m: np.stack([r[m] for r in rows]) for m in rows[0]}
    return Observations(action.name, mods, np.asarray(objects), np.asarray(trials), SKIN_EXTRACTION)
