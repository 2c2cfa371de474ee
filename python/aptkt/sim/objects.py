"""The object library: physical descriptions of the objects the simulated robot explores.

Objects live in TOML files (the package ships ``objects.toml`` with the paper's 10 prior and 5
new daily objects); users add objects to that file or to their own and load them with
:func:`load_library`. Every field is documented in ``docs/simulation.md``. A bad file raises
:class:`~aptkt.errors.ConfigError` naming the file, the object and the field.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from aptkt.errors import ConfigError, UnknownNameError
from aptkt.files import read_toml

__all__ = [
    "Layer",
    "Relaxation",
    "Ridge",
    "Surface",
    "Relation",
    "ObjectSpec",
    "ObjectLibrary",
    "load_library",
    "default_library",
    "SCHEMA_VERSION",
]

SCHEMA_VERSION = 1
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,62}$")
ROLES = ("prior", "new", "custom")


@dataclass(frozen=True)
class Layer:
    """One layer of the object, top to bottom. SI units.

    Mechanics: a Winkler foundation with a hyperbolic lock-up, ``σ = E ε / (1 - ε/ε_d)``.
    Thermal: conductivity ``k`` and volumetric heat capacity ``ρc``.
    """

    material: str
    thickness: float  # m
    modulus: float  # Pa, small-strain compressive modulus
    densification_strain: float  # (0, 1]; strain at which the layer locks up
    conductivity: float  # W/(m K)
    heat_capacity: float  # J/(m^3 K)

    @property
    def effusivity(self) -> float:
        """Thermal effusivity sqrt(k ρc) in W s^0.5 / (m^2 K)."""
        return math.sqrt(self.conductivity * self.heat_capacity)

    @property
    def diffusivity(self) -> float:
        """Thermal diffusivity k / ρc in m^2/s."""
        return self.conductivity / self.heat_capacity


@dataclass(frozen=True)
class Relaxation:
    """Quasi-linear viscoelastic relaxation ``G(t) = 1 - Σ w_i (1 - exp(-t/τ_i))``."""

    weights: tuple[float, ...] = ()
    times: tuple[float, ...] = ()

    @property
    def long_term(self) -> float:
        """G(∞): the fraction of the instantaneous stress that remains after a long hold."""
        return 1.0 - sum(self.weights)


@dataclass(frozen=True)
class Ridge:
    """A periodic surface component (weave, corrugation, grain): a plane wave of the height."""

    wavelength: float  # m
    amplitude: float  # m (peak)
    angle: float = 0.0  # degrees: direction of the wave vector in the object frame


@dataclass(frozen=True)
class Surface:
    """Texture, friction and thermal contact of the top face."""

    friction_static: float
    friction_kinetic: float
    roughness_rms: float  # m, isotropic random roughness (rms height)
    roughness_band: tuple[float, float]  # m, shortest and longest wavelength of the roughness
    roughness_exponent: float  # Hurst exponent H of the self-affine roughness, 0 < H <= 1
    contact_conductance: float  # W/(m^2 K), skin cover to surface at full contact
    ridges: tuple[Ridge, ...] = ()


@dataclass(frozen=True)
class Relation:
    """A designed likeness of an object to another (paper §5.1): in ``modality`` of
    ``actions`` its observations are meant to lie nearest to ``prior``'s, for the physical
    reason ``why``. The learner never reads it; tests and the docs check it."""

    prior: str
    modality: str
    actions: tuple[str, ...]
    why: str = ""


@dataclass(frozen=True)
class ObjectSpec:
    """A simulated object: geometry, layers, relaxation, surface."""

    name: str
    index: int
    role: str
    layers: tuple[Layer, ...]
    surface: Surface
    relaxation: Relaxation = Relaxation()
    description: str = ""
    related: tuple[str, ...] = ()  # every related object, those of ``relations`` included
    relations: tuple[Relation, ...] = ()
    height: float = 0.05  # m, top face above the table
    size: tuple[float, float] = (0.15, 0.15)  # m, extent of the top face (object x, y)
    crown_radius: float = 0.0  # m, cylindrical crown about the object's x axis; 0 = flat
    waviness: float = 0.0  # m rms, long-wavelength unevenness of the top face
    reflectivity: float = 0.5  # IR reflectivity seen by the proximity sensor, 0..1
    temperature_offset: float = 0.0  # K relative to the room
    variability: float = 0.05  # relative sd of material properties from trial to trial
    #: The recording session the object's trials belong to (docs/simulation.md, "Sessions and
    #: drift"): objects of one session share the skin's mounting and the room of that day.
    session: str = "custom"
    source: str = field(default="", compare=False)

    @property
    def top(self) -> Layer:
        return self.layers[0]

    @property
    def total_thickness(self) -> float:
        return sum(layer.thickness for layer in self.layers)


class ObjectLibrary(Mapping[str, ObjectSpec]):
    """Objects by name, iterated in index order."""

    def __init__(self, objects: Iterable[ObjectSpec]):
        by_name: dict[str, ObjectSpec] = {}
        by_index: dict[int, str] = {}
        for obj in objects:
            if obj.name in by_name:
                raise ConfigError(
                    f"{obj.source}: object {obj.name!r} is defined twice "
                    f"(also in {by_name[obj.name].source})"
                )
            if obj.index in by_index:
                raise ConfigError(
                    f"{obj.source}: object {obj.name!r}: field 'index': "
                    f"{obj.index} is already used by {by_index[obj.index]!r}"
                )
            by_name[obj.name] = obj
            by_index[obj.index] = obj.name
        for obj in by_name.values():
            for rel in obj.related:
                if rel not in by_name:
                    raise ConfigError(
                        f"{obj.source}: object {obj.name!r}: field 'related': "
                        f"unknown object {rel!r}"
                    )
        self._objects = dict(sorted(by_name.items(), key=lambda kv: kv[1].index))

    def __getitem__(self, name: str) -> ObjectSpec:
        try:
            return self._objects[name]
        except KeyError:
            raise UnknownNameError(
                f"unknown object {name!r}; known: {', '.join(self._objects)}"
            ) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._objects)

    def __len__(self) -> int:
        return len(self._objects)

    def by_index(self, index: int) -> ObjectSpec:
        for obj in self._objects.values():
            if obj.index == index:
                return obj
        raise UnknownNameError(f"no object with index {index}")

    def with_role(self, role: str) -> list[str]:
        return [name for name, obj in self._objects.items() if obj.role == role]

    def merged(self, other: Iterable[ObjectSpec]) -> ObjectLibrary:
        return ObjectLibrary([*self._objects.values(), *other])


# ---------------------------------------------------------------------------------------------
# Parsing and validation


class _Reader:
    """Reads fields of one TOML table with messages that name file, object and field."""

    def __init__(self, source: str, obj: str, table: Mapping[str, Any], prefix: str = ""):
        self.source, self.obj, self.table, self.prefix = source, obj, table, prefix
        self.used: set[str] = set()

    def fail(self, key: str, msg: str) -> ConfigError:
        return ConfigError(
            f"{self.source}: object {self.obj!r}: field {self.prefix + key!r}: {msg}"
        )

    def _get(self, key: str, default: Any) -> Any:
        self.used.add(key)
        if key not in self.table:
            if default is _REQUIRED:
                raise self.fail(key, "missing")
            return default
        return self.table[key]

    def number(
        self,
        key: str,
        default: Any = None,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
        hi_open: bool = False,
    ) -> float:
        value = self._get(key, _REQUIRED if default is None else default)
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
        ):
            raise self.fail(key, f"must be a finite number, got {value!r}")
        value = float(value)
        if lo is not None and (value < lo or (lo_open and value == lo)):
            raise self.fail(key, f"must be {'>' if lo_open else '>='} {lo:g}, got {value:g}")
        if hi is not None and (value > hi or (hi_open and value == hi)):
            raise self.fail(key, f"must be {'<' if hi_open else '<='} {hi:g}, got {value:g}")
        return value

    def integer(self, key: str, default: Any = None, *, lo: int = 1) -> int:
        value = self._get(key, _REQUIRED if default is None else default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"must be an integer, got {value!r}")
        if value < lo:
            raise self.fail(key, f"must be >= {lo}, got {value}")
        return value

    def string(self, key: str, default: Any = None) -> str:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {value!r}")
        return value

    def numbers(
        self,
        key: str,
        default: Any = None,
        *,
        length: int | None = None,
        lo: float | None = None,
        lo_open: bool = False,
    ) -> tuple[float, ...]:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, list):
            raise self.fail(key, f"must be a list of numbers, got {value!r}")
        if length is not None and len(value) != length:
            raise self.fail(key, f"must have {length} entries, got {len(value)}")
        out = []
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise self.fail(key, f"entry {i} must be a finite number, got {v!r}")
            if lo is not None and (v < lo or (lo_open and v == lo)):
                raise self.fail(
                    key, f"entry {i} must be {'>' if lo_open else '>='} {lo:g}, got {v:g}"
                )
            out.append(float(v))
        return tuple(out)

    def table_list(self, key: str) -> list[Mapping[str, Any]]:
        value = self._get(key, [])
        if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
            raise self.fail(key, "must be an array of tables ([[...]])")
        return value

    def subtable(self, key: str, required: bool = True) -> Mapping[str, Any]:
        value = self._get(key, _REQUIRED if required else {})
        if not isinstance(value, dict):
            raise self.fail(key, "must be a table")
        return value

    def finish(self) -> None:
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            raise self.fail(unknown[0], "unknown field (misspelt?)")


_REQUIRED = object()


def _parse_object(table: Mapping[str, Any], source: str, auto_index: int) -> ObjectSpec:
    name = table.get("name")
    label = name if isinstance(name, str) else "<unnamed>"
    r = _Reader(source, label, table)
    name = r.string("name")
    if not _NAME.match(name):
        raise r.fail("name", "must be lower case letters, digits and '_' starting with a letter")
    index = r.integer("index", auto_index)
    role = r.string("role", "custom")
    if role not in ROLES:
        raise r.fail("role", f"must be one of {', '.join(ROLES)}, got {role!r}")

    layers = []
    layer_tables = r.table_list("layer")
    if not layer_tables:
        raise r.fail("layer", "an object needs at least one [[object.layer]]")
    for i, lt in enumerate(layer_tables):
        lr = _Reader(source, name, lt, prefix=f"layer[{i}].")
        layers.append(
            Layer(
                material=lr.string("material", ""),
                thickness=lr.number("thickness", lo=0.0, lo_open=True),
                modulus=lr.number("modulus", lo=0.0, lo_open=True),
                densification_strain=lr.number(
                    "densification_strain", 1.0, lo=0.0, hi=1.0, lo_open=True
                ),
                conductivity=lr.number("conductivity", lo=0.0, lo_open=True),
                heat_capacity=lr.number("heat_capacity", lo=0.0, lo_open=True),
            )
        )
        lr.finish()

    rt = r.subtable("relaxation", required=False)
    rr = _Reader(source, name, rt, prefix="relaxation.")
    weights = rr.numbers("weights", [], lo=0.0)
    times = rr.numbers("times", [], lo=0.0, lo_open=True)
    rr.finish()
    if len(weights) != len(times):
        raise rr.fail("times", f"needs one entry per weight ({len(weights)}), got {len(times)}")
    if sum(weights) >= 1.0:
        raise rr.fail(
            "weights",
            f"must sum to < 1 (the long-term stiffness must stay > 0), got {sum(weights):g}",
        )

    st = r.subtable("surface")
    sr = _Reader(source, name, st, prefix="surface.")
    mu_k = sr.number("friction_kinetic", lo=0.0, lo_open=True)
    mu_s = sr.number("friction_static", lo=0.0, lo_open=True)
    if mu_s < mu_k:
        raise sr.fail("friction_static", f"must be >= friction_kinetic ({mu_k:g}), got {mu_s:g}")
    band = sr.numbers("roughness_band", [50e-6, 2e-3], length=2, lo=0.0, lo_open=True)
    if band[0] >= band[1]:
        raise sr.fail("roughness_band", f"needs shortest < longest wavelength, got {list(band)}")
    ridges = []
    for i, rt_ in enumerate(sr.table_list("ridge")):
        rg = _Reader(source, name, rt_, prefix=f"surface.ridge[{i}].")
        ridges.append(
            Ridge(
                wavelength=rg.number("wavelength", lo=0.0, lo_open=True),
                amplitude=rg.number("amplitude", lo=0.0),
                angle=rg.number("angle", 0.0, lo=-360.0, hi=360.0),
            )
        )
        rg.finish()
    surface = Surface(
        friction_static=mu_s,
        friction_kinetic=mu_k,
        roughness_rms=sr.number("roughness_rms", lo=0.0, hi=1e-3),
        roughness_band=(band[0], band[1]),
        roughness_exponent=sr.number("roughness_exponent", 0.8, lo=0.0, hi=1.0, lo_open=True),
        contact_conductance=sr.number("contact_conductance", lo=0.0, lo_open=True),
        ridges=tuple(ridges),
    )
    sr.finish()

    related = r._get("related", [])
    if not isinstance(related, list) or not all(isinstance(x, str) for x in related):
        raise r.fail("related", f"must be a list of object names, got {related!r}")
    relations = []
    for i, rt_ in enumerate(r.table_list("relation")):
        rl = _Reader(source, name, rt_, prefix=f"relation[{i}].")
        actions = rl._get("actions", _REQUIRED)
        if (
            not isinstance(actions, list)
            or not actions
            or not all(isinstance(a, str) and a for a in actions)
        ):
            raise rl.fail("actions", f"must be a non-empty list of action names, got {actions!r}")
        relations.append(
            Relation(
                prior=rl.string("prior"),
                modality=rl.string("modality"),
                actions=tuple(actions),
                why=rl.string("why", ""),
            )
        )
        rl.finish()
    related += [rel.prior for rel in relations if rel.prior not in related]
    size = r.numbers("size", [0.15, 0.15], length=2, lo=0.0, lo_open=True)
    session = r.string("session", role)
    if not _NAME.match(session):
        raise r.fail("session", "must be lower case letters, digits and '_' starting with a letter")
    spec = ObjectSpec(
        name=name,
        index=index,
        role=role,
        layers=tuple(layers),
        surface=surface,
        relaxation=Relaxation(weights, times),
        description=r.string("description", ""),
        related=tuple(related),
        relations=tuple(relations),
        height=r.number("height", 0.05, lo=0.0, lo_open=True, hi=1.0),
        size=(size[0], size[1]),
        crown_radius=r.number("crown_radius", 0.0, lo=0.0),
        waviness=r.number("waviness", 0.0, lo=0.0, hi=5e-3),
        reflectivity=r.number("reflectivity", 0.5, lo=0.0, hi=1.0),
        temperature_offset=r.number("temperature_offset", 0.0, lo=-30.0, hi=30.0),
        variability=r.number("variability", 0.05, lo=0.0, hi=0.5),
        session=session,
        source=source,
    )
    r.finish()
    if name in spec.related:
        raise r.fail("related", "an object cannot be related to itself")
    if spec.total_thickness > spec.height + 1e-12:
        raise r.fail(
            "layer",
            f"layers are {spec.total_thickness:g} m thick but the object is only "
            f"{spec.height:g} m high",
        )
    return spec


def _parse_document(doc: Mapping[str, Any], source: str, first_auto_index: int) -> list[ObjectSpec]:
    version = doc.get("schema_version", SCHEMA_VERSION)
    if version != SCHEMA_VERSION:
        raise ConfigError(
            f"{source}: field 'schema_version': this aptkt reads version {SCHEMA_VERSION}, got {version!r}"
        )
    unknown = sorted(set(doc) - {"schema_version", "object"})
    if unknown:
        raise ConfigError(
            f"{source}: unknown top-level field {unknown[0]!r} (objects go in [[object]] tables)"
        )
    tables = doc.get("object", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise ConfigError(f"{source}: field 'object': expected [[object]] tables")
    out: list[ObjectSpec] = []
    for t in tables:
        out.append(_parse_object(t, source, first_auto_index + len(out)))
    return out


def default_library() -> ObjectLibrary:
    """The package's library: the paper's 10 prior (index 1-10) and 5 new (11-15) objects."""
    ref = resources.files("aptkt.sim").joinpath("objects.toml")
    with resources.as_file(ref) as path:
        return ObjectLibrary(
            _parse_document(read_toml(Path(path), "an object library"), "objects.toml", 1)
        )


def load_library(*paths: str | Path, include_default: bool = True) -> ObjectLibrary:
    """Load object files; with ``include_default`` the package's objects come first.

    Objects without an ``index`` get the next free one after those already loaded.
    """
    objects: list[ObjectSpec] = list(default_library().values()) if include_default else []
    for p in paths:
        path = Path(p)
        next_index = max((o.index for o in objects), default=0) + 1
        objects.extend(_parse_document(read_toml(path, "an object library"), str(path), next_index))
    return ObjectLibrary(objects)
