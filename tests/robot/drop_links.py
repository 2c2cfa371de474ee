"""Drop the controller link in the middle of a press, ``N`` times, each followed by the close
of the arm (``python drop_links.py N``; prints one line per survived drop). Run in its own
process by ``test_link_drops.py``: a crash kills the process, not the tests. A crash prints
every thread's stack; a drop taking longer than ``PER_DROP_TIMEOUT`` s prints them and exits
(code 1), so a hang is a failure with its cause, not a stuck run."""

from __future__ import annotations

import faulthandler
import gc
import sys
import time

from loopback_helpers import (
    DEFAULT_CONTACT,
    FAST,
    PLACEMENT,
    START_POSE,
    FakeSkin,
    fire_after,
    free_loopback_host,
    in_contact,
)

from aptkt.errors import RobotError
from aptkt.robot import UR10, SafetyLimits
from aptkt.sim.loopback import Loopback

# One drop takes about 2 s (1 s of it waiting); 60 s means something hangs.
PER_DROP_TIMEOUT = 60.0


def main(n: int) -> None:
    faulthandler.enable(all_threads=True)
    with Loopback(
        free_loopback_host(), contact=DEFAULT_CONTACT, start_pose=START_POSE, unlock_delay=0.0
    ) as lb:
        skin = FakeSkin(lb)
        for i in range(n):
            faulthandler.dump_traceback_later(PER_DROP_TIMEOUT, exit=True)
            lb.reset(pose=START_POSE)
            lb.set_contact(DEFAULT_CONTACT)
            robot = UR10(lb.host, [PLACEMENT], SafetyLimits(**FAST))
            try:
                in_contact(robot, skin)
                fire_after(0.3, lambda: lb.drop_connections())
                robot.press(0.001, 3.0)
                raise AssertionError("the press ended although the link was dropped")
            except RobotError as exc:
                # The type decides; the message says why when a drop is reported otherwise.
                reason = f"{type(exc).__name__} ({' '.join(str(exc).split())[:200]})"
            finally:
                robot.close()  # the path of a live session's __exit__
            del robot
            gc.collect()
            time.sleep(0.7)  # the crashes came 0.55 s after the drop
            print(f"drop {i + 1}: {reason}, survived", flush=True)
        faulthandler.cancel_dump_traceback_later()


if __name__ == "__main__":
    main(int(sys.argv[1]))
