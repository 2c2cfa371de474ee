"""Contact mechanics: indentation law of layered objects, viscoelastic relaxation, geometry.

Model (docs/simulation.md, "Indentation"):

* Every force sensor carries the pressure of its patch of skin (Winkler foundation). Its local
  indentation ``δ`` (how far the skin plane at the sensor is below the undeformed surface) is
  shared by the skin's own compliance and the object's layers in series, all at the same
  pressure ``σ``::

      δ(σ) = σ / k_skin + Σ_i h_i σ / (E_i + σ / ε_d,i)

  which is the inverse of each layer's law ``σ = E ε / (1 - ε/ε_d)`` (linear at small strain,
  locking up at the densification strain ``ε_d``). ``δ(σ)`` is monotone, so ``σ(δ)`` is
  tabulated once per trial and interpolated.
* Viscoelasticity is quasi-linear (Fung): ``σ(t) = ∫ G(t-s) dσ_e(δ(s))`` with
  ``G(t) = g_∞ + Σ w_i exp(-t/τ_i)``, integrated exactly for a ``σ_e`` that is linear between
  samples.
* The surface height under each sensor combines the object's pose (shift, rotation, tilt),
  its crown, its long-wavelength waviness and its footprint.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.sim.objects import Layer, Relaxation
from aptkt.sim.recurrence import linear_recurrence

__all__ = ["IndentationLaw", "RelaxationState", "relax", "SurfaceShape"]


class IndentationLaw:
    """Pressure ``σ(δ)`` of the skin pressed by ``δ`` metres into a layered object."""

    def __init__(self, layers: Sequence[Layer], skin_stiffness: float, modulus_scale: float = 1.0):
        if skin_stiffness <= 0:
            raise InvalidInputError("skin stiffness must be > 0")
        self.layers = tuple(layers)
        self.skin_stiffness = float(skin_stiffness)
        sigma = np.concatenate([[0.0], np.logspace(-4, 7, 4000)])
        delta = self.depth(sigma, modulus_scale)
        self._sigma, self._delta = sigma, delta
        self._modulus_scale = modulus_scale

    @property
    def table(self) -> tuple[np.ndarray, np.ndarray]:
        """The tabulated law: depths (increasing) and their pressures."""
        return self._delta, self._sigma

    def depth(self, sigma: np.ndarray, modulus_scale: float | None = None) -> np.ndarray:
        """Total indentation (skin + object) at pressure ``sigma`` (the closed-form inverse law)."""
        scale = self._modulus_scale if modulus_scale is None else modulus_scale
        sigma = np.asarray(sigma, dtype=np.float64)
        d = sigma / self.skin_stiffness
        for layer in self.layers:
            e = layer.modulus * scale
            d = d + layer.thickness * sigma / (e + sigma / layer.densification_strain)
        return d

    def object_depth(self, sigma: np.ndarray) -> np.ndarray:
        """How far the object's surface is pushed in at pressure ``sigma``."""
        return self.depth(sigma) - np.asarray(sigma) / self.skin_stiffness

    def stress(self, delta: np.ndarray) -> np.ndarray:
        """Elastic pressure (Pa) at local indentation ``delta`` (m); 0 where out of contact."""
        delta = np.asarray(delta, dtype=np.float64)
        out = np.interp(delta, self._delta, self._sigma, left=0.0)
        beyond = delta > self._delta[-1]
        if np.any(beyond):  # far beyond the table only the skin is left to compress
            out = np.where(
                beyond, self._sigma[-1] + (delta - self._delta[-1]) * self.skin_stiffness, out
            )
        return np.where(delta > 0.0, out, 0.0)


