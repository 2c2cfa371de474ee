"""Running sessions on a robot: the UR10 with its skin, or the simulated world in its place.

=====================  =====================================================================
sessions               live sessions: a robot and a skin that explore objects on request
collector_pauses       no garbage collection inside a live trial (it would silence the skin)
grid                   the grid of trials that generation and collection share
generation             data sets simulated on the simulated world (``aptkt dataset generate``)
collection             data sets recorded on a live session, crash-safe (``aptkt collect``)
live_learning          APTKT on a live session, every recording stored (``aptkt learn``)
=====================  =====================================================================

This wing sits above everything it runs: the robots (:mod:`aptkt.robot`), the simulated world
(:mod:`aptkt.sim`), the data sets (:mod:`aptkt.data`) and the learner (:mod:`aptkt.learning`).
Import the module you need; the package itself imports nothing.
"""
