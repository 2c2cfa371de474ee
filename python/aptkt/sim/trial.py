"""Per-trial variation: everything that differs between two repetitions of the same action on
the same object (paper §5.2: objects were shifted and rotated by hand between trials).

All draws come from the trial's own SeedSequence (keyed by world seed, object, action and
trial), so a trial's conditions never depend on which other trials were run, or in what order.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

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
    ambient_sd: float = 0.4  # K, drift of the room over a session
    object_temperature_sd: float = 0.15  # K, object slightly off room temperature
    skin_offset_sd: float = 0.06  # K, skin not fully recovered from the previous action
    depth_error_sd: float = 15e-6  # m, robot repeatability along the press axis

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not math.isfinite(value) or (value < 0 and name != "ambient"):
                raise ValueError(f"TrialVariation.{name} must be finite and >= 0, got {value!r}")


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
    ambient: float
    object_temperature: float
    skin_offset: float
    depth_error: float  # m

    @classmethod
    def draw(cls, obj: ObjectSpec, variation: TrialVariation, seq: np.random.SeedSequence) -> TrialConditions:
        g = spawn_generators(seq, ["pose", "material", "thermal", "robot"])
        pose, mat, th = g["pose"], g["material"], g["thermal"]
        tilt = np.tan(np.deg2rad(variation.tilt_sd) * pose.standard_normal(2))
        cv = obj.variability
        ambient = variation.ambient + variation.ambient_sd * th.standard_normal()
        return cls(
            shift=(float(pose.uniform(-variation.shift, variation.shift)),
                   float(pose.uniform(-variation.shift, variation.shift))),
            rotation=float(np.deg2rad(pose.uniform(-variation.rotation, variation.rotation))),
            tilt=(float(tilt[0]), float(tilt[1])),
            modulus_scale=float(np.exp(cv * mat.standard_normal())),
            relaxation_scale=float(np.exp(cv * mat.standard_normal())),
            friction_scale=float(np.exp(0.5 * cv * mat.standard_normal())),
            roughness_scale=float(np.exp(cv * mat.standard_normal())),
            conductance_scale=float(np.exp(cv * mat.standard_normal())),
            ambient=float(ambient),
            object_temperature=float(ambient + obj.temperature_offset
                                     + variation.object_temperature_sd * th.standard_normal()),
            skin_offset=float(variation.skin_offset_sd * th.standard_normal()),
            depth_error=float(variation.depth_error_sd * g["robot"].standard_normal()),
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
