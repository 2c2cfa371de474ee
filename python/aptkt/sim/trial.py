"""Per-trial variation: everything that differs between two repetitions of the same action on
the same object (paper §5.2: objects were shifted and rotated by hand between trials).

All draws come from the trial's own SeedSequence (keyed by world seed, object, action and
trial), so a trial's conditions never depend on which other trials were run, or in what order.
What changes slowly over a run of trials or between sessions (the room, the skin's calibration
and surface) comes from :mod:`aptkt.sim.drift` and is combined with these draws here.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.sim.drift import SlowConditions
from aptkt.sim.objects import ObjectSpec
from aptkt.sim.seeding import spawn_generators

__all__ = ["TrialVariation", "TrialConditions"]


@dataclass(frozen=True)
class TrialVariation:
    """How much trials vary. Defaults describe careful manual re-placement in a lab."""

    shift: float = 0.008  # m, object moved uniformly within ± this in x and y
    rotation: float = 30.0  # degrees, object turned uniformly within ± this
    tilt_sd: float = 0.12  # degrees, the face leans (uneven base, objects not square)
    ambient: float = 24.0  # °C, room temperature
    ambient_sd: float = 0.03  # K, the room's quick fluctuation (drafts); its slow wander: drift.py
    object_temperature_sd: float = 0.15  # K, object slightly off room temperature
    skin_offset_sd: float = 0.03  # K, skin not fully recovered from the previous action
    depth_error_sd: float = 40e-6  # m, robot repeatability along the press axis (UR10: ±0.1 mm)
    texture_sd: float = 0.15  # relative spot-to-spot variation of the roughness amplitude
    friction_sd: float = 0.06  # relative spot-to-spot variation of the friction coefficients
    contact_sd: float = 0.12  # relative variation of the thermal contact (area, cleanliness)
    # The interface conductance: a rough, hard face touches the cover only on its asperities,
    # so where the cover lands changes the heat's path more than on a smooth face (which the
    # cover fills) or a soft one (which fills the cover): log-normal spread rough_contact_sd ·
    # r/(r + conformity_roughness) · E/(E + cover_modulus), roughness r, top-layer modulus E.
    rough_contact_sd: float = 0.6
    conformity_roughness: float = 5e-6  # m, roughness at which the cover half fills the face
    cover_modulus: float = 1.0e6  # Pa, objects much softer than the cover conform to it
    arm_vibration: float = 0.0025  # g rms of the arm's own vibration when moving at 5 cm/s
    arm_vibration_sd: float = 0.4  # log-normal spread of that amplitude between trials
    skin_stiffness_sd: float = (
        0.05  # relative drift of the skin cover's stiffness (temperature, wear)
    )
    force_gain_sd: float = 0.025  # relative change of the force sensors' gain between trials,
    # common to the patch (its slow creep over a run: drift.py)
    cell_gain_sd: float = 0.03  # ... and per cell
    # multiplies each object's own material variability (its ``variability``): 1 is the object's
    material_scale: float = 1.0

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not math.isfinite(value) or (value < 0 and name != "ambient"):
                raise InvalidInputError(
                    f"TrialVariation.{name} must be finite and >= 0, got {value!r}"
                )
        for name in ("conformity_roughness", "cover_modulus"):
            if getattr(self, name) <= 0:
                raise InvalidInputError(f"TrialVariation.{name} must be > 0")

    def interface_spread(self, obj: ObjectSpec) -> float:
        """Relative (log) spread between trials of the interface conductance on ``obj``'s face:
        large on rough, hard faces, small on smooth or soft ones."""
        r, modulus = obj.surface.roughness_rms, obj.top.modulus
        return (
            self.rough_contact_sd
            * r
            / (r + self.conformity_roughness)
            * modulus
            / (modulus + self.cover_modulus)
        )


@dataclass(frozen=True)
class TrialConditions:
    """One trial's draw. Scales multiply the object's nominal properties."""

    shift: tuple[float, float]
    rotation: float  # rad
    tilt: tuple[float, float]  # slope of the face along object x and y
    modulus_scale: float
    relaxation_scale: float
    friction_scale: float
    roughness_scale: float
    conductance_scale: float
    skin_stiffness_scale: float
    force_gain_drift: tuple[float, ...]  # per cell multiplier of the sensors' true gain
    arm_vibration: float  # g rms at 5 cm/s
    arm_modes: tuple[tuple[float, float, float, float, float], ...]  # (Hz, phase, dx, dy, dz)
    ambient: float
    object_temperature: float
    skin_offset: float
    depth_error: float  # m
    session: str = ""
    force_offset: tuple[tuple[float, ...], ...] = ()  # N per sensor (cells × 3): zero drift
    texture_coupling: float = 1.0  # multiplies what reaches the accelerometers via the cover
    interface_scale: float = 1.0  # multiplies the face's contact conductance (heat's interface)

    @classmethod
    def draw(
        cls,
        obj: ObjectSpec,
        variation: TrialVariation,
        seq: np.random.SeedSequence,
        n_cells: int = 7,
        slow: SlowConditions | None = None,
    ) -> TrialConditions:
        """One trial's conditions: this trial's own draws around the slow conditions ``slow``
        of its session and run (none: the nominal skin and room)."""
        slow = slow or SlowConditions(session=obj.session, room=0.0, object_lag=0.0)
        g = spawn_generators(
            seq, ["pose", "material", "thermal", "robot", "arm", "sensors", "interface"]
        )
        pose, mat, th, arm = g["pose"], g["material"], g["thermal"], g["arm"]
        tilt = np.tan(np.deg2rad(variation.tilt_sd) * pose.standard_normal(2))
        cv = obj.variability * variation.material_scale
        ambient = variation.ambient + slow.room + variation.ambient_sd * th.standard_normal()
        return cls(
            shift=(
                float(pose.uniform(-variation.shift, variation.shift)),
                float(pose.uniform(-variation.shift, variation.shift)),
            ),
            rotation=float(np.deg2rad(pose.uniform(-variation.rotation, variation.rotation))),
            tilt=(float(tilt[0]), float(tilt[1])),
            modulus_scale=float(np.exp(cv * mat.standard_normal())),
            relaxation_scale=float(np.exp(cv * mat.standard_normal())),
            friction_scale=slow.friction
            * float(np.exp(math.hypot(0.5 * cv, variation.friction_sd) * mat.standard_normal())),
            roughness_scale=float(
                np.exp(math.hypot(cv, variation.texture_sd) * mat.standard_normal())
            ),
            conductance_scale=float(
                np.exp(math.hypot(cv, variation.contact_sd) * mat.standard_normal())
            ),
            interface_scale=slow.contact
            * float(np.exp(variation.interface_spread(obj) * g["interface"].standard_normal())),
            skin_stiffness_scale=slow.cover_stiffness
            * float(np.exp(variation.skin_stiffness_sd * g["sensors"].standard_normal())),
            force_gain_drift=tuple(
                slow.force_gain * float(x)
                for x in np.exp(
                    variation.force_gain_sd * g["sensors"].standard_normal()
                    + variation.cell_gain_sd * g["sensors"].standard_normal(n_cells)
                )
            ),
            arm_vibration=float(
                variation.arm_vibration * np.exp(variation.arm_vibration_sd * arm.standard_normal())
            ),
            arm_modes=tuple(_arm_mode(arm) for _ in range(3)),
            ambient=float(ambient),
            object_temperature=float(
                ambient
                + slow.object_lag
                + obj.temperature_offset
                + variation.object_temperature_sd * th.standard_normal()
            ),
            skin_offset=float(variation.skin_offset_sd * th.standard_normal()),
            depth_error=float(variation.depth_error_sd * g["robot"].standard_normal()),
            session=slow.session,
            force_offset=slow.force_offset or tuple((0.0, 0.0, 0.0) for _ in range(n_cells)),
            texture_coupling=slow.coupling,
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _arm_mode(rng: np.random.Generator) -> tuple[float, float, float, float, float]:
    """One vibration mode of the moving arm: frequency, phase and a unit direction."""
    d = rng.standard_normal(3)
    d /= np.linalg.norm(d)
    return (
        float(rng.uniform(18.0, 110.0)),
        float(rng.uniform(0, 2 * np.pi)),
        float(d[0]),
        float(d[1]),
        float(d[2]),
    )
