"""Command-line options shared by ``aptkt collect`` and ``aptkt learn``: which robot, which
skin, which actions — and the live session they make (:mod:`aptkt.runtime.sessions`)."""

from __future__ import annotations

import argparse
from typing import Any

from aptkt.actions.executor import ExplorationSettings
from aptkt.commands._checks import MAX_THERMAL_WAIT, at_least, at_most, input_file
from aptkt.errors import ConfigError
from aptkt.names import name_problem

#: Exit code of `aptkt collect` and `aptkt learn` when a robot or skin fault stopped the
#: session mid-trial (1: bad input).
EXIT_FAULT = 3


def add_session_arguments(p: argparse.ArgumentParser, *, robot_required: bool = True) -> None:
    g = p.add_argument_group("robot and skin")
    g.add_argument(
        "--robot",
        choices=("ur10", "sim"),
        required=robot_required,
        help="ur10: the arm through ur_rtde with a hardware skin; sim: the simulated world (fast)",
    )
    g.add_argument(
        "--host",
        metavar="H",
        help="UR controller address (ur10; default: [robot] host of the workspace file)",
    )
    g.add_argument(
        "--workspace",
        metavar="TOML",
        help="workspace file: where each object lies (ur10; required)",
    )
    g.add_argument(
        "--skin", metavar="PORT", help="serial port of the skin adapter, e.g. /dev/ttyUSB0 (ur10)"
    )
    g.add_argument(
        "--tsu",
        action="store_true",
        help="read the skin from a Tactile Section Unit over UDP instead (ur10)",
    )
    g.add_argument(
        "--tsu-address",
        default="192.168.0.10:1336",
        metavar="HOST:PORT",
        help="TSU address (default %(default)s)",
    )
    g.add_argument(
        "--listen",
        default="0.0.0.0:1337",
        metavar="HOST:PORT",
        help="local UDP address for --tsu (default %(default)s)",
    )
    g.add_argument(
        "--patch",
        metavar="TOML",
        help="skin patch file (cells, force calibration); default: the 7-cell patch",
    )
    g.add_argument(
        "--thermal-wait",
        type=float,
        default=ExplorationSettings.thermal_wait,
        metavar="S",
        help="seconds to let the temperature sensors recover after each action (default %(default)s, paper §5.2)",
    )
    g.add_argument(
        "--objects-file",
        action="append",
        default=[],
        metavar="TOML",
        help="extra object library for --robot sim (repeatable)",
    )


def session_inputs(args: argparse.Namespace) -> dict[str, Any]:
    """The files a robot session reads, by option: an output must not name one."""
    return {
        option: getattr(args, option[2:].replace("-", "_"), None)
        for option in ("--workspace", "--patch", "--objects-file", "--actions-file")
    }


def add_action_arguments(p: argparse.ArgumentParser, *, default_help: str) -> None:
    p.add_argument("--actions", metavar="P1,S1,...", help=f"action names ({default_help})")
    p.add_argument(
        "--actions-file",
        metavar="TOML",
        help="your own actions ([[action]] tables); they join the paper's",
    )


def split_names(text: str | None, option: str) -> list[str] | None:
    if text is None:
        return None
    items = [x.strip() for x in text.split(",") if x.strip()]
    if not items:
        raise ConfigError(f"{option}: expected a comma-separated list of names")
    if len(set(items)) != len(items):
        raise ConfigError(f"{option}: a name appears twice in {text!r}")
    for item in items:
        why = name_problem(item)
        if why is not None:
            raise ConfigError(f"{option}: {why}")
    return items


def available_actions(args: argparse.Namespace) -> dict[str, Any]:
    """The paper's actions, plus (overriding by name) those of ``--actions-file``."""
    from aptkt.actions import PAPER_ACTIONS, actions_from_toml

    actions = dict(PAPER_ACTIONS)
    if args.actions_file:
        input_file(args.actions_file, "--actions-file")
        try:
            actions.update(actions_from_toml(args.actions_file))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"--actions-file: {exc}") from None
    return actions


