"""The public BioTac sliding data set (Gao et al., "Supervised autoencoder joint learning on
heterogeneous tactile sensory data", GitHub ``dexrob/BioTac_slide_20_50``) as a feature table.

The set holds 20 materials (``mat1`` … ``mat20``), each slid over 50 times by a SynTouch BioTac
on a robot arm. Every trial is one CSV file ``raw_data/matX/matX_N_bio.csv`` of the sensor's
100 Hz frames: a timestamp, the fluid temperature (TDC), its rate of change (TAC), the fluid
pressure (PDC), 22 samples of the dynamic pressure (PAC, 2.2 kHz) and the 19 electrode
impedances. One trial becomes one row of a feature table (docs/feature-tables.md) of the
action ``slide``, with four modalities — each a separate physical channel of the finger, so
that the multi-modal kernel can weigh them against each other:

``vibration`` (3)
    Hjorth activity (log10), mobility and complexity of the PAC signal: the vibration the
    texture excites while sliding — the same descriptors as the skin's accelerometer texture.
``pressure`` (2)
    Mean and standard deviation of PDC: how hard the finger pressed on the material and how
    much the contact force fluctuated (stick-slip).
``temperature`` (3)
    Mean TDC, its slope (least squares, per second) and mean TAC: heat flowing from the warm
    finger into the material — its thermal conductivity.
``electrodes`` (19)
    The mean of each electrode impedance: how the finger's skin deformed, which tells the
    contact area, the shear of friction and the material's compliance.

The data set has no licence: aptkt reads a copy the user obtained, and nothing of it is part of
aptkt.
"""

from __future__ import annotations

import math
import re
from array import array
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from aptkt.errors import RawDataError
from aptkt.features import MAX_MAGNITUDE, hjorth
from aptkt.files import open_regular
from aptkt.learning.observations import Observations

__all__ = [
    "ACTION",
    "COLUMNS",
    "MODALITIES",
    "TrialFile",
    "find_trials",
    "read_trial",
    "trial_features",
    "import_biotac_slide",
]

#: The one exploratory action of the data set.
ACTION = "slide"
#: Dynamic-pressure samples per 100 Hz frame (2.2 kHz).
PAC_PER_FRAME = 22
N_ELECTRODES = 19
#: The columns of a ``*_bio.csv`` file, in order.
COLUMNS: tuple[str, ...] = (
    "timestamp",
    "tdc",
    "tac",
    "pdc",
    *(f"pac{k}" for k in range(1, PAC_PER_FRAME + 1)),
    *(f"ele{k}" for k in range(1, N_ELECTRODES + 1)),
)
#: Feature dimensions of each modality, in the order of the table's columns.
MODALITIES: dict[str, int] = {"vibration": 3, "pressure": 2, "temperature": 3, "electrodes": 19}
#: Fewest frames a trial must hold (0.5 s): fewer cannot be a slide, only a broken recording.
MIN_FRAMES = 50
#: Largest trial number (the set's are 1 to 50).
MAX_TRIAL_NUMBER = 999_999_999
#: Largest trial file read. The set's files hold a few seconds of frames (under 1 MB); this
#: leaves room for minutes of them while a wrong file (a disk image, /dev/zero behind a link)
#: is refused before it is read.
MAX_TRIAL_BYTES = 64 << 20
#: Longest line read: a frame's 45 numbers take under 1 kB.
MAX_LINE_BYTES = 64 << 10

_TRIAL = re.compile(r"^(mat\d+)_(\d+)_bio\.csv$")


@dataclass(frozen=True)
class TrialFile:
    material: str
    trial: int
    path: Path


