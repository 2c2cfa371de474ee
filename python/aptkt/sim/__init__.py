"""Every stand-in for the hardware. The simulated world: objects, contact physics, a skin that
speaks the wire protocol and a robot on simulated time (docs/simulation.md); and the loopback
UR controller with its simulated skin, for the real UR10 backend without an arm
(:mod:`aptkt.sim.loopback`, docs/ur10.md).

>>> from aptkt.sim import SimWorld
>>> rec = SimWorld(seed=0).explore("rough_sponge", "P2", trial=0)
"""

from aptkt.sim.drift import RecordingDrift, Wander
from aptkt.sim.noise import NoiseLevel
from aptkt.sim.objects import ObjectLibrary, ObjectSpec, default_library, load_library
from aptkt.sim.robot import SimRobot
from aptkt.sim.skin_stream import PtySkinLink, SimSkin
from aptkt.sim.trial import TrialConditions, TrialVariation
from aptkt.sim.world import SimSession, SimWorld

__all__ = [
    "SimWorld",
    "SimSession",
    "SimRobot",
    "SimSkin",
    "PtySkinLink",
    "ObjectLibrary",
    "ObjectSpec",
    "default_library",
    "load_library",
    "TrialConditions",
    "TrialVariation",
    "RecordingDrift",
    "Wander",
    "NoiseLevel",
]
