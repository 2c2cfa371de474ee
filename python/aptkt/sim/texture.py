"""Vibration from sliding: surface texture and stick-slip.

Texture (docs/simulation.md, "Vibration"): the surface height is a sum of plane waves in the
object frame, ``h(u) = Σ A_k sin(2π κ_k·u + φ_k)`` — the object's periodic ridges plus a
self-affine random roughness (``A_k ∝ |κ_k|^-H`` over the roughness band). A cell moving with
object-frame velocity ``w`` meets component k at the temporal frequency ``f_k = |κ_k·w|``;
following the surface it accelerates normal to it by ``-A_k (2π f_k)^2 sin(...)``. What the
BMA250 reports is that motion shaped by

* the cover's smoothing of short wavelengths ``exp(-(π ℓ |κ|)^2)``,
* the base-excitation transmissibility of the cell on its contact stiffness (resonance f_n,
  damping ζ), ``(1 + 2iζr) / (1 - r^2 + 2iζr)``, ``r = f/f_n``,
* the compliance of the surface ``sqrt(E/(E + E_ref))`` and the contact pressure
  ``p/(p + p_ref)`` (the harder the skin is pressed, the better it follows the texture),
* the accelerometer's low-pass ``1/(1 + i f/f_bw)``; sampling at 250 Hz then aliases.

Friction turns the normal-load ripple into a tangential ripple ``β_t μ_k a_n / (1 + r^2)``
(dominant at low frequency), and obliquely oriented texture pushes the cell sideways.

Stick-slip: a spring-block per cell (tangential stiffness k_t, mass m_t). Slow sliding
(``v < v_c = Δμ F / sqrt(k_t m_t)``, ``Δμ = μ_s - μ_k``) sticks until the spring force reaches
``μ_s F`` (jittered per event), then slips, dropping the force by ``2 Δμ F s`` with strength
``s = 1 - v/v_c``. Each slip rings the cover's shear mode as a damped sinusoid of peak
``2 Δμ F s / m_t``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from aptkt import _core
from aptkt.sim.objects import ObjectSpec
from aptkt.sim.patch import SkinConstants
from aptkt.sim.seeding import CounterStream, seed_sequence

__all__ = ["TextureField", "texture_field", "waviness_waves", "texture_acceleration", "StickSlip"]

_RANDOM_COMPONENTS = 40


@dataclass(frozen=True)
class TextureField:
    """Plane waves of the surface height in the object frame."""

    kvec: np.ndarray  # (M, 2) cycles per metre
    amplitude: np.ndarray  # (M,) m
    phase: np.ndarray  # (M,) rad

    def scaled(self, factor: float) -> TextureField:
        return TextureField(self.kvec, self.amplitude * factor, self.phase)

    def rms(self) -> float:
        return float(np.sqrt(np.sum(self.amplitude**2) / 2.0))


@functools.lru_cache(maxsize=256)
def texture_field(obj: ObjectSpec) -> TextureField:
    """The object's own texture: a property of the object, seeded by its name only (made once
    per object and process; the arrays are read-only)."""
    rng = np.random.default_rng(seed_sequence(0, "texture", obj.name))
    s = obj.surface
    k, a, ph = [], [], []
    for ridge in s.ridges:
        ang = math.radians(ridge.angle)
        q = 1.0 / ridge.wavelength
        k.append((q * math.cos(ang), q * math.sin(ang)))
        a.append(ridge.amplitude)
        ph.append(rng.uniform(0, 2 * np.pi))
    if s.roughness_rms > 0:
        q_lo, q_hi = 1.0 / s.roughness_band[1], 1.0 / s.roughness_band[0]
        edges = np.geomspace(q_lo, q_hi, _RANDOM_COMPONENTS + 1)
        qs = edges[:-1] * (edges[1:] / edges[:-1]) ** rng.uniform(0, 1, _RANDOM_COMPONENTS)
        amp = qs**-s.roughness_exponent
        amp *= s.roughness_rms / np.sqrt(np.sum(amp**2) / 2.0)
        theta = rng.uniform(0, np.pi, _RANDOM_COMPONENTS)
        for qi, ai, ti in zip(qs, amp, theta):
            k.append((qi * math.cos(ti), qi * math.sin(ti)))
            a.append(ai)
            ph.append(rng.uniform(0, 2 * np.pi))
    if not k:
        return TextureField(np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    return TextureField(_frozen(np.array(k)), _frozen(np.array(a)), _frozen(np.array(ph)))


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@functools.lru_cache(maxsize=256)
def waviness_waves(obj: ObjectSpec, n: int = 4) -> np.ndarray:
    """Long-wavelength unevenness (wavelengths 10-60 mm) as rows (k_x, k_y, amplitude, phase),
    made once per object and process (read-only)."""
    if obj.waviness <= 0:
        return np.zeros((0, 4))
    rng = np.random.default_rng(seed_sequence(0, "waviness", obj.name))
    lam = rng.uniform(0.010, 0.060, n)
    theta = rng.uniform(0, np.pi, n)
    amp = rng.uniform(0.5, 1.0, n)
    amp *= obj.waviness / np.sqrt(np.sum(amp**2) / 2.0)
    return _frozen(
        np.stack(
            [np.cos(theta) / lam, np.sin(theta) / lam, amp, rng.uniform(0, 2 * np.pi, n)], axis=1
        )
    )


def texture_acceleration(
    field_: TextureField,
    k: SkinConstants,
    u: np.ndarray,
    w: np.ndarray,
    pressure: np.ndarray,
    top_modulus: float,
    mu_kinetic: float,
) -> np.ndarray:
    """Texture-driven acceleration (n, 3) in m/s^2 as (along the motion, lateral, normal-up).

    ``u`` (n, 2) are the cell centre's object-frame positions, ``w`` (n, 2) its object-frame
    velocity, ``pressure`` (n,) the cell's mean contact pressure.
    """
    n = u.shape[0]
    out = np.zeros((n, 3))
    speed = np.hypot(w[:, 0], w[:, 1])
    active = (speed > 1e-6) & (pressure > 0)
    if not np.any(active) or field_.amplitude.size == 0:
        return out
    ua, wa, pa, sa = u[active], w[active], pressure[active], speed[active]
    kv = field_.kvec  # (M, 2)
    f = np.abs(wa @ kv.T)  # (n, M) temporal frequency of each component
    qnorm = np.hypot(kv[:, 0], kv[:, 1])
    smooth = np.exp(-((np.pi * k.cover_contact_length * qnorm) ** 2))  # (M,)
    r = f / k.contact_resonance
    h_t = (1 + 2j * k.contact_damping * r) / (1 - r**2 + 2j * k.contact_damping * r)
    h_l = 1.0 / (1 + 1j * f / k.acc_bandwidth)
    h = h_t * h_l
    coupling = (
        math.sqrt(top_modulus / (top_modulus + k.coupling_modulus))
        * pa
        / (pa + k.coupling_pressure)
    )
    phase = 2 * np.pi * (ua @ kv.T) + field_.phase  # (n, M)
    base = -(field_.amplitude * smooth) * (2 * np.pi * f) ** 2 * np.abs(h)  # (n, M)
    arg = phase + np.angle(h)
    normal = base * np.sin(arg)
    tangential = k.tangential_coupling * mu_kinetic * normal / (1.0 + r**2)
    # Sine of the angle between the wave vector and the motion: oblique texture pushes sideways.
    cross = (wa[:, 0:1] * kv[None, :, 1] - wa[:, 1:2] * kv[None, :, 0]) / (
        sa[:, None] * np.maximum(qnorm, 1e-12)
    )
    lateral = k.lateral_coupling * cross * base * np.cos(arg)
    out[active, 0] = coupling * tangential.sum(axis=1)
    out[active, 1] = coupling * lateral.sum(axis=1)
    out[active, 2] = coupling * normal.sum(axis=1)
    return out


@dataclass
class StickSlipState:
    load: np.ndarray  # (7,) N, tangential spring force of each cell
    threshold: np.ndarray  # (7,) N, static friction to overcome for the next slip
    events: np.ndarray  # (7,) int, slips so far (the random stream's counter)
    ringing: list[list[tuple[float, float]]] = field(
        default_factory=list
    )  # per cell: (t_s, peak m/s^2)

    def copy(self) -> StickSlipState:
        return StickSlipState(
            self.load.copy(),
            self.threshold.copy(),
            self.events.copy(),
            [list(r) for r in self.ringing],
        )


class StickSlip:
    """Spring-block stick-slip of each cell; see the module docstring."""

    def __init__(
        self,
        k: SkinConstants,
        mu_static: float,
        mu_kinetic: float,
        seq: np.random.SeedSequence,
        n_cells: int = 7,
    ):
        self.k = k
        self.mu_s, self.mu_k = mu_static, mu_kinetic
        self._streams = [
            CounterStream(
                np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, 9000 + c)), 2
            )
            for c in range(n_cells)
        ]
        self.n_cells = n_cells
        self._omega = 2 * np.pi * k.slip_ring_frequency
        self._decay = k.slip_ring_damping * self._omega
        h = 1.0 / (1 + 1j * k.slip_ring_frequency / k.acc_bandwidth)
        self._gain, self._lag = abs(h), float(np.angle(h))
        #: The spring-block and its ringing as the compiled core takes them.
        self.params = _core.SlipParams(
            float(mu_static),
            float(mu_kinetic),
            float(k.tangential_stiffness),
            float(k.tangential_mass),
            float(k.slip_threshold_sd),
            float(k.rate_hz),
            _core.Ringing(
                float(k.slip_coupling),
                float(self._omega),
                float(self._decay),
                float(self._gain),
                float(self._lag),
            ),
        )

    def rest(self) -> StickSlipState:
        n = self.n_cells
        return StickSlipState(
            np.zeros(n), np.full(n, np.inf), np.zeros(n, dtype=np.int64), [[] for _ in range(n)]
        )

    def run(
        self,
        state: StickSlipState,
        cell: int,
        t: np.ndarray,
        path: np.ndarray,
        force: np.ndarray,
        speed: np.ndarray,
    ) -> np.ndarray:
        """Tangential acceleration (n,) m/s^2 of ``cell`` at sample times ``t`` (s).

        ``path`` (n,) is the sliding distance covered since the previous sample, ``force`` (n,)
        the cell's normal force, ``speed`` (n,) its sliding speed. Updates ``state`` in place.
        The loop runs in the compiled core (``aptkt_sim::slip``); its numpy formulation is the
        tests' reference (tests/sim/numpy_reference.py).
        """
        one = _core.SlipState(
            float(state.load[cell]),
            float(state.threshold[cell]),
            int(state.events[cell]),
            [(float(a), float(b)) for a, b in state.ringing[cell]],
        )
        out = _core.sim_slip(
            self.params,
            self._streams[cell].key,
            one,
            np.ascontiguousarray(t, dtype=np.float64),
            np.ascontiguousarray(path, dtype=np.float64),
            np.ascontiguousarray(force, dtype=np.float64),
            np.ascontiguousarray(speed, dtype=np.float64),
        )
        state.load[cell], state.threshold[cell], state.events[cell] = (
            one.load,
            one.threshold,
            one.events,
        )
        state.ringing[cell] = list(one.ring)
        return out
