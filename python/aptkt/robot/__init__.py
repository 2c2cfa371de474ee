"""Robots that carry the skin: the interface every backend implements and the UR10 backend.

The simulated arm and the loopback UR controller, which stand in for the hardware, are in
:mod:`aptkt.sim`."""

from aptkt.robot.base import ForceReading, Placement, Robot, SafetyLimits, TimedForceReading
from aptkt.robot.ur10 import UR10
from aptkt.robot.workspace import WorkspaceConfig, load_workspace

__all__ = [
    "Robot",
    "SafetyLimits",
    "Placement",
    "ForceReading",
    "TimedForceReading",
    "UR10",
    "WorkspaceConfig",
    "load_workspace",
]
