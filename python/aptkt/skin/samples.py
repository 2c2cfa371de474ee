"""Skin samples in physical units and the recordings exploratory actions produce.

Samples are kept flat, one row per sensor packet in arrival order with a ``cell_id``
column, exactly as the parser emits them; per-cell views and time-aligned grids are derived.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.skin.protocol import RAW_FIELDS

__all__ = ["SkinSamples", "Recording", "FIELDS"]

#: Per-sample fields, their trailing shape and dtype.
FIELDS: Mapping[str, tuple[tuple[int, ...], Any]] = {
    "cell_id": ((), np.uint16),
    "t_ns": ((), np.int64),
    "proximity": ((), np.float64),
    "acc": ((3,), np.float64),  # g
    "temp": ((2,), np.float64),  # °C: accelerometer die, LM71
    "force": ((3,), np.float64),  # N after the per-cell calibration
}


@dataclass
class SkinSamples:
    """A batch of sensor samples (rows) from one or more cells, in arrival order.

    ``raw``, when the samples came off the wire, holds the integers they were converted from
    (the keys of :data:`aptkt.skin.protocol.RAW_FIELDS`, force before calibration): the data
    set store writes those as they are, so a recording is converted to physical units once.
    """

    cell_id: np.ndarray
    t_ns: np.ndarray
    proximity: np.ndarray
    acc: np.ndarray
    temp: np.ndarray
    force: np.ndarray
    raw: Mapping[str, np.ndarray] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = None
        for name, (tail, dtype) in FIELDS.items():
            arr = np.asarray(getattr(self, name), dtype=dtype)
            if arr.shape[1:] != tail:
                raise InvalidInputError(
                    f"SkinSamples.{name}: expected shape (n, {tail}), got {arr.shape}"
                )
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise InvalidInputError(f"SkinSamples.{name}: {arr.shape[0]} rows, expected {n}")
            setattr(self, name, arr)
        if self.raw is not None:
            raw = {}
            for name, (raw_tail, raw_dtype) in RAW_FIELDS.items():
                col = np.asarray(self.raw[name], dtype=raw_dtype)
                if col.shape != (n, *raw_tail):
                    raise InvalidInputError(
                        f"SkinSamples.raw[{name!r}]: shape {col.shape}, expected {(n, *raw_tail)}"
                    )
                raw[name] = col
            self.raw = raw

    def __len__(self) -> int:
        return int(self.cell_id.shape[0])

    @classmethod
    def empty(cls) -> SkinSamples:
        cols: dict[str, Any] = {
            name: np.zeros((0, *tail), dtype) for name, (tail, dtype) in FIELDS.items()
        }
        return cls(**cols)

    @classmethod
    def concat(cls, parts: Iterable[SkinSamples]) -> SkinSamples:
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        raws = [p.raw for p in parts]
        raw = None
        if all(r is not None for r in raws):
            raw = {
                name: np.concatenate([r[name] for r in raws if r is not None])
                for name in RAW_FIELDS
            }
        return cls(
            **{name: np.concatenate([getattr(p, name) for p in parts]) for name in FIELDS}, raw=raw
        )

    def take(self, index: np.ndarray | slice) -> SkinSamples:
        raw = None if self.raw is None else {name: col[index] for name, col in self.raw.items()}
        return SkinSamples(**{name: getattr(self, name)[index] for name in FIELDS}, raw=raw)

    def for_cell(self, cell_id: int) -> SkinSamples:
        return self.take(self.cell_id == cell_id)

    def between(self, start_ns: int, stop_ns: int) -> SkinSamples:
        """Samples that arrived in ``[start_ns, stop_ns)``."""
        return self.take((self.t_ns >= start_ns) & (self.t_ns < stop_ns))

    def as_dict(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in FIELDS}


@dataclass
class Recording:
    """What one exploratory action recorded: the samples of a time window plus context.

    ``cells`` are the patch's cell ids in a fixed order; ``silent_cells`` lists cells of the
    patch that sent nothing (or stopped sending) during the window: they are reported here,
    never zero-filled.
    """

    samples: SkinSamples
    start_ns: int
    stop_ns: int
    cells: tuple[int, ...]
    silent_cells: tuple[int, ...] = ()
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return (self.stop_ns - self.start_ns) * 1e-9

    def grid(
        self,
        field_name: str,
        rate_hz: float | None = None,
        cells: Sequence[int] | None = None,
        *,
        n_steps: int | None = None,
    ) -> np.ndarray:
        """Resample one field onto a common time grid, per cell.

        Give either ``rate_hz`` (``n_steps = round(duration * rate_hz)``, step k at
        ``start + k / rate_hz``) or ``n_steps`` (steps spread evenly over the window). Returns
        an array of shape ``(n_cells, n_steps, *field_shape)``. Each cell is linearly
        interpolated between its own samples (held constant beyond its first and last one).
        Cells without samples raise :class:`ValueError`.
        """
        if (rate_hz is None) == (n_steps is None):
            raise InvalidInputError("give exactly one of rate_hz and n_steps")
        if rate_hz is not None:
            if rate_hz <= 0:
                raise InvalidInputError("rate_hz must be > 0")
            n_steps = max(int(round(self.duration * rate_hz)), 1)
            step_ns = 1e9 / rate_hz
        else:
            assert n_steps is not None  # exactly one of the two was given
            if n_steps < 1:
                raise InvalidInputError("n_steps must be >= 1")
            step_ns = (self.stop_ns - self.start_ns) / n_steps
        t_grid = self.start_ns + np.arange(n_steps) * step_ns
        cells = tuple(self.cells if cells is None else cells)
        values = getattr(self.samples, field_name)
        tail = values.shape[1:]
        out = np.empty((len(cells), n_steps, *tail), dtype=np.float64)
        for i, cid in enumerate(cells):
            mask = self.samples.cell_id == cid
            if not mask.any():
                raise InvalidInputError(f"cell {cid} has no samples in this recording")
            t = self.samples.t_ns[mask].astype(np.float64)
            v = values[mask].reshape(int(mask.sum()), -1)
            flat = np.empty((n_steps, v.shape[1]))
            for j in range(v.shape[1]):
                flat[:, j] = np.interp(t_grid, t, v[:, j])
            out[i] = flat.reshape((n_steps, *tail))
        return out
