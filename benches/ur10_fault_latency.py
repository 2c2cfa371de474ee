"""How fast the UR10 backend notices each fault, through the real ur_rtde client and the loopback.

For every fault: connect, approach a 200 N/m spring surface, start a 3 s press hold, inject the
fault 0.3 s in, and measure until the typed error reached the caller: detection, stopping and,
where the arm is still controllable, a 1 cm retract at 5 cm/s (about 0.33 s; reported as
"retracted"). Also: connect and close times. Writes benches/results/ur10_fault_latency.json.

    .venv/bin/python benches/ur10_fault_latency.py --repeat 3
"""

from __future__ import annotations

import argparse
import json
import math
import socket
import statistics
import threading
import time
from pathlib import Path

from aptkt.errors import AptktError
from aptkt.robot import UR10, Placement, SafetyLimits
from aptkt.sim.loopback import Loopback

PLACEMENT = Placement("surface", 0.0, -0.5, 0.0, (-0.04, -0.54, -0.01), (0.04, -0.46, 0.04))
START = (0.0, -0.5, 0.006, math.pi, 0.0, 0.0)


class Skin:
    """The loopback's contact force as a skin reading, with a stale/over-limit switch."""

    def __init__(self, lb: Loopback):
        self.lb, self.scale, self.stale, self.value, self.t = (
            lb,
            1.0,
            False,
            0.0,
            time.monotonic_ns(),
        )

    def __call__(self) -> float:
        if not self.stale:
            self.value, self.t = self.scale * self.lb.normal_force(), time.monotonic_ns()
        return self.value

    def last_update_ns(self) -> int:
        return self.t


def free_host() -> str:
    for last in range(1, 60):
        host = f"127.0.0.{last}"
        try:
            for port in (30004, 30003, 30002, 30001, 29999):
                with socket.socket() as s:
                    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                    s.bind((host, port))
            return host
        except OSError:
            continue
    raise RuntimeError("no free loopback address")


FAULTS = {
    "protective stop": lambda lb, skin: lb.protective_stop(),
    "program stop": lambda lb, skin: lb.stop_program(),
    "dropped connection": lambda lb, skin: lb.drop_connections(refuse_for=None),
    "frozen link": lambda lb, skin: lb.freeze(),
    "stale skin": lambda lb, skin: setattr(skin, "stale", True),
    "skin force limit": lambda lb, skin: setattr(skin, "scale", 100.0),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    results: dict[str, dict[str, float]] = {}
    connects, closes = [], []
    with Loopback(
        free_host(),
        contact={"type": "spring", "surface_z": 0.0, "stiffness": 200.0},
        start_pose=START,
        unlock_delay=0.0,
    ) as lb:
        for name, inject in FAULTS.items():
            total, kinds, retracted = [], set(), set()
            for _ in range(args.repeat):
                lb.reset(pose=START)
                lb.restore()
                t0 = time.monotonic()
                robot = UR10(lb.host, [PLACEMENT], SafetyLimits(approach_speed=0.01))
                connects.append(time.monotonic() - t0)
                skin = Skin(lb)
                robot.move_above(PLACEMENT, 0.004)
                robot.approach_contact(skin, 0.05)
                fired: list[int] = []
                z_fault = lb.state()["pose"][2] - 0.001

                def fire(fired=fired, inject=inject, skin=skin) -> None:
                    fired.append(time.monotonic_ns())
                    inject(lb, skin)

                timer = threading.Timer(0.3, fire)
                timer.start()
                try:
                    robot.press(0.001, 3.0)
                except AptktError as exc:
                    end = time.monotonic_ns()
                    kinds.add(type(exc).__name__)
                    total.append((end - fired[0]) * 1e-6)
                    retracted.add(lb.state()["pose"][2] > z_fault + 0.005)
                timer.join()
                t0 = time.monotonic()
                robot.close()
                closes.append(time.monotonic() - t0)
                lb.freeze(False)
            results[name] = {
                "error": "/".join(sorted(kinds)),
                "error_at_caller_ms": round(statistics.median(total), 1),
                "retracted": sorted(retracted) == [True],
            }
    results["connect_s"] = {"median": round(statistics.median(connects), 3)}
    results["close_s"] = {"median": round(statistics.median(closes), 3)}
    out = Path(__file__).parent / "results" / "ur10_fault_latency.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    for name, r in results.items():
        print(f"{name:20s} {r}")


if __name__ == "__main__":
    main()
