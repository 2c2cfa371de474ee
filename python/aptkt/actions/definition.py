"""Exploratory actions as data: a name, a movement and the movement's parameters (SI units).

The paper's seven actions (§5.2) are in :data:`PAPER_ACTIONS`; users define their own with
:class:`ExploratoryAction` or load them from TOML with :func:`actions_from_toml`.
"""

from __future__ import annotations

import enum
import math
import sys
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from aptkt.errors import InvalidInputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = [
    "Movement",
    "ExploratoryAction",
    "PAPER_ACTIONS",
    "MODALITIES_BY_MOVEMENT",
    "actions_from_toml",
    "redefinition",
]


class Movement(str, enum.Enum):
    """How the skin interacts with the object."""

    PRESS = "press"
    SLIDE = "slide"
    STATIC_CONTACT = "static_contact"


#: Which feature modalities each movement yields (docs/design.md §4, paper Table 2).
MODALITIES_BY_MOVEMENT: Mapping[Movement, tuple[str, ...]] = {
    Movement.PRESS: ("force", "thermal"),
    Movement.SLIDE: ("texture", "thermal"),
    Movement.STATIC_CONTACT: ("force", "thermal"),
}

_REQUIRED: Mapping[Movement, tuple[str, ...]] = {
    Movement.PRESS: ("depth", "hold_time"),
    Movement.STATIC_CONTACT: ("depth", "hold_time"),
    Movement.SLIDE: ("normal_force", "speed", "slide_time"),
}


@dataclass(frozen=True)
class ExploratoryAction:
    """One exploratory action with its parameters.

    Units are SI throughout: ``depth`` in m (indentation below the point of light contact),
    ``hold_time`` and ``slide_time`` in s, ``normal_force`` in N, ``speed`` in m/s.
    Parameters that do not belong to the movement must stay at 0 (an error otherwise).
    """

    name: str
    movement: Movement
    depth: float = 0.0
    hold_time: float = 0.0
    normal_force: float = 0.0
    speed: float = 0.0
    slide_time: float = 0.0
    description: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "movement", Movement(self.movement))
        if not self.name or not self.name.strip():
            raise InvalidInputError("an exploratory action needs a non-empty name")
        for key in ("depth", "hold_time", "normal_force", "speed", "slide_time"):
            value = getattr(self, key)
            # A bool is an int to Python: `hold_time = true` would hold for 1 s.
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not math.isfinite(value)
                or value < 0
            ):
                raise InvalidInputError(
                    f"action {self.name!r}: {key} must be a finite number >= 0, got {value!r}"
                )
        for key in _REQUIRED[self.movement]:
            if getattr(self, key) <= 0:
                raise InvalidInputError(
                    f"action {self.name!r}: a {self.movement.value} movement needs {key} > 0"
                )
        # A parameter the movement does not use would be silently ignored: a typo'd action
        # ("speed" on a press) must not run as something else than the user meant.
        unused = [
            k
            for k in ("depth", "hold_time", "normal_force", "speed", "slide_time")
            if k not in _REQUIRED[self.movement] and getattr(self, k) != 0
        ]
        if unused:
            raise InvalidInputError(
                f"action {self.name!r}: a {self.movement.value} movement does not use "
                f"{', '.join(unused)} (it uses {', '.join(_REQUIRED[self.movement])})"
            )

    @property
    def modalities(self) -> tuple[str, ...]:
        """Feature modalities this action yields, in kernel order."""
        return MODALITIES_BY_MOVEMENT[self.movement]

    @property
    def duration(self) -> float:
        """Length of the recording window in seconds (the hold or the slide)."""
        return self.slide_time if self.movement is Movement.SLIDE else self.hold_time

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["movement"] = self.movement.value
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ExploratoryAction:
        known = {f for f in cls.__dataclass_fields__}
        unknown = set(data) - known
        if unknown:
            raise InvalidInputError(
                f"action {data.get('name')!r}: unknown field(s) {sorted(unknown)}"
            )
        return cls(**dict(data))


