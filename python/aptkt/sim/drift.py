"""How a data set is recorded: in sessions, one trial after another, on a skin and in a room
that change slowly while it is recorded (docs/simulation.md, "Sessions and drift").

A real data set is not a set of independent draws. The trials of one object and action are
recorded as a *run*, one after another (about a minute apart: approach, action, lift, the 30 s
thermal wait, the object re-placed by hand), and while they are the room's temperature wanders
with the air conditioning, the force sensors' elastomer softens and creeps under the repeated
loads, the cover's surface picks up dust and wears. Objects recorded on another day (another
*session*) meet a re-mounted skin and a room at another temperature.

Each slow quantity is a :class:`Wander`: a constant offset per session plus an
Ornstein–Uhlenbeck process over the trials of a run,

    z[0] ~ N(0, 1),   z[t] = ρ z[t-1] + √(1 − ρ²) ε[t],   ρ = exp(−1 / L),

scaled by its stationary standard deviation (L: the correlation length in trials). Everything is
keyed by the world's seed and names (session; session, object and action for a run) and computed
from the run's start up to the trial asked for, so a trial's conditions do not depend on which
other trials are simulated, in which order or in how many processes.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.sim.objects import ObjectSpec
from aptkt.sim.seeding import seed_sequence, spawn_generators

__all__ = ["Wander", "RecordingDrift", "SlowConditions", "object_time_constant"]


@dataclass(frozen=True)
class Wander:
    """A slowly changing quantity: ``session`` is the standard deviation of its offset between
    sessions, ``run`` the stationary standard deviation of its wander within a run, ``trials``
    the wander's correlation length (trials)."""

    session: float = 0.0
    run: float = 0.0
    trials: float = 20.0

    def __post_init__(self) -> None:
        for name in ("session", "run"):
            value = getattr(self, name)
            if not math.isfinite(value) or value < 0:
                raise InvalidInputError(f"Wander.{name} must be finite and >= 0, got {value!r}")
        if not math.isfinite(self.trials) or self.trials <= 0:
            raise InvalidInputError(f"Wander.trials must be finite and > 0, got {self.trials!r}")

    def path(self, rng: np.random.Generator, length: int, width: int = 1) -> np.ndarray:
        """The run's wander at trials 0 .. length-1, shape (length, width). Trial t's value uses
        the first (t + 1) · width normal deviates of ``rng`` only, so it is the same whatever
        ``length`` is asked for."""
        eps = rng.standard_normal((length, width))
        rho = math.exp(-1.0 / self.trials)
        innovation = math.sqrt(1.0 - rho * rho)
        z = np.empty_like(eps)
        z[0] = eps[0]
        for t in range(1, length):
            z[t] = rho * z[t - 1] + innovation * eps[t]
        return self.run * z