def find_trials(directory: str | Path) -> list[TrialFile]:
    """Every ``matX/matX_N_bio.csv`` below ``directory`` (the repository or its ``raw_data``),
    sorted by material number and trial. Two files of one trial (``mat1_01_bio.csv`` and
    ``mat1_1_bio.csv``) are an error naming both: the table would hold the trial twice."""
    root = Path(directory)
    if not root.is_dir():
        raise RawDataError(f"{root}: no such directory")
    base = root / "raw_data" if (root / "raw_data").is_dir() else root
    found: dict[tuple[str, int], TrialFile] = {}
    for folder in base.iterdir():
        if not (folder.is_dir() and re.fullmatch(r"mat\d+", folder.name)):
            continue
        for path in folder.iterdir():
            m = _TRIAL.match(path.name)
            if m and m.group(1) == folder.name:
                if len(m.group(2).lstrip("0")) > 9:  # (a table stores trial numbers as integers)
                    raise RawDataError(
                        f"{path}: trial number {m.group(2)[:30]} is beyond {MAX_TRIAL_NUMBER}"
                    )
                trial = TrialFile(m.group(1), int(m.group(2)), path)
                key = (trial.material, trial.trial)
                if key in found:
                    first, second = sorted((found[key].path, path))
                    raise RawDataError(
                        f"{first} and {second} are both trial {trial.trial} of "
                        f"{trial.material}: keep one of them"
                    )
                found[key] = trial
    if not found:
        raise RawDataError(
            f"{root}: no BioTac trials (expected raw_data/matX/matX_N_bio.csv files, as in the "
            "repository dexrob/BioTac_slide_20_50)"
        )
    return sorted(found.values(), key=lambda t: (int(t.material[3:]), t.trial))


def read_trial(path: str | Path) -> np.ndarray:
    """The frames of one ``*_bio.csv`` file, (frames, len(COLUMNS)), checked: a regular file of
    at most :data:`MAX_TRIAL_BYTES`, read line by line (no line longer than
    :data:`MAX_LINE_BYTES`), the header, one finite number per cell within
    ±:data:`aptkt.features.MAX_MAGNITUDE` (the sensor's readings are 12-bit counts, its
    timestamps seconds since 1970), at least :data:`MIN_FRAMES` frames, increasing timestamps. Every
    problem is a :class:`~aptkt.errors.RawDataError` naming the file and the line."""
    path = Path(path)
    values = array("d")
    frames = 0
    header: list[str] | None = None
    with open_regular(path, MAX_TRIAL_BYTES, RawDataError, "a BioTac trial file") as fh:
        for number, line in _lines(fh, path):
            if not line.strip():
                if number == 1:
                    header = []  # (a blank first line is no header: said at the next line)
                continue
            if not header:
                header = _cells(line) if number == 1 else []
                if tuple(h.strip() for h in header) != COLUMNS:
                    raise RawDataError(
                        f"{path}, line 1: not a BioTac frame header (expected "
                        f"{', '.join(COLUMNS[:5])}, …, {COLUMNS[-1]}; got {_shown(header[:5])}"
                        f"{', …' if len(header) > 5 else ''})"
                    )
                continue
            values.extend(_frame(line, path, number))
            frames += 1
    if not header:
        raise RawDataError(f"{path}: the file is empty")
    if frames < MIN_FRAMES:
        raise RawDataError(f"{path}: {frames} frames; a slide needs at least {MIN_FRAMES} (0.5 s)")
    table = np.frombuffer(values, dtype=np.float64).reshape(frames, len(COLUMNS))
    steps = np.diff(table[:, 0])
    if np.any(steps <= 0):
        at = int(np.flatnonzero(steps <= 0)[0]) + 3
        raise RawDataError(f"{path}, line {at}: the timestamp does not increase")
    return table


def _shown(cells: list[str]) -> str:
    return ", ".join(c if len(c) <= 20 else c[:20] + "…" for c in cells)


