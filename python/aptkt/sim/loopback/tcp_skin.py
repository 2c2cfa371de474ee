"""The loopback controller's simulated skin: the patch on its TCP, streamed through a pty.

Every control cycle the controller knows where its TCP is and what its contact model pushes
back with. :class:`SimulatedSkin` turns that into what the 7-cell patch on the tool flange
would send: sensor packets of every cell at ``rate_hz`` (sample times on the controller's
clock, the TCP position interpolated between control cycles), quantised by
:func:`aptkt.skin.quantize` and framed by :func:`aptkt.skin.encode_sensor_packets`, written to
a pseudo-terminal. An unmodified :class:`~aptkt.skin.SerialSkin` opens :attr:`SimulatedSkin.port`
and reads it exactly as it reads the USB adapter, while ``ur_rtde`` drives the same
controller: hardware-in-the-loop on one machine.

What each field carries:

* **force** — the contact model's per-sensor forces (``sensor_forces(pose)``; models without it
  share the normal force equally over the 21 sensors), plus Gaussian noise, turned into
  normalised readings with the *reader's* patch calibration (so the reader gets newtons back);
* **acceleration** — gravity plus the TCP's acceleration (from the controller's velocity),
  in the tool frame (the cells' axes: x, y in the skin plane, z out of the skin), plus, while
  sliding on an object of the simulated world, the vibration of its texture
  (:func:`aptkt.sim.texture.texture_acceleration`), plus noise;
* **temperature** — each cell's heat exchange with what it touches, through the simulated
  world's thermal network (:class:`aptkt.sim.thermal.CellThermal`: the cell's electronics
  warm it, the object draws heat through the contact area); the LM71 and, 1.5 K warmer, the
  accelerometer's die; objects without a thermal description count as a wooden block;
* **proximity** — a constant "nothing in front" reading plus noise.

Not modelled: the patch's imperfections (calibration errors, crooked cells, clock drift
between cells — all cells sample in lock-step), stick-slip, the arm's own vibration, the
viscoelastic relaxation of soft objects, packet jitter and latency. Faults can be injected:
:meth:`SimulatedSkin.silence` mutes cells (or all of them: an unplugged patch).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.sim.loopback.rotvec import rotvec_to_matrix
from aptkt.sim.loopback.thermal_contact import ThermalContact
from aptkt.sim.objects import Layer
from aptkt.sim.patch import SkinConstants
from aptkt.sim.physics import GRAVITY
from aptkt.sim.skin_stream import PtySkinLink
from aptkt.sim.thermal import CellThermal, speed_bins
from aptkt.skin import encode_sensor_packets, quantize
from aptkt.skin.config import PatchConfig, default_patch, load_patch
from aptkt.skin.protocol import PACKET_RATE_HZ

__all__ = ["SkinConfig", "SimulatedSkin", "GENERIC_BLOCK"]

#: Thermal stand-in for contact models that do not describe their material: a 2 cm wooden block.
GENERIC_BLOCK = ThermalContact(
    "generic block (wood)",
    (Layer("wood", 0.02, 1e9, 1.0, 0.15, 1.0e6),),
    contact_conductance=1000.0,
)


@dataclass
class SkinConfig:
    """The loopback skin's settings (JSON-able: they cross the controller's process pipe)."""

    #: Sensor packets per cell and second.
    rate_hz: float = PACKET_RATE_HZ
    #: Patch file of the *reader* (cell ids and force calibration); None: the default patch.
    patch: str | None = None
    force_noise: float = 1.5e-3  # N rms per force sensor
    acc_noise: float = 0.004  # g rms per axis
    temp_noise: float = 0.012  # °C rms (LM71)
    die_temp_noise: float = 0.15  # °C rms (accelerometer die)
    proximity: float = 0.03  # reading with nothing in front
    proximity_noise: float = 1.0e-3
    ambient: float = 24.0  # °C, the room (and the objects, plus their own offset)
    texture: bool = True  # texture vibration of simulated-world objects while sliding
    seed: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate_hz) and 0 < self.rate_hz <= 1000):
            raise InvalidInputError(f"skin rate_hz must be in (0, 1000], got {self.rate_hz!r}")
        for name in ("force_noise", "acc_noise", "temp_noise", "die_temp_noise", "proximity_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"skin {name} must be >= 0, got {value!r}")

    @classmethod
    def from_spec(cls, spec: Mapping[str, Any] | bool | None) -> SkinConfig | None:
        """``True``/``{}``: defaults; a mapping: those fields; ``None``/``False``: no skin."""
        if spec is None or spec is False:
            return None
        if spec is True:
            return cls()
        unknown = set(spec) - set(cls.__dataclass_fields__)
        if unknown:
            raise InvalidInputError(f"skin: unknown setting(s) {sorted(unknown)}")
        return cls(**dict(spec))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class SimulatedSkin:
    """The patch on the loopback's TCP. :meth:`step` runs once per control cycle (the
    controller calls it at the end of its tick, lock held) and writes the packets due since
    the previous cycle to ``link`` (a :class:`aptkt.sim.skin_stream.PtySkinLink` unless given)."""

    def __init__(self, config: SkinConfig | None = None, link: Any = None):
        self.config = config or SkinConfig()
        patch: PatchConfig = load_patch(self.config.patch) if self.config.patch else default_patch()
        self.patch = patch
        self.cell_ids = np.asarray(patch.cell_ids, dtype=np.int64)
        self.n = len(self.cell_ids)
        self._calibration = patch.calibration()
        self._centres = patch.positions_mm[:, :2] * 1e-3  # (n, 2) m
        self.constants = SkinConstants()
        if link is None:
            link = PtySkinLink()
        self.link = link
        self._rng = np.random.default_rng(self.config.seed)
        self._period = 1.0 / self.config.rate_hz
        self._t: float | None = None
        self._pose = np.zeros(6)
        self._velocity = np.zeros(3)
        self._next_k = 0
        self._silent: set[int] = set()
        self._thermal: CellThermal | None = None
        self._thermal_key: ThermalContact | None = None
        self._thermal_state = np.zeros((self.n, 0))
        self._thermal_t = 0.0
        self.packets = 0
        self.latest_force = np.zeros((self.n, 3))
        self.latest_temp = np.full((self.n, 2), np.nan)

    @property
    def port(self) -> str | None:
        """Path of the pty a :class:`~aptkt.skin.SerialSkin` opens (None for other links)."""
        return getattr(self.link, "port", None)

    def close(self) -> None:
        close = getattr(self.link, "close", None)
        if callable(close):
            close()

    # ------------------------------------------------------------------ faults
    def silence(self, cells: Iterable[int] | None = None) -> None:
        """Mute these cells (ids; None: every cell, as if the patch were unplugged)."""
        ids = set(self.cell_ids.tolist()) if cells is None else {int(c) for c in cells}
        unknown = ids - set(self.cell_ids.tolist())
        if unknown:
            raise InvalidInputError(
                f"no cell(s) {sorted(unknown)} in the patch {self.patch.name!r}"
            )
        self._silent |= ids

    def restore(self) -> None:
        """Every cell sends again."""
        self._silent.clear()

    def stats(self) -> dict[str, Any]:
        return {
            "port": self.port,
            "rate_hz": self.config.rate_hz,
            "patch": self.patch.name,
            "packets": self.packets,
            "bytes_written": getattr(self.link, "bytes_written", None),
            "bytes_dropped": getattr(self.link, "bytes_dropped", None),
            "bytes_received": getattr(self.link, "bytes_received", None),
            "silent_cells": sorted(self._silent),
            "thermal_object": None if self._thermal_key is None else self._thermal_key.name,
            "temperature_lm71": (
                float(np.mean(self.latest_temp[:, 1]))
                if np.all(np.isfinite(self.latest_temp))
                else None
            ),
        }

    # ------------------------------------------------------------------ the control cycle
    def step(self, controller: Any) -> int:
        """Write the packets due between the previous cycle and ``controller.time``; returns
        how many sample times that were."""
        t1 = float(controller.time)
        pose1 = np.asarray(controller.pose, dtype=np.float64).copy()
        vel1 = np.asarray(controller.velocity[:3], dtype=np.float64).copy()
        contact = controller.contact
        if self._t is None:
            self._t, self._pose, self._velocity = t1, pose1, vel1
            self._next_k = math.floor(t1 / self._period) + 1
            self._update_thermal_object(contact, pose1, t1)
            return 0
        t0, pose0, vel0 = self._t, self._pose, self._velocity
        self._t, self._pose, self._velocity = t1, pose1, vel1
        last_k = math.floor(t1 / self._period + 1e-9)
        if last_k < self._next_k or t1 <= t0:
            return 0
        ks = np.arange(self._next_k, last_k + 1)
        self._next_k = last_k + 1
        ts = ks * self._period
        alpha = np.clip((ts - t0) / (t1 - t0), 0.0, 1.0)
        xyz = pose0[:3] + alpha[:, None] * (pose1[:3] - pose0[:3])  # (L, 3)
        acc_tcp = (vel1 - vel0) / (t1 - t0)

        forces = np.stack(
            [self._sensor_forces(contact, np.concatenate([p, pose1[3:]])) for p in xyz]
        )  # (L, n, 3)
        pressure = forces.mean(axis=2) / self.constants.sensor_area  # (L, n) Pa
        temps = self._temperatures(contact, pose1, ts, pressure[-1], vel1)  # (n, L, 2) [LM71, PCB]

        rot = rotvec_to_matrix(pose1[3:])  # columns: tool axes in the base frame
        specific = np.broadcast_to(
            acc_tcp + np.array([0.0, 0.0, GRAVITY]), forces.shape
        )  # (L, n, 3)
        if self.config.texture and np.any(pressure > 0) and float(np.hypot(*vel1[:2])) > 1e-6:
            method = getattr(contact, "texture_acceleration", None)
            if callable(method):
                # Cell positions as the contact models place the sensors: patch x/y along
                # base x/y (the simulated world's convention for a skin facing down).
                cells_xy = xyz[:, None, :2] + self._centres[None]  # (L, n, 2)
                tex = method(cells_xy.reshape(-1, 2), vel1, pressure.reshape(-1))
                specific = specific + np.asarray(tex).reshape(forces.shape)
        acc_g = specific @ rot / GRAVITY  # rows: R^T a, the reading in the cells' axes

        self._write(forces, acc_g, temps)
        return int(ks.size)

    def _sensor_forces(self, contact: Any, pose: np.ndarray) -> np.ndarray:
        method = getattr(contact, "sensor_forces", None)
        if callable(method):
            f = np.asarray(method(pose), dtype=np.float64)
            if f.shape == (self.n, 3):
                return np.maximum(f, 0.0)
        # Without a per-sensor model (or for a patch other than the nominal 7 cells) the
        # sensors share the normal force equally.
        return np.full((self.n, 3), max(float(contact.normal_force(pose)), 0.0) / (3 * self.n))

    def _update_thermal_object(self, contact: Any, pose: np.ndarray, t: float) -> None:
        method = getattr(contact, "thermal_contact", None)
        touched = (method(pose) if callable(method) else None) or GENERIC_BLOCK
        if touched == self._thermal_key:
            return
        thermal = CellThermal(
            self.constants,
            touched.layers,
            touched.contact_conductance,
            self.config.ambient,
            self.config.ambient + touched.temperature_offset,
        )
        state = np.tile(thermal.initial_state(), (self.n, 1))
        if self._thermal is not None:
            # A new object under the skin: the cells keep their own temperatures, the object
            # starts at its bulk temperature.
            skin_nodes = thermal.n - thermal.object_nodes
            state[:, :skin_nodes] = self._thermal_state[:, :skin_nodes]
        else:
            self._thermal_t = t
        self._thermal, self._thermal_key, self._thermal_state = thermal, touched, state

    def _temperatures(
        self,
        contact: Any,
        pose: np.ndarray,
        ts: np.ndarray,
        pressure: np.ndarray,
        velocity: np.ndarray,
    ) -> np.ndarray:
        if np.any(pressure > 0):
            self._update_thermal_object(contact, pose, float(ts[0]))
        thermal = self._thermal
        assert thermal is not None
        k = self.constants
        phi = thermal.contact_bins(pressure / (pressure + k.contact_pressure_half))
        speed = float(np.hypot(velocity[0], velocity[1]))
        v_bins = np.where(pressure > 0, speed_bins(np.full(self.n, speed)), 0)
        dt = np.tile(np.maximum(ts - self._thermal_t, 0.0), (self.n, 1))
        last = np.full(self.n, ts.size - 1)
        out, end = thermal.propagate_many(self._thermal_state, dt, last, phi, v_bins)
        self._thermal_state = end
        self._thermal_t = float(ts[-1])
        return out

    def _write(self, forces: np.ndarray, acc_g: np.ndarray, temps: np.ndarray) -> None:
        cfg, rng = self.config, self._rng
        n_t = forces.shape[0]
        keep = ~np.isin(self.cell_ids, list(self._silent))
        # Rows time-major: at each sample time every (sending) cell, in patch order.
        cells = np.tile(self.cell_ids, n_t)
        mask = np.tile(keep, n_t)
        f = forces.reshape(-1, 3) + cfg.force_noise * rng.standard_normal((cells.size, 3))
        acc = acc_g.reshape(-1, 3) + cfg.acc_noise * rng.standard_normal((cells.size, 3))
        t = temps.transpose(1, 0, 2).reshape(-1, 2)  # (L*n, [LM71, PCB])
        temp = np.stack(
            [
                t[:, 1]
                + self.constants.die_self_heating
                + cfg.die_temp_noise * rng.standard_normal(cells.size),
                t[:, 0] + cfg.temp_noise * rng.standard_normal(cells.size),
            ],
            axis=1,
        )
        prox = cfg.proximity + cfg.proximity_noise * rng.standard_normal(cells.size)
        self.latest_force = forces[-1]
        self.latest_temp = temp[-self.n :]
        if not mask.any():
            return
        cells, f, acc, temp, prox = cells[mask], f[mask], acc[mask], temp[mask], prox[mask]
        raw = quantize(
            cells, np.clip(prox, 0.0, None), acc, temp, self._calibration.to_normalised(cells, f)
        )
        self.link.write(encode_sensor_packets(raw))
        self.packets += int(cells.size)