@dataclass(frozen=True)
class RecordingDrift:
    """The slow changes of the skin and the room, in sessions and within runs. The defaults and
    their physical reasons are in docs/simulation.md ("Sessions and drift")."""

    #: K: the room's temperature. Air-conditioned labs hold their set point to ±0.5–1 K from
    #: day to day; within a run the regulation cycles by a few tenths of a kelvin over ~15 min.
    room: Wander = Wander(session=0.6, run=0.06, trials=15.0)
    #: N per sensor: the zero of the force sensors, common to the patch. The operator tares the
    #: skin when a session starts (what stays is the calibration's own error, patch.py); within
    #: a run the elastomer creeps under the repeated loads. Kept small against the approach's
    #: contact threshold (0.05 N over 21 sensors), as an operator would re-tare a skin whose
    #: unloaded reading came near it.
    force_offset: Wander = Wander(session=0.0, run=0.0004, trials=20.0)
    #: N per sensor, each sensor on its own (uneven creep).
    sensor_offset: Wander = Wander(session=0.0, run=0.0012, trials=20.0)
    #: Relative (log) gain of the force sensors, common to the patch: stress softening of the
    #: sensors' elastomer under repeated loading (Mullins effect) and its recovery.
    force_gain: Wander = Wander(session=0.03, run=0.05, trials=20.0)
    #: Relative (log) stiffness of the skin's cover and mount: temperature and wear.
    cover_stiffness: Wander = Wander(session=0.04, run=0.04, trials=20.0)
    #: Relative (log) coupling of the accelerometers to the surface through the cover: how
    #: tightly the cover sits (re-mounting) and how its surface wears over a run.
    coupling: Wander = Wander(session=0.15, run=0.15, trials=20.0)
    #: Relative (log) friction of the cover against the objects: dust and residue build up on
    #: its surface over a run; it is cleaned between sessions.
    friction: Wander = Wander(session=0.12, run=0.12, trials=20.0)
    #: Relative (log) thermal contact of the cover: the same surface film.
    contact: Wander = Wander(session=0.10, run=0.15, trials=20.0)
    #: K: an object's temperature off the room's when it is brought to the bench for a run
    #: (from a shelf by the window, a cupboard on an outer wall), the same for its runs of a
    #: session; it relaxes to the room's with the object's own time constant over the run.
    storage: float = 1.5
    #: s from one trial's start to the next one's (the time scale of the objects' thermal lag).
    trial_period: float = 60.0
    #: W/(m² K): heat loss of an object to its surroundings per area of its top face (free
    #: convection on top, the table and the sides below), setting how fast it follows the room.
    object_heat_loss: float = 20.0

    def __post_init__(self) -> None:
        if not math.isfinite(self.storage) or self.storage < 0:
            raise InvalidInputError(
                f"RecordingDrift.storage must be finite and >= 0, got {self.storage!r}"
            )
        for name in ("trial_period", "object_heat_loss"):
            value = getattr(self, name)
            if not math.isfinite(value) or value <= 0:
                raise InvalidInputError(
                    f"RecordingDrift.{name} must be finite and > 0, got {value!r}"
                )

    @classmethod
    def off(cls) -> RecordingDrift:
        """No sessions and no drift: every trial a fresh draw around the same skin and room."""
        still = Wander()
        return cls(
            storage=0.0,
            room=still,
            force_offset=still,
            sensor_offset=still,
            force_gain=still,
            cover_stiffness=still,
            coupling=still,
            friction=still,
            contact=still,
        )

    def to_dict(self) -> dict[str, object]:
        return asdict(self)

    def at(
        self, seed: int, obj: ObjectSpec, action_name: str, trial: int, n_cells: int = 7
    ) -> SlowConditions:
        """The slow conditions of trial ``trial`` of the run (session, object, action)."""
        if trial < 0:
            raise InvalidInputError(f"trial must be >= 0, got {trial}")
        quantities = (
            "room",
            "force_offset",
            "sensor_offset",
            "force_gain",
            "cover_stiffness",
            "coupling",
            "friction",
            "contact",
        )
        day = spawn_generators(seed_sequence(seed, "session", obj.session), quantities)
        stored = spawn_generators(seed_sequence(seed, "storage", obj.session, obj.name), ["t"])
        run = spawn_generators(
            seed_sequence(seed, "run", obj.session, obj.name, action_name), quantities
        )
        n = trial + 1

        def level(name: str, width: int = 1) -> np.ndarray:
            wander: Wander = getattr(self, name)
            offset = wander.session * day[name].standard_normal(width)
            return offset + wander.path(run[name], n, width)[trial]

        keep = self._lag_factor(obj)
        room_path = self.room.path(run["room"], n)[:, 0]
        room_offset = self.room.session * float(day["room"].standard_normal())
        offsets = level("force_offset") + level("sensor_offset", 3 * n_cells)
        return SlowConditions(
            session=obj.session,
            room=room_offset + float(room_path[trial]),
            object_lag=_lag(room_path, keep)
            + self.storage * float(stored["t"].standard_normal()) * keep ** (trial + 1),
            force_offset=tuple(tuple(float(x) for x in row) for row in offsets.reshape(n_cells, 3)),
            force_gain=float(np.exp(level("force_gain")[0])),
            cover_stiffness=float(np.exp(level("cover_stiffness")[0])),
            coupling=float(np.exp(level("coupling")[0])),
            friction=float(np.exp(level("friction")[0])),
            contact=float(np.exp(level("contact")[0])),
        )

    def _lag_factor(self, obj: ObjectSpec) -> float:
        """How much of its previous trial's temperature an object keeps (per trial period)."""
        return math.exp(-self.trial_period / object_time_constant(obj, self.object_heat_loss))


def object_time_constant(obj: ObjectSpec, heat_loss: float = 20.0) -> float:
    """Seconds an object takes to follow a change of the room: its heat capacity per area of
    the top face over its heat loss per area (a lumped body: the layers are thin against the
    face, and heat crosses them faster than it leaves through the surface)."""
    capacity = sum(layer.heat_capacity * layer.thickness for layer in obj.layers)
    return capacity / heat_loss


def _lag(room: np.ndarray, keep: float) -> float:
    """The object's temperature off the room at the last trial of ``room`` (K): the room's wander
    low-passed by the object, T_o[t] = a T_o[t−1] + (1 − a) T_room[t], minus the room. The object
    starts the run at the room's mean temperature (it has stood in the room for hours)."""
    t_obj = 0.0
    for value in room:
        t_obj = keep * t_obj + (1.0 - keep) * float(value)
    return t_obj - float(room[-1])


@dataclass(frozen=True)
class SlowConditions:
    """The slow part of one trial's conditions: where the session and the run's wander stand."""

    session: str
    room: float  # K, room temperature off the nominal
    object_lag: float  # K, object's temperature off the room's (it follows the room late)
    force_offset: tuple[tuple[float, ...], ...] = field(default=())  # N per sensor (cells × 3)
    force_gain: float = 1.0  # multiplies the force sensors' true sensitivity
    cover_stiffness: float = 1.0  # multiplies the skin cover's stiffness
    coupling: float = 1.0  # multiplies what reaches the accelerometers through the cover
    friction: float = 1.0  # multiplies the friction between cover and object
    contact: float = 1.0  # multiplies the thermal contact between cover and object

    def to_dict(self) -> dict[str, object]:
        return asdict(self)
