"""``aptkt skin monitor`` on a virtual serial device and on loopback UDP."""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from skin_helpers import VirtualAdapter, frames
from timing import LatenessProbe, repeat_if_disturbed

from aptkt.cli import main
from aptkt.skin import encode_packet, encode_sensor_packets
from aptkt.skin.config import default_patch

CELLS = [1, 2, 3, 4, 5, 6, 7]


def when_reading(port: str, action: Callable[[], object]) -> threading.Thread:
    """Run ``action`` once SerialSkin reads ``port``: its reader thread starts after the port
    is opened, and opening flushes the input, so bytes written before would be lost (a fixed
    delay lost them on a loaded machine)."""

    def wait() -> None:
        name = f"SerialSkin({port})"
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            if any(t.name == name for t in threading.enumerate()):
                action()
                return
            time.sleep(0.002)

    thread = threading.Thread(target=wait, daemon=True)
    thread.start()
    return thread


def test_monitor_serial_shows_rates_health_and_values(capsys, tmp_path):
    raw = frames(np.random.default_rng(0), CELLS, 300)
    raw["acc"][:] = [0, 0, 256]  # 1 g on z
    # A cell is shown silent after its patch's silence timeout; the shipped 0.1 s is less than
    # a loaded machine may keep the stream or the monitor waiting. Measured: four times the
    # lateness seen now, and a run kept waiting longer than half of it is repeated.
    probe = LatenessProbe().start()
    since = time.monotonic()
    time.sleep(0.5)
    timeout = max(0.1, math.ceil(4 * probe.worst(since) * 100) / 100)
    src = Path(default_patch().source).read_text()
    patch = tmp_path / "patch.toml"
    patch.write_text(src.replace("silence_timeout_s = 0.1", f"silence_timeout_s = {timeout}"))
    started = [0.0]

    def attempt() -> tuple[int, str]:
        started[0] = time.monotonic()
        adapter = VirtualAdapter()

        def play() -> None:
            adapter.write(b"\x01\x02\x03" + encode_packet("ping"))
            adapter.stream(raw, rate_hz=250, per_tick=7)

        try:
            player = when_reading(adapter.port, play)
            argv = ["skin", "monitor", adapter.port, "--duration", "0.9", "--interval", "0.45"]
            code = main([*argv, "--plain", "--patch", str(patch)])
            player.join(timeout=5.0)
        finally:
            adapter.close()
        return code, capsys.readouterr().out

    def check(result: object) -> None:
        code, out = result  # type: ignore[misc]
        assert code == 0
        last = out.strip().split("\n\n")[-1]
        rows = [
            line.split() for line in last.splitlines() if line.split() and line.split()[0].isdigit()
        ]
        assert [int(r[0]) for r in rows] == CELLS
        rates = [float(r[1]) for r in rows]
        assert all(150 < r < 350 for r in rates), rates  # 250 Hz per cell, loosely (shared machine)
        assert all(r[-1] == "ok" for r in rows), last
        assert all(r[4:7] == ["0.000", "0.000", "1.000"] for r in rows), last  # acc x y z in g
        assert "3 bytes skipped" in last and "ping 1" in last and "buffer overflows 0" in last

    try:
        repeat_if_disturbed(
            attempt, check, stall=lambda: probe.worst(started[0]), budget=timeout / 2
        )
    finally:
        probe.stop()


def test_monitor_reports_a_missing_port(capsys):
    code = main(["skin", "monitor", "/dev/aptkt-no-such-port", "--duration", "0.1"])
    assert code == 1
    assert "port not found" in capsys.readouterr().err


def test_monitor_needs_a_port_or_tsu(capsys):
    assert main(["skin", "monitor", "--duration", "0.1"]) == 1
    assert "give a serial PORT, or --tsu" in capsys.readouterr().err


def test_monitor_unplugged_mid_stream(adapter, capsys):
    raw = frames(np.random.default_rng(1), CELLS, 20)

    def play_then_unplug() -> None:
        adapter.write(encode_sensor_packets(raw))
        threading.Timer(0.2, adapter.unplug).start()

    player = when_reading(adapter.port, play_then_unplug)
    code = main(
        ["skin", "monitor", adapter.port, "--duration", "3", "--interval", "0.1", "--plain"]
    )
    player.join(timeout=5.0)
    captured = capsys.readouterr()
    assert code == 1
    assert "link lost mid-stream" in captured.err and "LINK ERROR" in captured.out


def test_monitor_tsu(capsys):
    fake = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    fake.bind(("127.0.0.1", 0))
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    listen = probe.getsockname()
    probe.close()  # a free port for the monitor to listen on
    data = encode_sensor_packets(frames(np.random.default_rng(2), CELLS, 10))

    def tsu() -> None:
        fake.settimeout(2.0)
        fake.recvfrom(64)  # first alive datagram: the monitor is listening
        for i in range(0, len(data), 20):
            fake.sendto(bytes([1]) + data[i : i + 19], listen)

    t = threading.Thread(target=tsu)
    t.start()
    try:
        code = main(
            [
                "skin",
                "monitor",
                "--tsu",
                "--tsu-address",
                f"127.0.0.1:{fake.getsockname()[1]}",
                "--listen",
                f"127.0.0.1:{listen[1]}",
                "--duration",
                "0.4",
                "--interval",
                "0.2",
                "--plain",
            ]
        )
    finally:
        t.join()
        fake.close()
    out = capsys.readouterr().out
    assert code == 0
    assert "70 sensor packets" in out and "udp: 70 datagrams" in out