def _lines(fh: IO[bytes], path: Path) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of each line, read one at a time, each at most
    :data:`MAX_LINE_BYTES` long."""
    number = 0
    while True:
        raw = fh.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        number += 1
        if len(raw) > MAX_LINE_BYTES:
            raise RawDataError(
                f"{path}, line {number}: longer than {MAX_LINE_BYTES} bytes; a frame of "
                f"{len(COLUMNS)} numbers is far shorter"
            )
        try:
            yield number, raw.decode("utf-8")
        except UnicodeDecodeError:
            raise RawDataError(f"{path}, line {number}: not text (UTF-8)") from None


def _frame(line: str, path: Path, number: int) -> list[float]:
    cells = _cells(line)
    if len(cells) != len(COLUMNS):
        raise RawDataError(
            f"{path}, line {number}: {len(cells)} values, the header has {len(COLUMNS)}"
        )
    try:
        row = [float(c) for c in cells]
    except ValueError:
        bad = next(c for c in cells if not _is_number(c))
        raise RawDataError(f"{path}, line {number}: {bad!r} is not a number") from None
    if not all(math.isfinite(v) for v in row):
        raise RawDataError(f"{path}, line {number}: a value is not finite")
    for column, v in zip(COLUMNS, row):
        if abs(v) > MAX_MAGNITUDE:
            raise RawDataError(
                f"{path}, line {number}, column {column}: {v:g} is beyond ±{MAX_MAGNITUDE:g}, "
                "no reading of a BioTac (its features would not be finite numbers)"
            )
    return row


def _cells(line: str) -> list[str]:
    # The data set's rows end in a comma: an empty last cell that is not a column.
    cells = line.rstrip().split(",")
    return cells[:-1] if cells and cells[-1] == "" else cells


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def trial_features(frames: np.ndarray) -> dict[str, np.ndarray]:
    """The four modalities' feature vectors of one trial's frames (see the module's text)."""
    t = frames[:, 0] - frames[0, 0]
    tdc, tac, pdc = frames[:, 1], frames[:, 2], frames[:, 3]
    pac = frames[:, 4 : 4 + PAC_PER_FRAME].reshape(-1)
    electrodes = frames[:, 4 + PAC_PER_FRAME :]
    activity, mobility, complexity = hjorth(pac)
    if not (activity > 0 and math.isfinite(mobility) and math.isfinite(complexity)):
        raise RawDataError("the vibration (PAC) signal is constant: no texture can be measured")
    slope = float(np.polyfit(t, tdc, 1)[0])
    features = {
        "vibration": np.array([math.log10(activity), mobility, complexity]),
        "pressure": np.array([pdc.mean(), pdc.std()]),
        "temperature": np.array([tdc.mean(), slope, tac.mean()]),
        "electrodes": electrodes.mean(axis=0),
    }
    for name, v in features.items():  # (values within MAX_MAGNITUDE keep them finite)
        if not np.all(np.isfinite(v)):
            raise RawDataError(f"the {name} features are not finite numbers")
    return features


def import_biotac_slide(
    directory: str | Path,
    *,
    materials: Iterable[str] | None = None,
    modalities: Iterable[str] | None = None,
    on_trial: Callable[[TrialFile], None] | None = None,
) -> Observations:
    """Every trial below ``directory`` (or of the given ``materials``) as observations of the
    action ``slide``: objects ``matX``, trials ``N``; every modality of :data:`MODALITIES`, or
    the given ones."""
    chosen = list(MODALITIES) if modalities is None else list(dict.fromkeys(modalities))
    unknown_modalities = [m for m in chosen if m not in MODALITIES]
    if unknown_modalities or not chosen:
        raise RawDataError(
            f"unknown modalities {', '.join(unknown_modalities) or '(none given)'}; the BioTac "
            f"sliding set has {', '.join(MODALITIES)}"
        )
    trials = find_trials(directory)
    if materials is not None:
        wanted = list(dict.fromkeys(materials))
        known = {t.material for t in trials}
        unknown = [m for m in wanted if m not in known]
        if unknown:
            raise RawDataError(
                f"{directory}: no trials of {', '.join(unknown)}; found "
                f"{', '.join(sorted(known, key=lambda m: int(m[3:])))}"
            )
        trials = [t for t in trials if t.material in set(wanted)]
    rows: dict[str, list[np.ndarray]] = {m: [] for m in chosen}
    for trial in trials:
        try:
            features = trial_features(read_trial(trial.path))
        except RawDataError as exc:
            message = str(exc)
            raise RawDataError(
                message if str(trial.path) in message else f"{trial.path}: {message}"
            ) from None
        for m in chosen:
            rows[m].append(features[m])
        if on_trial is not None:
            on_trial(trial)
    return Observations(
        ACTION,
        {m: np.vstack(v) for m, v in rows.items()},
        np.array([t.material for t in trials]),
        np.array([t.trial for t in trials], dtype=np.int64),
    )
