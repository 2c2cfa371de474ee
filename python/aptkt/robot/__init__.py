"""Robots that carry the skin: the interface, the simulated arm and the UR10 backend."""

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