@dataclass
class RelaxationState:
    """Hereditary state of the quasi-linear viscoelastic model, one row per Prony term."""

    h: np.ndarray  # (n_terms, ...) relaxing parts of the stress
    last_elastic: np.ndarray  # (...) elastic stress at the previous sample

    @classmethod
    def rest(cls, relaxation: Relaxation, shape: tuple[int, ...]) -> RelaxationState:
        return cls(np.zeros((len(relaxation.weights), *shape)), np.zeros(shape))

    def copy(self) -> RelaxationState:
        return RelaxationState(self.h.copy(), self.last_elastic.copy())


def relax(
    relaxation: Relaxation, elastic: np.ndarray, dt: float, state: RelaxationState
) -> tuple[np.ndarray, RelaxationState]:
    """Relaxed stress for elastic stresses ``elastic`` (n, ...) sampled every ``dt`` seconds.

    Each Prony term obeys ``h[k] = a h[k-1] + w (τ/dt)(1 - a)(σ_e[k] - σ_e[k-1])``,
    ``a = exp(-dt/τ)``: the exact convolution for piecewise-linear ``σ_e``.
    """
    elastic = np.asarray(elastic, dtype=np.float64)
    if elastic.shape[0] == 0 or not relaxation.weights:
        new_last = elastic[-1] if elastic.shape[0] else state.last_elastic
        return elastic.copy(), RelaxationState(state.h.copy(), np.array(new_last, copy=True))
    increments = np.diff(elastic, axis=0, prepend=state.last_elastic[None, ...])
    out = relaxation.long_term * elastic
    new_h = np.empty_like(state.h)
    for i, (w, tau) in enumerate(zip(relaxation.weights, relaxation.times)):
        a = math.exp(-dt / tau)
        gain = w * (tau / dt) * (1.0 - a)
        h = linear_recurrence(a, gain * increments, state.h[i])
        out = out + h
        new_h[i] = h[-1]
    return out, RelaxationState(new_h, elastic[-1].copy())


@dataclass(frozen=True)
class SurfaceShape:
    """Height of an object's top face in the robot base frame (metres).

    ``centre`` (x, y) and ``rotation`` (rad) place the object frame; ``surface_z`` is the top
    face's height at the centre; ``tilt`` (slope along object x and y) makes the face lean;
    ``crown_radius`` bends it about the object's x axis; ``waves`` (k_x, k_y, amplitude, phase)
    in the object frame are its long-wavelength waviness; ``size`` bounds the face.
    """

    centre: tuple[float, float]
    rotation: float
    surface_z: float
    tilt: tuple[float, float]
    crown_radius: float
    waves: np.ndarray  # (n, 4): kx, ky (cycles/m), amplitude (m), phase (rad)
    size: tuple[float, float]

    def to_object(self, xy: np.ndarray) -> np.ndarray:
        """Base-frame (..., 2) points to object-frame coordinates."""
        c, s = math.cos(self.rotation), math.sin(self.rotation)
        d = np.asarray(xy, dtype=np.float64) - np.asarray(self.centre)
        return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], axis=-1)

    def to_object_direction(self, v: np.ndarray) -> np.ndarray:
        c, s = math.cos(self.rotation), math.sin(self.rotation)
        v = np.asarray(v, dtype=np.float64)
        return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], axis=-1)

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Surface height at base-frame points (..., 2); ``-inf`` off the face."""
        u = self.to_object(xy)
        z = self.surface_z + self.tilt[0] * u[..., 0] + self.tilt[1] * u[..., 1]
        if self.crown_radius > 0:
            z = z - u[..., 1] ** 2 / (2.0 * self.crown_radius)
        if len(self.waves):
            arg = (
                2
                * np.pi
                * (u[..., 0, None] * self.waves[:, 0] + u[..., 1, None] * self.waves[:, 1])
                + self.waves[:, 3]
            )
            z = z + np.sum(self.waves[:, 2] * np.sin(arg), axis=-1)
        inside = (np.abs(u[..., 0]) <= self.size[0] / 2) & (np.abs(u[..., 1]) <= self.size[1] / 2)
        return np.where(inside, z, -np.inf)
