"""Heat exchange between a warm skin cell and the object it touches.

Model (docs/simulation.md, "Heat exchange"): per cell, a linear thermal network

    C dT/dt = -K(φ, v) T + q(φ, v)

with nodes [LM71, PCB, inner cover, outer cover, object nodes top → bottom]. The PCB carries
the electronics' heat; it loses heat to the mount and the air behind; the outer cover loses
heat to the air on the uncovered part ``1 - φ`` of the cell and to the object through the
contact conductance ``h_c φ A``. The object is a 1-D column of its layers (on a wooden table)
discretised with geometrically growing node thickness, ending at the object's bulk
temperature. While the skin slides at speed ``v`` fresh object material keeps arriving, which
the column sees as a relaxation of every node to the bulk temperature at rate ``v / L_cell``.

For fixed ``(φ, v)`` the system is linear time-invariant; it is solved exactly through the
eigen-decomposition of the symmetrised matrix ``C^-1/2 K C^-1/2``, so any sample times (and
any chunking of them) give the same temperatures.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from aptkt._core import SimThermal, _flush_subnormals
from aptkt.errors import InvalidInputError
from aptkt.sim.objects import Layer
from aptkt.sim.patch import SkinConstants

__all__ = [
    "TABLE_LAYER",
    "ThermalNetwork",
    "CellThermal",
    "contact_bins",
    "speed_bins",
    "interface_level",
    "INTERFACE_LEVELS_PER_OCTAVE",
    "thermal_network",
]

#: What every object stands on (thermally): a wooden table top.
TABLE_LAYER = Layer("table top (wood)", 0.03, 1e9, 1.0, 0.15, 1.0e6)

#: Contact fractions are quantised to this many steps so that systems can be cached.
CONTACT_STEPS = 20
#: Sliding speeds are quantised to this step (m/s) for the same reason.
SPEED_STEP = 0.002

#: A trial's interface conductance is quantised to this many levels per factor of two, so that
#: an object's trials share a few networks (each decomposed once per configuration it meets).
INTERFACE_LEVELS_PER_OCTAVE = 8

_SKIN_NODES = 4  # LM71, PCB, inner cover, outer cover
_FIRST_NODE = 40e-6  # m, thickness of the first object node of every layer
_GROWTH = 1.8
_HORIZON = 60.0  # s: the column reaches 3 diffusion lengths of this time


def contact_bins(phi: np.ndarray) -> np.ndarray:
    """Quantised contact fractions (integers 0..CONTACT_STEPS)."""
    return np.clip(np.rint(np.asarray(phi) * CONTACT_STEPS), 0, CONTACT_STEPS).astype(np.int64)


def _discretise(layers: Sequence[Layer]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node thickness, conductivity and heat capacity of the object column (top first).

    Nodes grow geometrically inside each layer; the column ends once heat would need more than
    ``_HORIZON`` seconds to cross three diffusion lengths (Σ d_i / sqrt(α_i) > 3 sqrt(horizon)),
    or at the bottom of the table.
    """
    d: list[float] = []
    k: list[float] = []
    c: list[float] = []
    travel = 0.0  # Σ d / sqrt(α): square root of the diffusion time to this depth
    limit = 3.0 * math.sqrt(_HORIZON)
    for layer in layers:
        remaining = layer.thickness
        step = min(_FIRST_NODE, layer.thickness)
        while remaining > 1e-12 and travel < limit:
            take = remaining if remaining - step < 0.3 * step else step
            d.append(take)
            k.append(layer.conductivity)
            c.append(layer.heat_capacity)
            remaining -= take
            travel += take / math.sqrt(layer.diffusivity)
            step *= _GROWTH
        if travel >= limit:
            break
    return np.array(d), np.array(k), np.array(c)


@dataclass(frozen=True)
class _System:
    """Exact solution operator of one LTI configuration, in symmetrised coordinates."""

    u: np.ndarray  # (N, N) eigenvectors of S = C^-1/2 K C^-1/2
    mu: np.ndarray  # (N,) eigenvalues of S (decay rates, 1/s)
    ss_heater: np.ndarray  # (N,) steady state per watt of heater power (sources off)
    ss_ambient: np.ndarray  # (N,) steady state per kelvin of room temperature
    ss_object: np.ndarray  # (N,) steady state per kelvin of object temperature
    sqrt_c: np.ndarray  # (N,) C^1/2


