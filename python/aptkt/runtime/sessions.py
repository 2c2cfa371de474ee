"""Live sessions: a robot with its skin that explores objects on request — the UR10 with a
hardware skin source, or the simulated world. ``aptkt collect`` and ``aptkt learn`` run on them.

A session is a context manager with ``explore(object, action, trial) -> Recording`` (the shared
executor, :func:`aptkt.actions.executor.explore`), ``check_objects(names)`` and ``describe()``. On a
robot or skin fault ``explore`` raises the typed error, as a :class:`~aptkt.errors.TrialFault`
with what was recorded once the recording had started (see :mod:`aptkt.actions.executor`); the
robot is stopped by its backend. A recording in which a cell fell silent counts as a skin fault
(a :class:`~aptkt.errors.TrialFault` caused by :class:`~aptkt.errors.SilentCellError`); Ctrl-C
mid-trial raises :class:`~aptkt.errors.TrialInterrupted` with what the skin had recorded.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, Protocol

from aptkt.actions import ExploratoryAction
from aptkt.actions.executor import ExplorationSettings, calibration_metadata, explore
from aptkt.actions.limits import check_action_limits
from aptkt.errors import (
    ConfigError,
    InvalidStateError,
    SafetyLimitError,
    SilentCellError,
    TrialFault,
    TrialInterrupted,
)
from aptkt.robot import UR10
from aptkt.robot.workspace import load_workspace
from aptkt.runtime.collector_pauses import heap_frozen, no_collector_pauses
from aptkt.sim.objects import default_library, load_library
from aptkt.sim.world import SimWorld
from aptkt.skin.samples import Recording

__all__ = ["LiveSession", "RobotSession", "SimSession"]


class LiveSession(Protocol):
    name: str

    def __enter__(self) -> LiveSession: ...

    def __exit__(self, *exc: object) -> None: ...

    def explore(self, obj: str, action: ExploratoryAction, trial: int) -> Recording: ...

    def check_objects(self, names: Iterable[str]) -> None: ...

    def check_actions(self, actions: Iterable[ExploratoryAction], objects: Iterable[str]) -> None:
        """Refuse, before any motion, actions the backend's limits would stop mid-way."""
        ...

    def describe(self) -> dict[str, Any]: ...


def _require_complete(rec: Recording) -> Recording:
    """A recording in which a cell fell silent is a skin fault, not a trial: its features would
    silently differ from complete ones. Raised with the recording attached, like any fault."""
    if rec.silent_cells:
        err = SilentCellError(f"cell(s) {list(rec.silent_cells)} fell silent during the recording")
        raise TrialFault(err, rec) from err
    return rec


class SimSession:
    """The simulated world, fast path (simulated time): every trial is simulated from its own
    seed (world seed, object, action, trial), exactly as ``aptkt dataset generate`` does."""

    name = "sim"

    def __init__(
        self,
        seed: int = 0,
        settings: ExplorationSettings | None = None,
        object_files: Sequence[str] = (),
    ):

        library = load_library(*object_files) if object_files else default_library()
        settings = settings or ExplorationSettings()
        # Simulated data stay reproducible: no wall-clock stamp in the metadata.
        self.settings = replace(settings, stamp_wall_clock=False)
        self.world = SimWorld(library, seed=seed, settings=self.settings)
        self.seed = int(seed)
        self.object_files = tuple(str(f) for f in object_files)

    def __enter__(self) -> SimSession:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def check_actions(self, actions: Iterable[ExploratoryAction], objects: Iterable[str]) -> None:
        pass  # the simulated world has no safety limits to exceed

    def check_objects(self, names: Iterable[str]) -> None:
        unknown = [n for n in names if n not in self.world.objects]
        if unknown:
            raise ConfigError(
                f"--objects: the simulated world has no object(s) {', '.join(unknown)}; "
                f"known: {', '.join(self.world.objects)}"
            )

    def explore(self, obj: str, action: ExploratoryAction, trial: int) -> Recording:
        return _require_complete(self.world.explore(obj, action, trial))

    def describe(self) -> dict[str, Any]:
        return {
            "robot": "sim",
            "world": "aptkt.sim.SimWorld",
            "seed": self.seed,
            "object_files": list(self.object_files),
            "settings": asdict(self.settings),
        }