PAPER_ACTIONS: Mapping[str, ExploratoryAction] = {
    a.name: a
    for a in (
        ExploratoryAction(
            "P1", Movement.PRESS, depth=0.001, hold_time=3.0, description="press 1 mm, hold 3 s"
        ),
        ExploratoryAction(
            "P2", Movement.PRESS, depth=0.002, hold_time=3.0, description="press 2 mm, hold 3 s"
        ),
        ExploratoryAction(
            "S1",
            Movement.SLIDE,
            normal_force=0.1,
            speed=0.01,
            slide_time=5.0,
            description="slide at 0.1 N, 1 cm/s for 5 s",
        ),
        ExploratoryAction(
            "S2",
            Movement.SLIDE,
            normal_force=0.1,
            speed=0.05,
            slide_time=1.0,
            description="slide at 0.1 N, 5 cm/s for 1 s",
        ),
        ExploratoryAction(
            "S3",
            Movement.SLIDE,
            normal_force=0.2,
            speed=0.01,
            slide_time=5.0,
            description="slide at 0.2 N, 1 cm/s for 5 s",
        ),
        ExploratoryAction(
            "S4",
            Movement.SLIDE,
            normal_force=0.2,
            speed=0.05,
            slide_time=1.0,
            description="slide at 0.2 N, 5 cm/s for 1 s",
        ),
        ExploratoryAction(
            "C1",
            Movement.STATIC_CONTACT,
            depth=0.002,
            hold_time=15.0,
            description="static contact 2 mm, hold 15 s",
        ),
    )
}


def redefinition(
    action: ExploratoryAction, known: Mapping[str, ExploratoryAction], whose: str
) -> str | None:
    """Why ``action`` may not carry its name: ``known`` (``whose`` actions) has an action of
    that name with other parameters. Data, features and prior knowledge are filed under action
    names; a second meaning of a name would pair models of one movement with observations of
    another. None if the name is free or the definition the same."""
    old = known.get(action.name)
    if old is None or old == action:
        return None
    changed = ", ".join(
        f"{k} {getattr(old, k):g} -> {getattr(action, k):g}"
        for k in ("depth", "hold_time", "normal_force", "speed", "slide_time")
        if getattr(old, k) != getattr(action, k)
    )
    if old.movement != action.movement:
        changed = f"movement {old.movement.value} -> {action.movement.value}" + (
            f", {changed}" if changed else ""
        )
    return (
        f"action {action.name!r} redefines {whose} {action.name} ({changed}); "
        "give your action another name"
    )


def actions_from_toml(path: str | Path) -> dict[str, ExploratoryAction]:
    """Load actions from a TOML file with one ``[[action]]`` table per action. An action named
    like one of the paper's (:data:`PAPER_ACTIONS`) must be that action: a file that redefines
    one is refused."""
    path = Path(path)
    with path.open("rb") as fh:
        try:
            doc = tomllib.load(fh)
        except UnicodeDecodeError:
            raise InvalidInputError(
                f"{path}: not an actions file (TOML text), not even UTF-8 text"
            ) from None
    tables = doc.get("action")
    if not isinstance(tables, list) or not tables:
        raise InvalidInputError(f"{path}: expected one or more [[action]] tables")
    actions: dict[str, ExploratoryAction] = {}
    for i, table in enumerate(tables):
        try:
            action = ExploratoryAction.from_dict(table)
        except (TypeError, ValueError) as exc:
            raise InvalidInputError(f"{path}: action #{i + 1}: {exc}") from None
        if action.name in actions:
            raise InvalidInputError(f"{path}: action {action.name!r} is defined twice")
        why = redefinition(action, PAPER_ACTIONS, "the paper's")
        if why:
            raise InvalidInputError(f"{path}: {why}")
        actions[action.name] = action
    return actions
