"""``aptkt skin monitor`` on a virtual serial device and on loopback UDP."""

from __future__ import annotations

import socket
import threading

import numpy as np
from skin_helpers import frames

from aptkt.cli import main
from aptkt.skin import encode_packet, encode_sensor_packets

CELLS = [1, 2, 3, 4, 5, 6, 7]


def test_monitor_serial_shows_rates_health_and_values(adapter, capsys):
    raw = frames(np.random.default_rng(0), CELLS, 300)
    raw["acc"][:] = [0, 0, 256]  # 1 g on z

    def play() -> None:  # once the monitor has opened the port (opening flushes the input)
        adapter.write(b"\x01\x02\x03" + encode_packet("ping"))
        adapter.stream(raw, rate_hz=250, per_tick=7)

    timer = threading.Timer(0.15, play)
    timer.start()
    code = main(
        ["skin", "monitor", adapter.port, "--duration", "0.9", "--interval", "0.45", "--plain"]
    )
    timer.join()
    out = capsys.readouterr().out
    assert code == 0
    last = out.strip().split("\n\n")[-1]
    rows = [
        line.split() for line in last.splitlines() if line.split() and line.split()[0].isdigit()
    ]
    assert [int(r[0]) for r in rows] == CELLS
    rates = [float(r[1]) for r in rows]
    assert all(150 < r < 350 for r in rates), rates  # 250 Hz per cell, loosely (shared machine)
    assert all(r[-1] == "ok" for r in rows)
    assert all(r[4:7] == ["0.000", "0.000", "1.000"] for r in rows), last  # acc x y z in g
    assert "3 bytes skipped" in last and "ping 1" in last and "buffer overflows 0" in last


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

    timer = threading.Timer(0.15, play_then_unplug)
    timer.start()
    code = main(
        ["skin", "monitor", adapter.port, "--duration", "3", "--interval", "0.1", "--plain"]
    )
    timer.join()
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