class RobotSession:
    """The UR10 (``UR10.from_config(workspace, host=...)``) with a hardware skin source.

    ``make_skin`` builds the (unopened) skin source, e.g. ``lambda: SerialSkin(port, patch)``.
    Entering opens the skin first (a silent patch fails fast, before the arm moves), then
    connects the robot. Leaving closes both (the robot stops and disconnects).
    """

    name = "ur10"

    def __init__(
        self,
        workspace: str | Path,
        make_skin: Callable[[], Any],
        *,
        host: str | None = None,
        settings: ExplorationSettings | None = None,
        skin_description: dict[str, Any] | None = None,
        cell_timeout: float = 2.0,
        **robot_options: Any,
    ):

        self.workspace = load_workspace(workspace)
        self.workspace_file = str(workspace)
        self.host = host or self.workspace.host
        if not self.host:
            raise ConfigError(f"{workspace}: no robot host given (set [robot] host or pass --host)")
        self.settings = settings or ExplorationSettings()
        self._make_skin = make_skin
        self.skin_description = dict(skin_description or {})
        self.cell_timeout = cell_timeout
        self.robot_options = robot_options
        self.robot: Any = None
        self.skin: Any = None
        self._frozen: Any = None

    def check_objects(self, names: Iterable[str]) -> None:
        unknown = [n for n in names if n not in self.workspace.placements]
        if unknown:
            known = ", ".join(self.workspace.placements) or "none"
            raise ConfigError(
                f"--objects: {self.workspace_file} places no object(s) {', '.join(unknown)}; "
                f"it places: {known}"
            )

    def check_actions(self, actions: Iterable[ExploratoryAction], objects: Iterable[str]) -> None:
        placements = [self.workspace.placements[o] for o in objects]
        for action in actions:
            try:
                check_action_limits(action, self.workspace.limits, placements)
            except SafetyLimitError as exc:
                raise SafetyLimitError(f"{exc} (limits of {self.workspace_file})") from None

    def __enter__(self) -> RobotSession:
        skin = self._make_skin()
        skin.open()
        try:
            skin.wait_for_cells(self.cell_timeout)
            self.robot = UR10.from_config(self.workspace, host=self.host, **self.robot_options)
        except BaseException:
            skin.close()
            raise
        self.skin = skin
        # Everything is loaded and connected: what exists now, no collection needs to scan.
        self._frozen = heap_frozen()
        self._frozen.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        robot, self.robot = self.robot, None
        skin, self.skin = self.skin, None
        frozen, self._frozen = self._frozen, None
        try:
            if robot is not None:
                robot.close()
        finally:
            try:
                if skin is not None:
                    skin.close()
            finally:
                if frozen is not None:
                    frozen.__exit__(None, None, None)

    def explore(self, obj: str, action: ExploratoryAction, trial: int) -> Recording:
        if self.robot is None:
            raise InvalidStateError("RobotSession.explore outside 'with session:'")
        try:
            # A collection inside a recording would silence every cell for its length
            # (aptkt.runtime.collector_pauses).
            with no_collector_pauses():
                recording = explore(
                    self.robot,
                    self.skin,
                    self.robot.placement(obj),
                    action,
                    trial=trial,
                    settings=self.settings,
                )
            return _require_complete(recording)
        except KeyboardInterrupt as exc:
            # Ctrl-C mid-action: the backend stopped the arm; keep what the skin recorded.
            if getattr(self.skin, "recording", False):
                rec = self.skin.stop_recording()
                rec.metadata["calibration"] = calibration_metadata(self.skin)
                rec.metadata["aborted"] = "KeyboardInterrupt"
                raise TrialInterrupted(exc, rec) from exc
            raise

    def describe(self) -> dict[str, Any]:
        return {
            "robot": "ur10",
            "host": self.host,
            "workspace": self.workspace_file,
            "placements": {n: asdict(p) for n, p in self.workspace.placements.items()},
            "limits": asdict(self.workspace.limits),
            "skin": self.skin_description,
            "settings": asdict(self.settings),
        }
