"""A loopback UR controller: try the UR10 backend, and test it, without an arm.

It speaks enough of the real protocols for the real ``ur_rtde`` client — RTDE (30004), the
dashboard server (29999), the script ports (30001-30003) and the register handshake of
ur_rtde's control script — and integrates the TCP kinematically against a pluggable contact
model. With ``skin=True`` (``--skin-pty``) a simulated skin patch on the TCP streams the skin's
wire protocol through a pty for the real :class:`~aptkt.skin.SerialSkin`
(:mod:`aptkt.sim.loopback.tcp_skin`). See ``docs/ur10.md`` for what it covers and what it does not.

Run one in a terminal with ``python -m aptkt.sim.loopback``; in code use :class:`Loopback`
(a child process: ur_rtde's constructors hold the GIL, so the controller cannot share the
client's interpreter).
"""

from aptkt.sim.loopback.config import CB3_VERSION, E_SERIES_VERSION, ControllerConfig
from aptkt.sim.loopback.contact import ContactModel, NoContact, Scene, SpringSurface
from aptkt.sim.loopback.controller import SimulatedController
from aptkt.sim.loopback.process import Loopback, LoopbackError
from aptkt.sim.loopback.script import SUPPORTED_COMMANDS
from aptkt.sim.loopback.servers import LoopbackServer

__all__ = [
    "Loopback",
    "LoopbackError",
    "LoopbackServer",
    "SimulatedController",
    "ControllerConfig",
    "ContactModel",
    "SpringSurface",
    "NoContact",
    "Scene",
    "SUPPORTED_COMMANDS",
    "CB3_VERSION",
    "E_SERIES_VERSION",
]
