"""The skin patch description and its force calibration, loaded from a TOML file.

File layout (see ``data/patch_7cells.toml``, the default)::

    [patch]
    name = "end-effector-7"
    silence_timeout_s = 0.1       # optional, > 0
    force_offset = 0.0            # optional defaults for every cell: number or [3 numbers]
    force_gain = 1.0

    [[cell]]
    id = 1                        # 1..16382 (0 = not connected, 16383 = broadcast)
    position_mm = [0.0, 0.0, 0.0]
    force_offset = [0.01, 0.02, 0.0]   # optional per-cell override
    force_gain = 2.0                   # optional per-cell override (> 0)

Force calibration model, per cell and force sensor: ``newtons = gain * (normalised - offset)``
where ``normalised = raw / 1024``. The simulator uses the same model in reverse
(:meth:`ForceCalibration.to_normalised`).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from aptkt.errors import ConfigError, InvalidInputError
from aptkt.skin.protocol import RAW_RANGES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = [
    "CellConfig",
    "PatchConfig",
    "ForceCalibration",
    "load_patch",
    "default_patch",
    "DEFAULT_PATCH_FILE",
]

#: Name of the default patch file shipped in the package (``aptkt/skin/data``).
DEFAULT_PATCH_FILE = "patch_7cells.toml"

#: The largest cell id the wire carries (the protocol's table; it is the broadcast id).
((_, _MAX_CELL_ID),) = RAW_RANGES["cell_id"]


@dataclass(frozen=True)
class CellConfig:
    """One cell of the patch: its id, nominal position and force calibration (3 sensors)."""

    cell_id: int
    position_mm: tuple[float, float, float]
    force_offset: tuple[float, float, float]
    force_gain: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class ForceCalibration:
    """Per-cell, per-sensor affine map between normalised force readings and newtons,
    ``newtons = gain * (normalised - offset)``; ``offset`` and ``gain`` are ``(cells, 3)``.

    Recordings carry it in their metadata as :meth:`to_metadata` (plain JSON);
    :meth:`from_metadata` reads it back.
    """

    cell_ids: tuple[int, ...]
    offset: np.ndarray
    gain: np.ndarray
    #: cell id → row; -1 for cells outside the patch. A table keeps lookups vectorised.
    index: np.ndarray = field(init=False, repr=False)

    MODEL: ClassVar[str] = "newtons = gain * (normalised - offset)"

    def __post_init__(self) -> None:
        cell_ids = tuple(int(c) for c in self.cell_ids)
        n = len(cell_ids)
        object.__setattr__(self, "cell_ids", cell_ids)
        object.__setattr__(self, "offset", np.array(self.offset, dtype=np.float64).reshape(n, 3))
        object.__setattr__(self, "gain", np.array(self.gain, dtype=np.float64).reshape(n, 3))
        index = np.full(_MAX_CELL_ID + 1, -1, dtype=np.intp)
        index[list(cell_ids)] = np.arange(n)
        object.__setattr__(self, "index", index)

    def to_metadata(self) -> dict[str, Any]:
        """The calibration as recordings carry it in their metadata (JSON)."""
        return {
            "model": self.MODEL,
            "cell_ids": list(self.cell_ids),
            "offset": self.offset.tolist(),
            "gain": self.gain.tolist(),
        }

    @classmethod
    def from_metadata(cls, data: Mapping[str, Any] | None) -> ForceCalibration:
        """Inverse of :meth:`to_metadata`; ``ValueError`` if ``data`` is missing or malformed."""
        if not data:
            raise InvalidInputError("the recording's metadata has no 'calibration'")
        try:
            return cls(data["cell_ids"], data["offset"], data["gain"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InvalidInputError(f"the recording's calibration is malformed: {exc}") from None

    def rows(self, cell_id: np.ndarray) -> np.ndarray:
        """Row of each cell id, -1 for cells the patch does not describe."""
        cid = np.asarray(cell_id, dtype=np.intp)
        inside = (cid >= 0) & (cid <= _MAX_CELL_ID)
        return np.where(inside, self.index[np.clip(cid, 0, _MAX_CELL_ID)], -1)

    def checked_rows(self, cell_id: np.ndarray) -> np.ndarray:
        """Like :meth:`rows`; ``ValueError`` naming the cells without a calibration."""
        rows = self.rows(cell_id)
        if (rows < 0).any():
            unknown = sorted(set(np.asarray(cell_id)[rows < 0].tolist()))
            raise InvalidInputError(f"no force calibration for cell(s) {unknown}")
        return rows

    def to_newtons(self, cell_id: np.ndarray, force_norm: np.ndarray) -> np.ndarray:
        """``(n,)`` cell ids and ``(n, 3)`` normalised forces → ``(n, 3)`` newtons."""
        rows = self.checked_rows(cell_id)
        return self.gain[rows] * (np.asarray(force_norm, dtype=np.float64) - self.offset[rows])

    def to_normalised(self, cell_id: np.ndarray, force_n: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_newtons` (what a cell would report for a given force)."""
        rows = self.checked_rows(cell_id)
        return np.asarray(force_n, dtype=np.float64) / self.gain[rows] + self.offset[rows]


