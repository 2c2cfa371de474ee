"""``aptkt skin monitor``: a live view of the skin link — packet rate per cell, link health
and current sensor values."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any, TextIO

import numpy as np

from aptkt.errors import ConfigError, SkinError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("skin", help="skin tools (live monitor)")
    skin_sub = p.add_subparsers(dest="skin_command", required=True, metavar="SKIN_COMMAND")
    m = skin_sub.add_parser(
        "monitor",
        help="live view of packet rate per cell, link health and sensor values",
        description="Open a skin source and show packet rate per cell, link health (bytes skipped, "
        "rejected packets, buffer overflows) and the current sensor values, refreshed live.",
    )
    m.add_argument(
        "port", nargs="?", metavar="PORT", help="serial port of the skin adapter, e.g. /dev/ttyUSB0"
    )
    m.add_argument(
        "--tsu", action="store_true", help="read from a Tactile Section Unit over UDP instead"
    )
    m.add_argument(
        "--tsu-address",
        default="192.168.0.10:1336",
        metavar="HOST:PORT",
        help="TSU address (default %(default)s)",
    )
    m.add_argument(
        "--listen",
        default="0.0.0.0:1337",
        metavar="HOST:PORT",
        help="local UDP address (default %(default)s)",
    )
    m.add_argument(
        "--patch",
        metavar="TOML",
        help="patch TOML (cells and force calibration); default: the 7-cell patch",
    )
    m.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="stop after S seconds (default: until Ctrl-C)",
    )
    m.add_argument(
        "--interval",
        type=float,
        default=0.5,
        metavar="S",
        help="refresh period (default %(default)s s)",
    )
    m.add_argument(
        "--plain",
        action="store_true",
        help="append snapshots instead of redrawing (default when not a terminal)",
    )
    m.set_defaults(func=run)


def _host_port(text: str, option: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"{option}: expected HOST:PORT, got {text!r}")
    return host, int(port)


def _make_source(args: argparse.Namespace) -> Any:
    from aptkt.skin import SerialSkin, TsuSkin

    if args.tsu:
        return TsuSkin(
            args.patch,
            tsu_address=_host_port(args.tsu_address, "--tsu-address"),
            listen_address=_host_port(args.listen, "--listen"),
        )
    if not args.port:
        raise ConfigError("give a serial PORT, or --tsu for UDP")
    return SerialSkin(args.port, args.patch)


def _fmt(x: float, spec: str) -> str:
    """``format(x, spec)``, or a dash of the same width for a value not received yet."""
    if np.isfinite(x):
        return format(x, spec)
    width = spec.split(".")[0]
    return "-".rjust(int(width) if width.isdigit() else 1)


def render(
    stats: dict[str, Any], latest: dict[str, np.ndarray], elapsed_s: float, title: str
) -> str:
    """One screen of the monitor, as text."""
    lines = [f"{title}   {elapsed_s:6.1f} s"]
    silent = set(stats["silent_cells"])
    lines.append(
        f"{'cell':>5} {'rate/Hz':>8} {'packets':>9}  {'prox':>6}  {'acc x/y/z (g)':>22}  "
        f"{'T die/LM71 (°C)':>16}  {'force 0/1/2 (N)':>22}  state"
    )
    for i, cid in enumerate(latest["cell_id"].tolist()):
        acc = " ".join(_fmt(v, "6.3f") for v in latest["acc"][i])
        temp = " ".join(_fmt(v, "7.2f") for v in latest["temp"][i])
        force = " ".join(_fmt(v, "6.3f") for v in latest["force"][i])
        lines.append(
            f"{cid:>5} {_fmt(stats['rate_hz'].get(cid, float('nan')), '8.1f')} "
            f"{stats['packets_per_cell'].get(cid, 0):>9}  {_fmt(latest['proximity'][i], '6.4f')}  "
            f"{acc:>22}  {temp:>16}  {force:>22}  {'SILENT' if cid in silent else 'ok'}"
        )
    rej = stats["rejected"]
    others = {k: v for k, v in stats["other_packets"].items() if v}
    lines.append(
        f"link: {stats['bytes']} bytes, {stats['packets']} sensor packets, "
        f"{stats['bytes_skipped']} bytes skipped, rejected {stats['rejected_total']} "
        f"(unknown header {rej['unknown_header']}, payload high bit {rej['payload_high_bit']}, "
        f"bad end marker {rej['bad_end_marker']}), buffer overflows {stats['overflows']}"
    )
    if others:
        lines.append("other packets: " + ", ".join(f"{k} {v}" for k, v in sorted(others.items())))
    if stats["unknown_cells"]:
        lines.append(
            "cells not in the patch: "
            + ", ".join(f"{k} ({v})" for k, v in sorted(stats["unknown_cells"].items()))
        )
    if "datagrams" in stats:
        lines.append(
            f"udp: {stats['datagrams']} datagrams, {stats['bad_datagrams']} bad, "
            f"{stats['foreign_datagrams']} foreign, {stats['alive_sent']} alive sent"
        )
    if stats["link_error"]:
        lines.append(f"LINK ERROR: {stats['link_error']}")
    return "\n".join(lines)


def monitor(
    source: Any, duration: float | None, interval: float, out: TextIO, redraw: bool, title: str
) -> int:
    """Run the live view on an open source until ``duration`` (or Ctrl-C)."""
    start = time.monotonic()
    while True:
        time.sleep(
            interval
            if duration is None
            else max(0.0, min(interval, start + duration - time.monotonic()))
        )
        try:
            source.read()  # keep the buffer drained: overflows then mean the link outruns us
        except SkinError:
            pass  # reported below through stats["link_error"], then raised
        screen = render(source.stats, source.latest(), time.monotonic() - start, title)
        out.write(("\x1b[H\x1b[2J" if redraw else "") + screen + "\n" + ("" if redraw else "\n"))
        out.flush()
        if source.link_error is not None:
            raise source.link_error
        if duration is not None and time.monotonic() - start >= duration:
            return 0


def run(args: argparse.Namespace) -> int:
    source = _make_source(args)
    title = f"aptkt skin monitor — {'TSU ' + args.tsu_address if args.tsu else args.port} — patch {source.patch.name}"
    redraw = sys.stdout.isatty() and not args.plain
    with source:
        try:
            return monitor(source, args.duration, args.interval, sys.stdout, redraw, title)
        except KeyboardInterrupt:
            return 0
