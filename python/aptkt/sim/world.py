"""The simulated world behind one simple facade.

>>> world = SimWorld(seed=0)
>>> rec = world.explore("rough_sponge", "P2", trial=3)      # a Recording, as from hardware

Each call to :meth:`SimWorld.explore` builds the trial from its own seed (object, action, trial)
and runs the shared executor (:func:`aptkt.actions.executor.explore`) with the simulated robot and
the in-process simulated skin, so results do not depend on the order of calls or on the
process that makes them. :meth:`SimWorld.session` gives the robot and skin for your own loop;
``realtime=True`` streams the bytes through a pty for :class:`~aptkt.skin.SerialSkin`.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.actions import PAPER_ACTIONS, ExplorationSettings, ExploratoryAction, Movement, explore
from aptkt.errors import InvalidInputError, UnknownNameError
from aptkt.robot.base import Placement, SafetyLimits
from aptkt.sim.drift import RecordingDrift
from aptkt.sim.engine import FastDriver, RealTimeDriver, SimEngine
from aptkt.sim.noise import FITTED, NoiseLevel
from aptkt.sim.objects import ObjectLibrary, ObjectSpec, default_library
from aptkt.sim.patch import DEFAULT_CELL_IDS, PatchGeometry, PatchImperfections, SkinConstants
from aptkt.sim.physics import ContactPhysics, ObjectPose
from aptkt.sim.robot import SimRobot
from aptkt.sim.seeding import stable_words, trial_seed_sequence
from aptkt.sim.skin_stream import PtySkinLink, SimSkin
from aptkt.sim.trial import TrialConditions, TrialVariation
from aptkt.skin import CellConfig, PatchConfig
from aptkt.skin.samples import Recording

__all__ = ["SimWorld", "SimSession", "OBJECT_SPOT"]

#: Where objects lie on the table (robot base frame, m); the table top is at z = 0.
OBJECT_SPOT = (0.55, 0.0)
_APPROACH_ALTITUDE = 0.02  # m above the surface where a session's arm starts


@dataclass
class SimSession:
    """A placed object with the arm and skin that explore it (fast or real time)."""

    robot: SimRobot
    placement: Placement
    engine: SimEngine
    patch: PatchConfig
    skin: SimSkin | None = None  # fast sessions
    port: str | None = None  # real-time sessions: open SerialSkin(port, patch)
    conditions: TrialConditions | None = None


class SimWorld:
    """Objects, a simulated UR10-like arm and a 7-cell skin patch.

    ``seed`` keys every trial; ``patch_seed`` fixes the patch's own imperfections (its
    calibration errors, crooked cells, clocks), so two worlds with different seeds share the
    same skin, as two data sets recorded with one robot do. ``drift`` describes how the skin
    and the room change while a data set is recorded: between sessions (each object's
    ``session``) and over a run of trials (trial ``t`` of an object and action is the run's
    ``t``-th); :meth:`RecordingDrift.off` gives independent trials around a fixed skin. ``layout`` takes the cell ids and
    positions from a skin patch file; the force calibration is always the simulated patch's
    own (:attr:`patch`, the one to give a skin source reading this world). ``noise`` scales the
    trials' variation and the drift together (:class:`~aptkt.sim.noise.NoiseLevel`; default
    :data:`~aptkt.sim.noise.FITTED`, fitted to a real sensor's table; ``PHYSICAL``: the
    physical defaults alone).
    """

    def __init__(
        self,
        objects: ObjectLibrary | None = None,
        *,
        seed: int = 0,
        variation: TrialVariation | None = None,
        limits: SafetyLimits | None = None,
        constants: SkinConstants | None = None,
        patch_seed: int = 0,
        cell_ids: tuple[int, ...] = DEFAULT_CELL_IDS,
        layout: PatchConfig | None = None,
        settings: ExplorationSettings | None = None,
        drift: RecordingDrift | None = None,
        noise: NoiseLevel | dict[str, float] | None = None,
    ):
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InvalidInputError(f"seed must be an integer >= 0, got {seed!r}")
        self.objects = objects if objects is not None else default_library()
        self.seed = int(seed)
        self.variation = variation or TrialVariation()
        if noise is None:
            noise = FITTED
        elif not isinstance(noise, NoiseLevel):
            noise = NoiseLevel.from_dict(noise)
        self.noise = noise
        self.drift = noise.recording_drift(drift if drift is not None else RecordingDrift())
        self._variations: dict[str, TrialVariation] = {}
        self.limits = limits or SafetyLimits()
        if layout is not None:  # cell ids and positions from a skin patch file
            self.geometry = PatchGeometry.from_patch(
                layout.cell_ids, layout.positions_mm, constants or SkinConstants()
            )
        else:
            self.geometry = PatchGeometry(cell_ids, constants or SkinConstants())
        self.imperfections = PatchImperfections.generate(
            self.geometry.constants, self.geometry.n_cells, patch_seed
        )
        self.settings = settings or ExplorationSettings(stamp_wall_clock=False)
        self.patch = PatchConfig(
            name=f"simulated-{self.geometry.n_cells}",
            cells=tuple(
                CellConfig(
                    cell_id=cid,
                    position_mm=(float(x * 1e3), float(y * 1e3), 0.0),
                    force_offset=_triple(self.imperfections.believed_offset[i]),
                    force_gain=_triple(self.imperfections.believed_gain[i]),
                )
                for i, (cid, (x, y)) in enumerate(
                    zip(self.geometry.cell_ids, self.geometry.centres)
                )
            ),
            # Arrival times are stamped by the reading thread: on a busy CPU the real-time pty
            # reader can stall for a few hundred ms and would report live cells as silent.
            silence_timeout_s=0.5,
            source="aptkt.sim",
        )

    # ------------------------------------------------------------------ objects and trials
    def object(self, name: str) -> ObjectSpec:
        return self.objects[name]

    def placement(self, object_name: str, action: ExploratoryAction | None = None) -> Placement:
        """The nominal placement the robot is told about. For slides the start point is moved
        back by half the slide so that the slide crosses the middle of the object."""
        obj = self.objects[object_name]
        x, y = OBJECT_SPOT
        if action is not None and action.movement is Movement.SLIDE:
            ramp = action.speed / self.limits.max_acceleration
            x -= 0.5 * action.speed * (action.slide_time + ramp)
        half = max(obj.size) / 2 + 0.08
        return Placement(
            object_name=obj.name,
            x=x,
            y=y,
            surface_z=obj.height,
            workspace_min=(
                OBJECT_SPOT[0] - half,
                OBJECT_SPOT[1] - half,
                max(obj.height - 0.01, 0.0),
            ),
            workspace_max=(OBJECT_SPOT[0] + half, OBJECT_SPOT[1] + half, obj.height + 0.25),
            slide_direction=(1.0, 0.0),
        )

    def conditions(self, object_name: str, action_name: str, trial: int) -> TrialConditions:
        obj = self.objects[object_name]
        if obj.name not in self._variations:
            self._variations[obj.name] = self.noise.variation(self.variation, self.seed, obj.name)
        return TrialConditions.draw(
            obj,
            self._variations[obj.name],
            trial_seed_sequence(self.seed, obj.name, action_name, trial),
            self.geometry.n_cells,
            self.drift.at(self.seed, obj, action_name, trial, self.geometry.n_cells),
        )

    def _action(self, action: ExploratoryAction | str) -> ExploratoryAction:
        if isinstance(action, ExploratoryAction):
            return action
        try:
            return PAPER_ACTIONS[action]
        except KeyError:
            raise UnknownNameError(
                f"unknown action {action!r}; paper actions: {', '.join(PAPER_ACTIONS)}"
            ) from None

    # ------------------------------------------------------------------ sessions
    @contextmanager
    def session(
        self,
        object_name: str,
        action_name: str = "session",
        trial: int = 0,
        *,
        realtime: bool = False,
        action: ExploratoryAction | None = None,
    ) -> Iterator[SimSession]:
        """The object placed for one trial, with the arm hovering above it.

        Fast sessions (default) run on simulated time and carry an in-process :class:`SimSkin`.
        Real-time sessions stream through a pty: open ``SerialSkin(session.port, session.patch)``.
        """
        obj = self.objects[object_name]
        seq = trial_seed_sequence(self.seed, obj.name, action_name, trial)
        cond = self.conditions(obj.name, action_name, trial)
        noise = np.random.SeedSequence(
            seq.entropy, spawn_key=(*seq.spawn_key, *stable_words("noise"))
        )
        placement = self.placement(obj.name, action)
        pose = ObjectPose(OBJECT_SPOT, obj.height, 0.0)
        physics = ContactPhysics(obj, pose, cond, self.geometry, self.imperfections, noise)
        start = np.array([placement.x, placement.y, obj.height + _APPROACH_ALTITUDE])
        if realtime:
            # Simulated time is the monotonic clock, the one SerialSkin stamps packets with.
            link = PtySkinLink()
            engine = SimEngine(physics, link, start, t0_ns=time.monotonic_ns())
            driver = RealTimeDriver(engine)
            robot = SimRobot(driver, self.limits, depth_error=cond.depth_error)
            try:
                yield SimSession(
                    robot, placement, engine, self.patch, port=link.port, conditions=cond
                )
            finally:
                driver.close()
                link.close()
            return
        holder: dict[str, Any] = {}
        skin = SimSkin(self.patch, clock=lambda: holder["engine"].now_ns)
        engine = SimEngine(physics, skin, start)
        holder["engine"] = engine
        skin.open()
        # A few packets per cell before anything moves, as a running skin would have sent.
        engine.advance(int(20e6), detail=True)
        robot = SimRobot(FastDriver(engine), self.limits, depth_error=cond.depth_error)
        try:
            yield SimSession(robot, placement, engine, self.patch, skin=skin, conditions=cond)
        finally:
            skin.close()

    def explore(
        self, object_name: str, action: ExploratoryAction | str, trial: int = 0
    ) -> Recording:
        """Apply one action once (fast, simulated time) and return the recording."""
        act = self._action(action)
        with self.session(object_name, act.name, trial, action=act) as s:
            assert s.skin is not None
            rec = explore(
                s.robot,
                s.skin,
                s.placement,
                act,
                trial=trial,
                settings=self.settings,
                metadata={
                    "simulation": self.describe_trial(object_name, act.name, trial, s.conditions)
                },
            )
        return rec

    def describe_trial(
        self, object_name: str, action_name: str, trial: int, cond: TrialConditions | None = None
    ) -> dict[str, Any]:
        """What the simulator did in a trial (stored with the recording; never used by learning)."""
        obj = self.objects[object_name]
        cond = cond or self.conditions(object_name, action_name, trial)
        return {
            "seed": self.seed,
            "object_index": obj.index,
            "object_role": obj.role,
            "session": obj.session,
            "conditions": cond.to_dict(),
        }


def _triple(v: Any) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))
