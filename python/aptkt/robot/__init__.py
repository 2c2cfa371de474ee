"""Robots that carry the skin: the interface, the simulated arm and the UR10 backend."""

from aptkt.robot.base import ForceReading, Placement, Robot, SafetyLimits

__all__ = ["Robot", "SafetyLimits", "Placement", "ForceReading"]