def pick_actions(names: list[str], available: dict[str, Any]) -> list[Any]:
    unknown = [a for a in names if a not in available]
    if unknown:
        raise ConfigError(
            f"--actions: unknown action(s) {', '.join(unknown)}; known: {', '.join(available)} "
            "(define your own with --actions-file)"
        )
    return [available[a] for a in names]


def _host_port(text: str, option: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"{option}: expected HOST:PORT, got {text!r}")
    return host, int(port)


def make_session(args: argparse.Namespace, *, seed: int = 0) -> Any:
    """The (not yet entered) live session the options describe."""
    at_least(args.thermal_wait, 0, "--thermal-wait")
    at_most(args.thermal_wait, MAX_THERMAL_WAIT, "--thermal-wait", "an hour")
    settings = ExplorationSettings(thermal_wait=args.thermal_wait)
    if args.robot == "sim":
        from aptkt.runtime.sessions import SimSession

        ignored = [
            o
            for o, v in (
                ("--host", args.host),
                ("--workspace", args.workspace),
                ("--skin", args.skin),
                ("--tsu", args.tsu),
                ("--patch", args.patch),
            )
            if v
        ]
        if ignored:
            raise ConfigError(
                f"{', '.join(ignored)}: only for --robot ur10 (the simulated world has its own "
                "placements and skin)"
            )
        for path in args.objects_file or ():
            input_file(path, "--objects-file")  # (a device or FIFO would be read for ever)
        return SimSession(seed=seed, settings=settings, object_files=args.objects_file)

    from aptkt.runtime.sessions import RobotSession

    if args.objects_file:
        raise ConfigError("--objects-file: only for --robot sim")
    if not args.workspace:
        raise ConfigError("--robot ur10 needs --workspace FILE (where each object lies)")
    for option, value in (("--workspace", args.workspace), ("--patch", args.patch)):
        if value:
            input_file(value, option)
    if bool(args.skin) == bool(args.tsu):
        raise ConfigError(
            "--robot ur10 needs the skin: --skin PORT (USB adapter) or --tsu (UDP), not both"
        )
    if args.tsu:
        tsu_address = _host_port(args.tsu_address, "--tsu-address")
        listen = _host_port(args.listen, "--listen")

        def make_skin() -> Any:
            from aptkt.skin import TsuSkin

            return TsuSkin(args.patch, tsu_address=tsu_address, listen_address=listen)

        skin_desc = {"source": "TsuSkin", "tsu_address": args.tsu_address, "listen": args.listen}
    else:

        def make_skin() -> Any:
            from aptkt.skin import SerialSkin

            return SerialSkin(args.skin, args.patch)

        skin_desc = {"source": "SerialSkin", "port": args.skin}
    skin_desc["patch"] = args.patch or "default (7 cells)"
    return RobotSession(
        args.workspace, make_skin, host=args.host, settings=settings, skin_description=skin_desc
    )


def object_list(objects: list[str], most: int = 10) -> str:
    """Up to ``most`` object names, then how many more (a library may hold thousands)."""
    shown = ", ".join(objects[:most])
    return shown + (f", ... ({len(objects) - most} more)" if len(objects) > most else "")


def add_noise_option(p: argparse._ActionsContainer) -> None:
    p.add_argument(
        "--noise",
        metavar="NOISE",
        help="the simulated world's noise level: a file from 'aptkt dataset fit-noise', or "
        "'physical' for the simulation's physical defaults alone (default: the level fitted to "
        "a real sensor, docs/simulation.md)",
    )


def noise_level(text: str | None) -> Any:  # -> NoiseLevel
    """``--noise`` as given: None is the world's default."""
    from aptkt.sim.noise import FITTED, PHYSICAL, load_noise_level

    if text is None:
        return FITTED
    if text == "physical":
        return PHYSICAL
    return load_noise_level(input_file(text, "--noise"))
