"""``python -m aptkt.sim.loopback``: run a loopback UR controller in this terminal.

Then connect anything that speaks to a UR controller (ur_rtde, ``aptkt.robot.UR10``) to the
host it prints. With ``--skin-pty`` a simulated skin patch on the TCP streams the skin's wire
protocol through a pty whose path it prints (``aptkt skin monitor PATH`` shows it). With
``--workspace FILE`` the objects of a workspace file lie where the file says. ``--stdio`` is the mode :class:`~aptkt.sim.loopback.Loopback` uses for its
child process (JSON commands on stdin, answers on stdout).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from aptkt.errors import ConfigError
from aptkt.sim.loopback.config import CB3_VERSION, E_SERIES_VERSION, ControllerConfig
from aptkt.sim.loopback.contact import scene_from_workspace
from aptkt.sim.loopback.controller import SimulatedController
from aptkt.sim.loopback.process import serve_stdio
from aptkt.sim.loopback.servers import LoopbackServer
from aptkt.sim.loopback.tcp_skin import SkinConfig


def build_parser() -> argparse.ArgumentParser:
    """The command line, apart from running it: the docs' commands are checked against it."""
    parser = argparse.ArgumentParser(
        prog="python -m aptkt.sim.loopback", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="loopback address to serve on (default 127.0.0.1)"
    )
    parser.add_argument(
        "--series",
        choices=("cb3", "e-series"),
        default="cb3",
        help="cb3: PolyScope 3.15, RTDE at 125 Hz; e-series: PolyScope 5.11, 500 Hz",
    )
    parser.add_argument(
        "--surface-z", type=float, default=0.0, help="height of the simulated surface (m)"
    )
    parser.add_argument("--stiffness", type=float, default=200.0, help="surface stiffness (N/m)")
    parser.add_argument("--friction", type=float, default=0.3, help="Coulomb friction coefficient")
    parser.add_argument(
        "--object",
        default=None,
        metavar="NAME",
        help="press a simulated-world object (aptkt.sim library) lying at --object-xy "
        "instead of the spring surface",
    )
    parser.add_argument("--object-xy", type=float, nargs=2, default=(0.0, -0.5), metavar=("X", "Y"))
    parser.add_argument(
        "--workspace",
        default=None,
        metavar="FILE",
        help="put an object at every placement of this workspace file: objects of the "
        "simulated world's library by name, spring surfaces for other names",
    )
    parser.add_argument(
        "--start-pose",
        type=float,
        nargs=6,
        metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
        default=None,
        help="initial TCP pose",
    )
    parser.add_argument(
        "--skin-pty",
        action="store_true",
        help="simulate the skin patch on the TCP and stream it through a pty (path printed)",
    )
    parser.add_argument(
        "--skin-rate",
        type=float,
        default=SkinConfig.rate_hz,
        metavar="HZ",
        help="packets per cell and second of the simulated skin (default %(default)s)",
    )
    parser.add_argument(
        "--patch",
        default=None,
        metavar="FILE",
        help="patch file the skin's reader uses (cell ids, force calibration); default: "
        "the 7-cell patch",
    )
    parser.add_argument("--stdio", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--config-json", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--ports-json", default=None, help=argparse.SUPPRESS)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)

    ports: dict[str, Any] = {"rtde": 30004, "dashboard": 29999, "script": [30001, 30002, 30003]}
    if args.ports_json:
        ports.update(json.loads(args.ports_json))
    if args.config_json:
        config = ControllerConfig(**json.loads(args.config_json))
    else:
        extra: dict[str, Any] = {}
        if args.start_pose is not None:
            extra["start_pose"] = tuple(args.start_pose)
        contact: dict[str, Any] = {
            "type": "spring",
            "surface_z": args.surface_z,
            "stiffness": args.stiffness,
            "friction": args.friction,
        }
        if args.object and args.workspace:
            parser.error("--object and --workspace exclude each other")
        if args.object:
            contact = {
                "type": "sim_object",
                "object": args.object,
                "x": args.object_xy[0],
                "y": args.object_xy[1],
            }
        if args.workspace:
            try:
                contact = scene_from_workspace(
                    args.workspace, stiffness=args.stiffness, friction=args.friction
                )
            except (ConfigError, ValueError) as exc:
                print(f"--workspace: {exc}", file=sys.stderr)
                return 1
        if args.skin_pty:
            try:
                extra["skin"] = SkinConfig(rate_hz=args.skin_rate, patch=args.patch).to_dict()
            except ValueError as exc:
                print(f"--skin-rate: {exc}", file=sys.stderr)
                return 1
        config = ControllerConfig(
            version=CB3_VERSION if args.series == "cb3" else E_SERIES_VERSION,
            contact=contact,
            **extra,
        )

    if args.stdio:
        serve_stdio(config, args.host, ports, sys.stdin, sys.stdout)
        return 0

    try:
        controller = SimulatedController(config)
    except (OSError, ValueError) as exc:  # a bad contact spec or patch file, no pty
        print(f"cannot start the loopback: {exc}", file=sys.stderr)
        return 1
    try:
        server = LoopbackServer(
            controller,
            host=args.host,
            rtde_port=ports["rtde"],
            dashboard_port=ports["dashboard"],
            script_ports=ports["script"],
        ).start()
    except OSError as exc:
        print(f"cannot serve on {args.host}: {exc}", file=sys.stderr)
        return 1
    print(
        f"loopback UR controller (PolyScope {config.polyscope_version}, {config.frequency:.0f} Hz) "
        f"on {args.host}: RTDE {ports['rtde']}, dashboard {ports['dashboard']}, script {ports['script']}. "
        "Ctrl-C stops."
    )
    if controller.skin is not None:
        print(
            f"simulated skin ({controller.skin.patch.name}, {controller.skin.config.rate_hz:g} Hz per cell) "
            f"on {controller.skin.port}",
            flush=True,
        )
    try:
        while True:
            time.sleep(1.0)
            s = controller.snapshot()
            x, y, z = s["pose"][:3]
            print(
                f"t={s['time']:8.2f}s  tcp=({x:+.4f}, {y:+.4f}, {z:+.4f}) m  "
                f"Fn={s['normal_force']:.3f} N  program={'running' if s['program_running'] else 'stopped'}"
                f"{'  PROTECTIVE STOP' if s['protective_stopped'] else ''}",
                flush=True,
            )
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        if controller.skin is not None:
            controller.skin.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
