"""How noisy the simulated world is as a whole: three numbers that a real sensor's table can set
(:func:`aptkt.experiments.noise_fit.fit_noise`, docs/simulation.md "Noise fitted to a table").

The world's noise comes from many physical draws (``TrialVariation``: a trial's own;
``RecordingDrift``: what wanders over a run and between sessions). A real sensor differs from the
simulated one in how large these are together, not in which mechanisms there are, so a fit scales
them together rather than one by one:

- ``trial`` multiplies every spread of a trial's own draws, the materials' variability included:
  how far two touches of one object differ, against how far objects lie apart;
- ``drift`` multiplies every slow wander and the storage offset: how much the trials of a run
  move together;
- ``objects`` is the spread between objects of how repeatable a touch on each is: object ``o``'s
  trial spreads are multiplied by ``exp(objects · z_o)``, ``z_o ~ N(0, 1)`` keyed by the world's
  seed and the object's name. A real skin's noise differs from material to material far more
  than the simulated physics alone makes it differ.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError, InvalidInputError
from aptkt.files import read_toml
from aptkt.sim.drift import RecordingDrift, Wander
from aptkt.sim.seeding import seed_sequence
from aptkt.sim.trial import TrialVariation

__all__ = [
    "NoiseLevel",
    "TRIAL_SPREADS",
    "MAX_LEVEL",
    "PHYSICAL",
    "FITTED",
    "load_noise_level",
    "noise_level_toml",
]

#: The fields of :class:`TrialVariation` that are spreads (the rest are levels and constants).
TRIAL_SPREADS = (
    "shift",
    "rotation",
    "tilt_sd",
    "ambient_sd",
    "object_temperature_sd",
    "skin_offset_sd",
    "depth_error_sd",
    "texture_sd",
    "friction_sd",
    "contact_sd",
    "rough_contact_sd",
    "arm_vibration_sd",
    "skin_stiffness_sd",
    "force_gain_sd",
    "cell_gain_sd",
    "material_scale",
)


#: The largest level of each number. Four times the trials' spreads moves an object by up to
#: ±32 mm and turns it by up to ±120° between touches (a touch may then miss a small object's
#: face), ten times the drift shifts the room by 6 K between sessions, and an object factor of 2
#: makes one object in six more than 7 times as noisy as the median one.
MAX_LEVEL = {"trial": 4.0, "drift": 10.0, "objects": 2.0}


@dataclass(frozen=True)
class NoiseLevel:
    """The world's noise against its physical defaults (``NoiseLevel()`` changes nothing)."""

    trial: float = 1.0
    drift: float = 1.0
    objects: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value, most = getattr(self, f.name), MAX_LEVEL[f.name]
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise InvalidInputError(
                    f"noise level {f.name} must be a finite number >= 0, got {value!r}"
                )
            if value > most:
                raise InvalidInputError(
                    f"noise level {f.name} {value:g} is above its largest, {most:g} (a world "
                    "noisier than that is not a sensor the simulation describes)"
                )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> NoiseLevel:
        unknown = sorted(set(data) - {f.name for f in fields(cls)})
        if unknown:
            raise InvalidInputError(
                f"unknown noise level field(s) {', '.join(unknown)}; known: trial, drift, objects"
            )
        for key, value in data.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InvalidInputError(f"noise level {key} must be a number, got {value!r}")
        return cls(**{k: float(v) for k, v in data.items()})

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    def repeatability(self, seed: int, object_name: str) -> float:
        """Object ``object_name``'s factor on its trial spreads (1 when ``objects`` is 0)."""
        if self.objects == 0.0:
            return 1.0
        z = np.random.default_rng(
            seed_sequence(seed, "repeatability", object_name)
        ).standard_normal()
        return math.exp(self.objects * float(z))

    def variation(self, base: TrialVariation, seed: int, object_name: str) -> TrialVariation:
        """``base`` with its spreads scaled for one object."""
        k = self.trial * self.repeatability(seed, object_name)
        if k == 1.0:
            return base
        return replace(base, **{name: getattr(base, name) * k for name in TRIAL_SPREADS})

    def recording_drift(self, base: RecordingDrift) -> RecordingDrift:
        """``base`` with every wander's session and run spread, and the storage offset, scaled."""
        if self.drift == 1.0:
            return base
        k = self.drift
        scaled: dict[str, Any] = {
            f.name: replace(w, session=w.session * k, run=w.run * k)
            for f in fields(base)
            if isinstance(w := getattr(base, f.name), Wander)
        }
        return replace(base, storage=base.storage * k, **scaled)


#: The physical defaults alone (``TrialVariation()`` and ``RecordingDrift()`` as they are).
PHYSICAL = NoiseLevel()

#: The world's default: fitted to the BioTac sliding set's table (docs/simulation.md, "Noise
#: fitted to a table": ``aptkt dataset fit-noise biotac.csv -o biotac-noise.toml --probes 4``).
FITTED = NoiseLevel(trial=1.0306, drift=1.5041, objects=0.5131)


def load_noise_level(path: str | Path) -> NoiseLevel:
    """Read a noise level file (TOML: a ``[noise]`` table with ``trial``, ``drift`` and
    ``objects``, as ``aptkt dataset fit-noise`` writes it)."""
    doc = read_toml(path, "a noise level file")
    table = doc.get("noise")
    if not isinstance(table, Mapping) or set(doc) - {"noise"}:
        raise ConfigError(
            f"{path}: a noise level file holds a [noise] table (trial, drift, objects), as "
            "'aptkt dataset fit-noise' writes it"
        )
    try:
        return NoiseLevel.from_dict(table)
    except InvalidInputError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def noise_level_toml(level: NoiseLevel, comments: tuple[str, ...] = ()) -> str:
    """The file :func:`load_noise_level` reads."""
    lines = [f"# {c}" for c in comments]
    lines += ["[noise]"] + [f"{k} = {v:.4f}" for k, v in level.to_dict().items()]
    return "\n".join(lines) + "\n"
