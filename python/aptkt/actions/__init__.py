"""Exploratory actions: what they are and how one is carried out.

=====================  =====================================================================
definition             actions as data (a name, a movement, its parameters); the paper's
                       seven (:data:`PAPER_ACTIONS`); user actions from TOML
executor               :func:`explore`: one action on any :class:`~aptkt.robot.Robot` with any
                       :class:`~aptkt.skin.SkinSource` (paper §5.2), shared by every backend
=====================  =====================================================================

The executor talks only to the robot and skin protocols, so it sits below every backend that
uses it: the simulated world (:mod:`aptkt.sim`) and the live sessions (:mod:`aptkt.runtime`).
"""

from aptkt.actions.definition import (
    MODALITIES_BY_MOVEMENT,
    PAPER_ACTIONS,
    ExploratoryAction,
    Movement,
    actions_from_toml,
)
from aptkt.actions.executor import ExplorationSettings, crop_recording, explore

__all__ = [
    "Movement",
    "ExploratoryAction",
    "PAPER_ACTIONS",
    "MODALITIES_BY_MOVEMENT",
    "actions_from_toml",
    "ExplorationSettings",
    "explore",
    "crop_recording",
]
