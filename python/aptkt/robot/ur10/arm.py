"""The :class:`UR10`: the Robot protocol on a UR controller, composed of its connection,
safety supervisor, motions and sample trace (one module each in this package)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Generic, TypeVar

import numpy as np

from aptkt.errors import AptktError, ConfigError, InvalidInputError, RobotError
from aptkt.robot.base import ForceReading, Placement, SafetyLimits
from aptkt.robot.ur10.connection import Connection
from aptkt.robot.ur10.motions import Motions
from aptkt.robot.ur10.sampling import Trace
from aptkt.robot.ur10.supervisor import Supervisor
from aptkt.robot.workspace import DEFAULT_TOOL_ORIENTATION, WorkspaceConfig, load_workspace

__all__ = ["UR10"]

T = TypeVar("T")


class _Setting(Generic[T]):
    """An attribute of the UR10 that lives on one of its parts (read and written through)."""

    def __init__(self, part: str):
        self.part = part

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, robot: Any, owner: type | None = None) -> T:
        value: T = getattr(getattr(robot, self.part), self.name)
        return value

    def __set__(self, robot: Any, value: T) -> None:
        setattr(getattr(robot, self.part), self.name, value)


class UR10:
    """A UR10 (CB3 or e-Series controller) carrying the skin; implements :class:`~aptkt.robot.Robot`.

    Parameters
    ----------
    host:
        Controller address. ``connect=False`` defers the connection to :meth:`connect`.
    placements:
        Objects of the cell by name (see :mod:`aptkt.robot.workspace`); only used to look up
        placements by name, every movement gets its :class:`Placement` explicitly.
    limits:
        Safety limits enforced on every command and every supervision cycle.
    workspace:
        Optional ``(min, max)`` box every movement must stay in, also between objects.
    tool_orientation:
        TCP rotation vector used for all movements (default: skin facing straight down).
    clock:
        Nanosecond clock shared with the skin source, so both timestamp on one time base.
    retract_height:
        How far (m) to retract upwards after a fault while the arm is still controllable.
    measured_tolerance:
        Factor on ``max_speed`` / ``max_acceleration`` above which a *measured* value is a
        fault (commands are always kept within the limits themselves); measurement noise and
        the controller's own trajectory generation need some headroom.
    force_tolerance / force_tolerance_abs / settle_samples / establish_timeout:
        A slide starts once the skin force stayed within ``max(force_tolerance * F,
        force_tolerance_abs)`` of the target F for ``settle_samples`` consecutive cycles;
        ``establish_timeout`` s at most.
    """

    transfer_speed: _Setting[float] = _Setting("_motions")
    retract_height: _Setting[float] = _Setting("_motions")
    force_tolerance: _Setting[float] = _Setting("_motions")
    force_tolerance_abs: _Setting[float] = _Setting("_motions")
    settle_samples: _Setting[int] = _Setting("_motions")
    establish_timeout: _Setting[float] = _Setting("_motions")
    #: ``(start_ns, stop_ns)`` of the last hold (press) or constant-speed part of a slide,
    #: on :meth:`now_ns`'s clock; :func:`aptkt.actions.executor.explore` crops recordings to it.
    action_window_ns: _Setting[tuple[int, int] | None] = _Setting("_motions")
    measured_tolerance: _Setting[float] = _Setting("_supervisor")
    max_supervision_hz: _Setting[float] = _Setting("_supervisor")
    frequency: _Setting[float] = _Setting("_link")

    def __init__(
        self,
        host: str,
        placements: Mapping[str, Placement] | Iterable[Placement] = (),
        limits: SafetyLimits | None = None,
        *,
        workspace: tuple[Sequence[float], Sequence[float]] | None = None,
        tool_orientation: Sequence[float] = DEFAULT_TOOL_ORIENTATION,
        clock: Callable[[], int] = time.monotonic_ns,
        frequency: float | None = None,
        transfer_speed: float = 0.05,
        retract_height: float = 0.01,
        measured_tolerance: float = 1.5,
        force_tolerance: float = 0.15,
        force_tolerance_abs: float = 0.02,
        settle_samples: int = 5,
        establish_timeout: float = 3.0,
        trace_seconds: float = 120.0,
        max_supervision_hz: float = 250.0,
        connect: bool = True,
    ):
        self.host = host
        self.limits = limits or SafetyLimits()
        if isinstance(placements, Mapping):
            self.placements = dict(placements)
        else:
            self.placements = {p.object_name: p for p in placements}
        self.workspace = None
        if workspace is not None:
            self.workspace = (tuple(map(float, workspace[0])), tuple(map(float, workspace[1])))
        self.tool_orientation = tuple(float(v) for v in tool_orientation)
        if len(self.tool_orientation) != 3:
            raise InvalidInputError("tool_orientation must be a rotation vector of 3 numbers")
        self._clock = clock
        self._trace = Trace(trace_seconds)
        self._link = Connection(host, self.limits.watchdog_timeout, frequency)
        self._supervisor = Supervisor(
            self._link,
            self.limits,
            clock,
            self._trace,
            workspace=self.workspace,
            measured_tolerance=measured_tolerance,
            max_supervision_hz=max_supervision_hz,
        )
        self._motions = Motions(
            self._link,
            self._supervisor,
            self.limits,
            clock,
            self.tool_orientation,
            transfer_speed=transfer_speed,
            retract_height=retract_height,
            force_tolerance=force_tolerance,
            force_tolerance_abs=force_tolerance_abs,
            settle_samples=settle_samples,
            establish_timeout=establish_timeout,
        )
        if connect:
            self.connect()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_config(
        cls, config: WorkspaceConfig | str | Path, host: str | None = None, **kwargs: Any
    ) -> UR10:
        """A UR10 for a workspace file (or parsed config); ``host`` overrides ``[robot] host``.

        This is what ``aptkt collect/learn --robot ur10`` build on.
        """
        if not isinstance(config, WorkspaceConfig):
            config = load_workspace(config)
        host = host or config.host
        if not host:
            raise ConfigError(
                f"{config.source}: no robot host given (set [robot] host or pass --host)"
            )
        return cls(
            host,
            config.placements,
            config.limits,
            workspace=config.workspace,
            tool_orientation=config.tool_orientation,
            **kwargs,
        )

    def connect(self) -> None:
        """Connect, upload ur_rtde's control script and arm the controller's RTDE watchdog."""
        self.close()
        self._link.open()
        self._supervisor.reset()
        self._link.arm_watchdog()

    def close(self) -> None:
        """Stop the arm, end the control script and disconnect. Safe to call repeatedly."""
        link = self._link
        link.stop_keepalive()
        if link.control is not None and link.lost is None:
            self.stop()
            try:
                if link.link_ok():
                    link.call("stopScript")
            except AptktError:
                pass
        link.disconnect()

    def __enter__(self) -> UR10:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def connected(self) -> bool:
        return self._link.connected

    # The clients, for tests that check they are destroyed on close.
    @property
    def _control(self) -> Any:
        return self._link.control

    @property
    def _receive(self) -> Any:
        return self._link.receive

    def now_ns(self) -> int:
        return int(self._clock())

    def placement(self, name: str) -> Placement:
        try:
            return self.placements[name]
        except KeyError:
            raise RobotError(
                f"no placement for object {name!r} (known: {sorted(self.placements)})"
            ) from None

    # ------------------------------------------------------------------ Robot protocol
    def move_above(self, placement: Placement, clearance: float) -> None:
        self._motions.move_above(placement, clearance)

    def approach_contact(self, total_force: ForceReading, threshold: float) -> float:
        return self._motions.approach_contact(total_force, threshold)

    def press(self, depth: float, hold_time: float) -> None:
        self._motions.press(depth, hold_time)

    def slide(
        self,
        normal_force: float,
        speed: float,
        duration: float,
        direction: tuple[float, float],
        total_force: ForceReading,
    ) -> None:
        self._motions.slide(normal_force, speed, duration, direction, total_force)

    def lift(self, height: float) -> None:
        self._motions.lift(height)

    def wait(self, seconds: float) -> None:
        self._motions.wait(seconds)

    def stop(self) -> None:
        """Stop every motion now. Never raises; sends nothing once the link is lost."""
        self._motions.stop()

    def recover(self) -> None:
        """After a protective stop, a stopped program or a lost link: make the arm usable again.

        Unlocks a protective stop through the dashboard server (a real controller accepts
        that 5 s after the stop at the earliest), then reconnects and re-uploads the
        control script. Inspect the cause of the fault first.
        """
        link = self._link
        if link.receive is not None and link.lost is None and link.protective_stopped():
            link.unlock_protective_stop()
        self._motions.forget()
        self.connect()

    # ------------------------------------------------------------------ recording metadata
    def trace(
        self, start_ns: int | None = None, stop_ns: int | None = None
    ) -> dict[str, np.ndarray]:
        """Robot samples seen by the supervision loop in ``[start_ns, stop_ns)`` (host clock).

        ``robot_timestamp`` is the controller's own clock (s since boot), so the skin's
        host timestamps and the robot's can be related sample by sample.
        """
        return self._trace.window(start_ns, stop_ns)

    def recording_metadata(self, start_ns: int, stop_ns: int) -> dict[str, Any]:
        """Metadata for a skin :class:`~aptkt.skin.Recording` of ``[start_ns, stop_ns)``: the
        robot trace (JSON-able lists) and the median host-minus-controller clock offset."""
        return {
            "robot": "UR10",
            "robot_host": self.host,
            "robot_frequency_hz": self.frequency,
            **self._trace.metadata(start_ns, stop_ns),
        }
