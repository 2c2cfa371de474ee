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

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from aptkt.sim.objects import Layer
from aptkt.sim.patch import SkinConstants

__all__ = ["TABLE_LAYER", "CellThermal", "contact_bins"]

#: What every object stands on (thermally): a wooden table top.
TABLE_LAYER = Layer("table top (wood)", 0.03, 1e9, 1.0, 0.15, 1.0e6)

#: Contact fractions are quantised to this many steps so that systems can be cached.
CONTACT_STEPS = 20

_SKIN_NODES = 4  # LM71, PCB, inner cover, outer cover
_FIRST_NODE = 20e-6  # m, thickness of the first object node of every layer
_GROWTH = 1.4
_HORIZON = 120.0  # s: the column reaches 3 diffusion lengths of this time


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

    u: np.ndarray  # (N, N) eigenvectors of S
    mu: np.ndarray  # (N,) eigenvalues of S (decay rates, 1/s)
    t_ss: np.ndarray  # (N,) steady-state temperatures
    sqrt_c: np.ndarray  # (N,) C^1/2


class CellThermal:
    """Thermal network of one cell against one object, for one trial's conditions."""

    def __init__(self, constants: SkinConstants, layers: Sequence[Layer], contact_conductance: float,
                 ambient: float, object_temperature: float):
        self.k = constants
        self.ambient = float(ambient)
        self.object_temperature = float(object_temperature)
        self.contact_conductance = float(contact_conductance)
        self.d, self.kc, self.rc = _discretise([*layers, TABLE_LAYER])
        self.n = _SKIN_NODES + len(self.d)
        a = constants.cell_area
        cov_c = constants.cover_heat_capacity * constants.cover_thickness * a
        g_sens = 0.02 / constants.lm71_lag  # W/K: a 0.02 J/K sensor lagging by lm71_lag
        self.cap = np.concatenate([[0.02, constants.pcb_capacity, cov_c / 2, cov_c / 2], self.rc * self.d * a])
        self._g_sens = g_sens
        self._g_cov_half = constants.cover_conductivity * a / (constants.cover_thickness / 4)
        self._g_cov_mid = constants.cover_conductivity * a / (constants.cover_thickness / 2)
        self._g_obj_half = self.kc * a / (self.d / 2)  # node centre to its faces
        self._cache: dict[tuple[int, float], _System] = {}

    @property
    def object_nodes(self) -> int:
        return len(self.d)

    def _build(self, phi: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
        """Conductance matrix K (symmetric) and source vector q for contact ``phi``, speed ``speed``."""
        k, n, a = self.k, self.n, self.k.cell_area
        K = np.zeros((n, n))
        q = np.zeros(n)

        def link(i: int, j: int, g: float) -> None:
            K[i, i] += g
            K[j, j] += g
            K[i, j] -= g
            K[j, i] -= g

        def ground(i: int, g: float, temp: float) -> None:
            K[i, i] += g
            q[i] += g * temp

        link(0, 1, self._g_sens)
        q[1] += k.heater_power
        ground(1, k.back_conductance, self.ambient)
        link(1, 2, self._g_cov_half)
        link(2, 3, self._g_cov_mid)
        top = _SKIN_NODES
        # Exposed faces: cover and object surface see the air where they do not touch.
        g_air = k.air_transfer * a * (1.0 - phi)
        if g_air > 0:
            ground(3, 1.0 / (1.0 / self._g_cov_half + 1.0 / g_air), self.ambient)
            ground(top, 1.0 / (1.0 / self._g_obj_half[0] + 1.0 / g_air), self.ambient)
        if phi > 0:
            g_c = 1.0 / (1.0 / self._g_cov_half + 1.0 / (self.contact_conductance * a * phi) + 1.0 / self._g_obj_half[0])
            link(3, top, g_c)
        for i in range(len(self.d) - 1):
            link(top + i, top + i + 1, 1.0 / (1.0 / self._g_obj_half[i] + 1.0 / self._g_obj_half[i + 1]))
        ground(n - 1, self._g_obj_half[-1], self.object_temperature)
        if speed > 0:
            rate = speed / k.pitch  # fresh material under the cell
            for i in range(len(self.d)):
                ground(top + i, self.cap[top + i] * rate, self.object_temperature)
        return K, q

    def system(self, phi_bin: int, speed: float) -> _System:
        key = (int(phi_bin), float(speed))
        sys_ = self._cache.get(key)
        if sys_ is None:
            K, q = self._build(phi_bin / CONTACT_STEPS, speed)
            s = 1.0 / np.sqrt(self.cap)
            S = K * s[:, None] * s[None, :]
            mu, u = np.linalg.eigh(S)
            t_ss = np.linalg.solve(K, q)
            sys_ = _System(u, mu, t_ss, np.sqrt(self.cap))
            self._cache[key] = sys_
        return sys_

    def initial_state(self, skin_offset: float = 0.0) -> np.ndarray:
        """Steady state in free air (skin warm, object at its bulk temperature) plus an offset."""
        t = self.system(0, 0.0).t_ss.copy()
        t[:_SKIN_NODES] += skin_offset
        t[_SKIN_NODES:] = self.object_temperature
        return t

    def propagate(self, state: np.ndarray, dt: np.ndarray, phi_bin: int, speed: float) -> tuple[np.ndarray, np.ndarray]:
        """Temperatures of [LM71, PCB] after each elapsed time ``dt`` (s, increasing) and the full
        state after the last one, starting from ``state`` in configuration ``(phi_bin, speed)``."""
        sys_ = self.system(phi_bin, speed)
        z0 = sys_.u.T @ (sys_.sqrt_c * (state - sys_.t_ss))
        decay = np.exp(-np.outer(dt, sys_.mu))  # (n, N)
        rows = sys_.u[:2] / sys_.sqrt_c[:2, None]  # back to temperatures for nodes 0 and 1
        out = sys_.t_ss[:2] + (decay * z0) @ rows.T
        end = sys_.t_ss + (sys_.u @ (decay[-1] * z0)) / sys_.sqrt_c
        return out, end