class ThermalNetwork:
    """The conductances and capacities of one cell against one object (no temperatures), with
    its solution operators cached per (contact step, sliding speed). Shared by all trials of an
    object: trial temperatures only enter the steady state, which is linear in them."""

    def __init__(
        self, constants: SkinConstants, layers: tuple[Layer, ...], contact_conductance: float
    ):
        self.k = constants
        self.contact_conductance = float(contact_conductance)
        self.d, self.kc, self.rc = _discretise([*layers, TABLE_LAYER])
        self.n = _SKIN_NODES + len(self.d)
        a = constants.cell_area
        cov_c = constants.cover_heat_capacity * constants.cover_thickness * a
        self.cap = np.concatenate(
            [[0.02, constants.pcb_capacity, cov_c / 2, cov_c / 2], self.rc * self.d * a]
        )
        self._g_sens = 0.02 / constants.lm71_lag  # W/K: a 0.02 J/K sensor lagging by lm71_lag
        self._g_cov_half = constants.cover_conductivity * a / (constants.cover_thickness / 4)
        self._g_cov_mid = constants.cover_conductivity * a / (constants.cover_thickness / 2)
        self._g_obj_half = self.kc * a / (self.d / 2)  # node centre to its faces
        self._cache: dict[tuple[int, int], _System] = {}
        #: The same operators as the compiled core holds them (shared by the object's trials).
        self.core = SimThermal(self.n)

    def _build(
        self, phi: float, speed: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Conductance matrix K (symmetric) and the source vectors per watt of heater, per kelvin
        of room and per kelvin of object temperature. The network is a chain (sensor, PCB, the
        cover's halves, the object's layers), so K is tridiagonal: the conductance between
        neighbours, plus each node's conductances to the room and to the object's far side."""
        k, n, a = self.k, self.n, self.k.cell_area
        top = _SKIN_NODES
        between = np.empty(n - 1)  # between node i and node i + 1
        between[:3] = self._g_sens, self._g_cov_half, self._g_cov_mid
        between[3] = 0.0
        if phi > 0:
            between[3] = 1.0 / (
                1.0 / self._g_cov_half
                + 1.0 / (self.contact_conductance * a * phi)
                + 1.0 / self._g_obj_half[0]
            )
        between[top:] = 1.0 / (1.0 / self._g_obj_half[:-1] + 1.0 / self._g_obj_half[1:])
        q_heat, q_amb, q_obj = np.zeros(n), np.zeros(n), np.zeros(n)
        q_heat[1] = 1.0
        q_amb[1] = k.back_conductance
        # Exposed faces: cover and object surface see the air where they do not touch.
        g_air = k.air_transfer * a * (1.0 - phi)
        if g_air > 0:
            q_amb[3] = 1.0 / (1.0 / self._g_cov_half + 1.0 / g_air)
            q_amb[top] = 1.0 / (1.0 / self._g_obj_half[0] + 1.0 / g_air)
        q_obj[n - 1] = self._g_obj_half[-1]
        if speed > 0:
            q_obj[top:] += self.cap[top:] * (speed / k.pitch)  # fresh material under the cell
        diagonal = q_amb + q_obj
        diagonal[:-1] += between
        diagonal[1:] += between
        K = np.diag(diagonal) - np.diag(between, 1) - np.diag(between, -1)
        return K, q_heat, q_amb, q_obj

    def system(self, phi_bin: int, speed_bin: int) -> _System:
        key = (int(phi_bin), int(speed_bin))
        sys_ = self._cache.get(key)
        if sys_ is None:
            K, q_heat, q_amb, q_obj = self._build(phi_bin / CONTACT_STEPS, speed_bin * SPEED_STEP)
            s = 1.0 / np.sqrt(self.cap)
            # The eigenvectors of a stiff chain (metal over wood) decay through the subnormal
            # range inside LAPACK, which then runs ~100x slower (27 ms for 29 nodes); those
            # intermediates are far below any result's last bit, so they are flushed to zero.
            previous = _flush_subnormals(True)
            try:
                mu, u = np.linalg.eigh(K * s[:, None] * s[None, :])
            finally:
                _flush_subnormals(False, previous)
            ss = np.linalg.solve(K, np.stack([q_heat, q_amb, q_obj], axis=1))
            sys_ = _System(u, mu, ss[:, 0], ss[:, 1], ss[:, 2], np.sqrt(self.cap))
            self._cache[key] = sys_
        return sys_


# An object meets a dozen interface levels (interface_level), each its own network.
@functools.lru_cache(maxsize=512)
def thermal_network(
    constants: SkinConstants, layers: tuple[Layer, ...], contact_conductance: float
) -> ThermalNetwork:
    """The (cached) network of an object: built once per process, shared by all its trials."""
    return ThermalNetwork(constants, layers, contact_conductance)


def interface_level(scale: float) -> float:
    """``scale`` rounded to the nearest of the levels 2^(i / INTERFACE_LEVELS_PER_OCTAVE)."""
    if not scale > 0 or not math.isfinite(scale):
        raise InvalidInputError(f"an interface scale must be finite and > 0, got {scale!r}")
    steps = round(math.log2(scale) * INTERFACE_LEVELS_PER_OCTAVE)
    return float(2.0 ** (steps / INTERFACE_LEVELS_PER_OCTAVE))


def speed_bins(speed: np.ndarray) -> np.ndarray:
    """Sliding speeds quantised to SPEED_STEP (integers)."""
    return np.rint(np.asarray(speed) / SPEED_STEP).astype(np.int64)


class CellThermal:
    """The thermal network of a cell against an object under one trial's temperatures."""

    def __init__(
        self,
        constants: SkinConstants,
        layers: Sequence[Layer],
        contact_conductance: float,
        ambient: float,
        object_temperature: float,
        conductance_scale: float = 1.0,
    ):
        self.k = constants
        self.net = thermal_network(constants, tuple(layers), float(contact_conductance))
        self.n = self.net.n
        self.ambient = float(ambient)
        self.object_temperature = float(object_temperature)
        #: A trial's better or worse contact scales the contact fraction the heat sees.
        self.conductance_scale = float(conductance_scale)
        self._ss_cache: dict[tuple[int, int], np.ndarray] = {}

    @property
    def object_nodes(self) -> int:
        return len(self.net.d)

    def contact_bins(self, phi: np.ndarray) -> np.ndarray:
        return contact_bins(np.minimum(np.asarray(phi) * self.conductance_scale, 1.0))

    def _t_ss(self, sys_: _System) -> np.ndarray:
        return (
            self.k.heater_power * sys_.ss_heater
            + self.ambient * sys_.ss_ambient
            + self.object_temperature * sys_.ss_object
        )

    def initial_state(self, skin_offset: float = 0.0) -> np.ndarray:
        """Steady state in free air (skin warm, object at its bulk temperature) plus an offset."""
        t = self._t_ss(self.net.system(0, 0)).copy()
        t[:_SKIN_NODES] += skin_offset
        t[_SKIN_NODES:] = self.object_temperature
        return t

    def propagate(
        self, state: np.ndarray, dt: np.ndarray, phi_bin: int, speed_bin: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Temperatures of [LM71, PCB] after each elapsed time ``dt`` (s, increasing) and the full
        state after the last one, starting from ``state`` in configuration ``(phi_bin, speed_bin)``."""
        sys_ = self.net.system(phi_bin, speed_bin)
        t_ss = self._t_ss(sys_)
        z0 = sys_.u.T @ (sys_.sqrt_c * (state - t_ss))
        decay = np.exp(-np.outer(dt, sys_.mu))  # (n, N)
        rows = sys_.u[:2] / sys_.sqrt_c[:2, None]  # back to temperatures for nodes 0 and 1
        out = t_ss[:2] + (decay * z0) @ rows.T
        end = t_ss + (sys_.u @ (decay[-1] * z0)) / sys_.sqrt_c
        return out, end

    def propagate_many(
        self,
        states: np.ndarray,
        dt: np.ndarray,
        last: np.ndarray,
        phi_bins: np.ndarray,
        speed_bins_: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`propagate` for several cells at once, each in its own configuration.

        ``states`` (g, N); ``dt`` (g, L) elapsed times per cell (rows padded beyond ``last``);
        returns [LM71, PCB] temperatures (g, L, 2) and each cell's state at ``dt[i, last[i]]``.
        """
        systems = [self.net.system(int(p), int(v)) for p, v in zip(phi_bins, speed_bins_)]
        u = np.stack([x.u for x in systems])  # (g, N, N)
        mu = np.stack([x.mu for x in systems])  # (g, N)
        sqrt_c = systems[0].sqrt_c
        t_ss = np.stack(
            [
                self._t_ss_cached(int(p), int(v), x)
                for p, v, x in zip(phi_bins, speed_bins_, systems)
            ]
        )
        z0 = np.einsum("gn,gnm->gm", (states - t_ss) * sqrt_c, u)
        decay = np.exp(-dt[:, :, None] * mu[:, None, :])  # (g, L, N)
        rows = u[:, :2, :] / sqrt_c[:2, None]  # (g, 2, N)
        out = t_ss[:, None, :2] + np.einsum("gln,gkn->glk", decay * z0[:, None, :], rows)
        at_end = decay[np.arange(dt.shape[0]), last] * z0  # (g, N)
        end = t_ss + np.einsum("gm,gnm->gn", at_end, u) / sqrt_c
        return out, end

    def _t_ss_cached(self, phi_bin: int, speed_bin: int, sys_: _System) -> np.ndarray:
        key = (phi_bin, speed_bin)
        t = self._ss_cache.get(key)
        if t is None:
            t = self._ss_cache[key] = self._t_ss(sys_)
        return t
