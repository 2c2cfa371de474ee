"""What the skin touches, thermally: shared by the contact models (:mod:`.contact`,
:mod:`.object_surface`) and the simulated skin (:mod:`.tcp_skin`), in a module of its own so
that none of them imports another for it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["ThermalContact"]


@dataclass(frozen=True)
class ThermalContact:
    """What the skin touches, thermally: the object's layers (top first,
    :class:`aptkt.sim.objects.Layer`), the contact conductance of its surface (W/(m^2 K)) and
    its temperature relative to the room (K)."""

    name: str
    layers: tuple[Any, ...]
    contact_conductance: float
    temperature_offset: float = 0.0