@dataclass(frozen=True)
class PatchConfig:
    """The cells a skin source expects, their positions and calibration."""

    name: str
    cells: tuple[CellConfig, ...]
    silence_timeout_s: float = 0.1
    source: str | None = None

    @property
    def cell_ids(self) -> tuple[int, ...]:
        return tuple(c.cell_id for c in self.cells)

    @property
    def positions_mm(self) -> np.ndarray:
        return np.array([c.position_mm for c in self.cells], dtype=np.float64).reshape(-1, 3)

    def calibration(self) -> ForceCalibration:
        return ForceCalibration(
            self.cell_ids,
            np.array([c.force_offset for c in self.cells]),
            np.array([c.force_gain for c in self.cells]),
        )

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], source: str = "<mapping>") -> PatchConfig:
        """Build and validate a patch from parsed TOML; errors name ``source`` and the field."""
        return _Parser(source).patch(data)


def load_patch(path: str | Path) -> PatchConfig:
    """Load a patch TOML file; :class:`~aptkt.errors.ConfigError` names the file and field."""
    path = Path(path)
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read patch file: {exc.strerror or exc}") from exc
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from exc
    return PatchConfig.from_mapping(data, str(path))


def default_patch() -> PatchConfig:
    """The 7-cell end-effector patch shipped with aptkt."""
    res = resources.files("aptkt.skin").joinpath("data").joinpath(DEFAULT_PATCH_FILE)
    with resources.as_file(res) as path:
        return load_patch(path)


class _Parser:
    """Validation of one patch document, field by field."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, field: str, message: str) -> ConfigError:
        return ConfigError(f"{self.source}: {field}: {message}")

    def number(self, field: str, value: Any) -> float:
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
        ):
            raise self.fail(field, f"expected a finite number, got {value!r}")
        return float(value)

    def triple(self, field: str, value: Any, allow_scalar: bool) -> tuple[float, float, float]:
        if allow_scalar and not isinstance(value, (list, tuple)):
            x = self.number(field, value)
            return (x, x, x)
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            what = "a number or a list of 3 numbers" if allow_scalar else "a list of 3 numbers"
            raise self.fail(field, f"expected {what}, got {value!r}")
        a, b, c = (self.number(f"{field}[{i}]", v) for i, v in enumerate(value))
        return (a, b, c)

    def gain(self, field: str, value: Any) -> tuple[float, float, float]:
        g = self.triple(field, value, allow_scalar=True)
        if min(g) <= 0:
            raise self.fail(
                field, f"gains must be > 0 (newtons per normalised unit), got {value!r}"
            )
        return g

    def no_unknown_keys(self, field: str, table: Mapping[str, Any], allowed: set[str]) -> None:
        extra = sorted(set(table) - allowed)
        if extra:
            raise self.fail(
                field, f"unknown key(s) {', '.join(extra)} (allowed: {', '.join(sorted(allowed))})"
            )

    def patch(self, data: Mapping[str, Any]) -> PatchConfig:
        self.no_unknown_keys("(top level)", data, {"patch", "cell"})
        head = data.get("patch", {})
        if not isinstance(head, Mapping):
            raise self.fail("patch", "expected a table [patch]")
        self.no_unknown_keys(
            "patch", head, {"name", "silence_timeout_s", "force_offset", "force_gain"}
        )
        name = head.get("name", Path(self.source).stem)
        if not isinstance(name, str) or not name:
            raise self.fail("patch.name", f"expected a non-empty string, got {name!r}")
        timeout = self.number("patch.silence_timeout_s", head.get("silence_timeout_s", 0.1))
        if timeout <= 0:
            raise self.fail("patch.silence_timeout_s", f"must be > 0, got {timeout}")
        offset = self.triple("patch.force_offset", head.get("force_offset", 0.0), allow_scalar=True)
        gain = self.gain("patch.force_gain", head.get("force_gain", 1.0))

        cells_data = data.get("cell")
        if not isinstance(cells_data, list) or not cells_data:
            raise self.fail("cell", "expected at least one [[cell]] table")
        cells = []
        seen: set[int] = set()
        for i, cell in enumerate(cells_data):
            where = f"cell[{i}]"
            if not isinstance(cell, Mapping):
                raise self.fail(where, "expected a table")
            self.no_unknown_keys(where, cell, {"id", "position_mm", "force_offset", "force_gain"})
            cid = cell.get("id")
            if (
                isinstance(cid, bool)
                or not isinstance(cid, int)
                or not 1 <= cid <= _MAX_CELL_ID - 1
            ):
                raise self.fail(
                    f"{where}.id", f"expected an integer in 1..{_MAX_CELL_ID - 1}, got {cid!r}"
                )
            if cid in seen:
                raise self.fail(f"{where}.id", f"cell id {cid} appears twice")
            seen.add(cid)
            if "position_mm" not in cell:
                raise self.fail(f"{where}.position_mm", "missing")
            cells.append(
                CellConfig(
                    cell_id=cid,
                    position_mm=self.triple(
                        f"{where}.position_mm", cell["position_mm"], allow_scalar=False
                    ),
                    force_offset=self.triple(
                        f"{where}.force_offset", cell.get("force_offset", offset), True
                    ),
                    force_gain=self.gain(f"{where}.force_gain", cell.get("force_gain", gain)),
                )
            )
        return PatchConfig(
            name=name, cells=tuple(cells), silence_timeout_s=timeout, source=self.source
        )
