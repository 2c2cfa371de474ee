"""The UR10 backend: exploratory movements through ur_rtde with safety enforced in code.

Every movement is sent as an asynchronous or speed command and then *supervised* from Python
at the controller's RTDE rate (125 Hz on CB3, 500 Hz on e-Series). Each cycle checks, in
this order: the link (connected, fresh robot data), protective/emergency stop, the control
program, measured TCP speed and acceleration, the TCP wrench along the surface normal, the
skin's total normal force (and its freshness), and the workspace box of the current object.
Any violation stops the arm, retracts it upwards when the arm is still under control, and
raises a typed error (:class:`~aptkt.errors.SafetyLimitError`,
:class:`~aptkt.errors.ProtectiveStopError`, :class:`~aptkt.errors.ProgramStoppedError`,
:class:`~aptkt.errors.RobotConnectionError`, or the skin's own
:class:`~aptkt.errors.SkinError`).

Why supervise instead of blocking calls: a blocking ``moveL`` cannot be interrupted by a
skin reading, and after a lost connection ur_rtde waits for its (now stale) state for up to
300 s. So once the link is found lost, this class sends nothing more to the controller; the
controller's own RTDE watchdog (armed at connect, ``1 / limits.watchdog_timeout`` Hz) stops
the program on its side. While the arm is idle the control client's process feeds that
watchdog (no work of this process can delay it); during a movement only the supervision loop
does, so a stalled loop stops the arm too.

One module per concern, composed by :class:`UR10` (:mod:`~aptkt.robot.ur10.arm`):

- :mod:`~aptkt.robot.ur10.connection`: ur_rtde's receive client, link freshness, the
  controller's watchdog, the one lock of every control call;
- :mod:`~aptkt.robot.ur10.control`: ur_rtde's control client in a process of its own, killed
  the moment the link is suspect (ur_rtde's own reconnect is not safe in-process);
- :mod:`~aptkt.robot.ur10.supervisor`: the limit checks of every supervision cycle;
- :mod:`~aptkt.robot.ur10.motions`: the Robot protocol's motions, fault stop and retract;
- :mod:`~aptkt.robot.ur10.sampling`: the skin's force reading and the trace of samples.
"""

from aptkt.robot.ur10.arm import UR10

__all__ = ["UR10"]
