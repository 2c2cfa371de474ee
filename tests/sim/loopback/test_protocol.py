"""The loopback's wire protocols, spoken by a raw-socket client written from UR's RTDE guide.

The server runs in this process (a plain socket client, unlike ur_rtde, never holds the
GIL while it waits), on a loopback address of its own.
"""

from __future__ import annotations

import math
import socket
import struct
import time
from collections.abc import Iterator

import pytest
from loopback_helpers import free_loopback_host

from aptkt.sim.loopback import (
    ControllerConfig,
    Loopback,
    LoopbackError,
    LoopbackServer,
    SimulatedController,
)
from aptkt.sim.loopback.servers import _split_program


class RawRtde:
    """A minimal RTDE protocol-2 client."""

    def __init__(self, host: str):
        self.sock = socket.create_connection((host, 30004), timeout=2.0)

    def send(self, kind: str, payload: bytes = b"") -> None:
        self.sock.sendall(struct.pack(">HB", 3 + len(payload), ord(kind)) + payload)

    def recv(self) -> tuple[str, bytes]:
        head = self._exact(3)
        size, kind = struct.unpack(">HB", head)
        return chr(kind), self._exact(size - 3)

    def recv_kind(self, kind: str) -> bytes:
        while True:  # data packages may already be on their way
            k, body = self.recv()
            if k == kind:
                return body

    def _exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("closed")
            buf += chunk
        return buf

    def setup_outputs(self, names: list[str], frequency: float = 125.0) -> tuple[int, list[str]]:
        self.send("O", struct.pack(">d", frequency) + ",".join(names).encode())
        body = self.recv_kind("O")
        return body[0], body[1:].decode().split(",")

    def setup_inputs(self, names: list[str]) -> tuple[int, list[str]]:
        self.send("I", ",".join(names).encode())
        body = self.recv_kind("I")
        return body[0], body[1:].decode().split(",")


@pytest.fixture(scope="module")
def server() -> Iterator[LoopbackServer]:
    ctl = SimulatedController(ControllerConfig(start_pose=(0.1, -0.4, 0.3, math.pi, 0.0, 0.0)))
    with LoopbackServer(ctl, host=free_loopback_host()) as srv:
        yield srv


@pytest.fixture
def rtde(server) -> Iterator[RawRtde]:
    client = RawRtde(server.host)
    yield client
    client.sock.close()


def test_protocol_version_and_controller_version(rtde):
    rtde.send("V", struct.pack(">H", 2))
    assert rtde.recv() == ("V", b"\x01")
    rtde.send("V", struct.pack(">H", 7))
    assert rtde.recv() == ("V", b"\x00")  # only protocol 2 is spoken
    rtde.send("v")
    kind, body = rtde.recv()
    assert kind == "v" and struct.unpack(">IIII", body) == (3, 15, 8, 106339)


def test_output_recipe_streams_at_the_requested_rate(rtde, server):
    rtde.send("V", struct.pack(">H", 2)) or rtde.recv()
    recipe, types = rtde.setup_outputs(
        ["timestamp", "actual_TCP_pose", "runtime_state", "output_int_register_0"], frequency=62.5
    )
    assert recipe == 1 and types == ["DOUBLE", "VECTOR6D", "UINT32", "INT32"]
    rtde.send("S")
    assert rtde.recv_kind("S") == b"\x01"
    t0 = time.monotonic()
    stamps = []
    while time.monotonic() - t0 < 0.4:
        kind, body = rtde.recv()
        assert kind == "U" and body[0] == 1
        ts, *pose = struct.unpack(">d6d", body[1:57])
        stamps.append(ts)
        assert pose == pytest.approx([0.1, -0.4, 0.3, math.pi, 0.0, 0.0])
        assert struct.unpack(">Ii", body[57:65]) == (1, 0)  # STOPPED, no program yet
    steps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert steps and all(s == pytest.approx(0.016) for s in steps)  # every second 8 ms cycle
    assert len(stamps) == pytest.approx(0.4 * 62.5, abs=5)
    rtde.send("P")
    assert rtde.recv_kind("P") == b"\x01"


def test_unknown_outputs_and_bad_frequencies_fail_the_recipe(rtde):
    assert rtde.setup_outputs(["timestamp", "warp_drive"]) == (0, ["DOUBLE", "NOT_FOUND"])
    assert rtde.setup_outputs(["timestamp"], frequency=1000.0)[0] == 0  # above 125 Hz on CB3
    assert rtde.setup_outputs(["output_bit_register_3"])[1] == [
        "NOT_FOUND"
    ]  # 0..63 are not general purpose
    assert rtde.setup_outputs(["output_bit_register_64", "input_double_register_47"])[1] == [
        "BOOL",
        "DOUBLE",
    ]


def test_inputs_belong_to_one_connection_at_a_time(rtde, server):
    recipe, types = rtde.setup_inputs(["input_int_register_0", "input_double_register_3"])
    assert recipe == 1 and types == ["INT32", "DOUBLE"]
    other = RawRtde(server.host)
    try:
        assert other.setup_inputs(["input_int_register_0"]) == (0, ["IN_USE"])
        assert other.setup_inputs(["output_int_register_0"]) == (0, ["NOT_FOUND"])  # not writable
    finally:
        other.sock.close()
    rtde.send("U", struct.pack(">Bid", 1, 42, 2.5))
    deadline = time.monotonic() + 1.0
    while server.controller.input_int[0] != 42 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert server.controller.input_int[0] == 42 and server.controller.input_double[3] == 2.5
    rtde.sock.close()
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline:  # released when the owner disconnects
        late = RawRtde(server.host)
        ok = late.setup_inputs(["input_int_register_0"])[0] == 1
        late.sock.close()
        if ok:
            break
        time.sleep(0.02)
    assert ok


def test_dashboard_greets_and_answers_line_by_line(server):
    with socket.create_connection((server.host, 29999), timeout=2.0) as s:
        f = s.makefile("rwb")
        assert f.readline() == b"Connected: Universal Robots Dashboard Server\n"
        f.write(b"PolyscopeVersion\nget robot model\nrobotmode\n")
        f.flush()
        assert f.readline() == b"URSoftware 3.15.8.106339 (loopback)\n"
        assert f.readline() == b"UR10\n"
        assert f.readline() == b"Robotmode: RUNNING\n"
        f.write(b"quit\n")
        f.flush()
        assert f.readline() == b"Disconnected\n"
        assert f.readline() == b""


def test_script_ports_run_ur_rtde_programs_only(server):
    ctl = server.controller
    with socket.create_connection((server.host, 30002), timeout=2.0) as s:
        s.sendall(b'def other():\n  textmsg("hi")\nend\n')
        deadline = time.monotonic() + 1.0
        while "other" not in ctl.stop_reason and time.monotonic() < deadline:
            time.sleep(0.01)
    assert "cannot run program 'other'" in ctl.stop_reason and not ctl.program_running
    with socket.create_connection((server.host, 30003), timeout=2.0) as s:
        script = (
            "def rtde_control():\n# HEADER_BEGIN\n    global reg_offset_float = # float register offset\n"
            "24    global reg_offset_int = # int register offset\n24    x = 1\nend\n"
        )
        s.sendall(script[:40].encode())
        time.sleep(0.05)  # a program split across TCP segments is assembled first
        assert not ctl.program_running
        s.sendall(script[40:].encode())
        deadline = time.monotonic() + 1.0
        while not ctl.program_running and time.monotonic() < deadline:
            time.sleep(0.01)
    assert ctl.program_running and ctl.program.int_offset == 24
    assert ctl.output_int[24] == 1
    ctl.stop_program("test over")


def test_program_splitting():
    assert _split_program("def a():\n  b()\n") == (None, "def a():\n  b()\n")
    assert _split_program("\ndef a():\n  end\nend\nrest") == ("def a():\n  end\nend\n", "rest")
    assert _split_program("stopl(1)\npopup(1)\n") == ("stopl(1)\n", "popup(1)\n")


def test_drop_refuse_and_restore(server):
    client = RawRtde(server.host)
    deadline = time.monotonic() + 1.0
    while not server.connections.get("rtde") and time.monotonic() < deadline:
        time.sleep(0.01)  # accepted by the server's accept loop
    assert server.drop_connections(refuse_for=None) >= 1
    with pytest.raises(ConnectionError):
        client.recv()
    with pytest.raises(OSError):
        socket.create_connection((server.host, 30004), timeout=0.5)
    server.restore()
    RawRtde(server.host).sock.close()


def test_a_busy_port_is_a_clear_start_error():
    host = free_loopback_host()
    with socket.socket() as blocker:
        # As the loopback does: an earlier test's connection to this port may linger in
        # TIME_WAIT, which only a plain bind refuses; a listening socket still blocks the port.
        blocker.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        blocker.bind((host, 29999))
        blocker.listen()
        with pytest.raises(LoopbackError, match=f"loopback on {host} failed to start: OSError"):
            Loopback(host).start()


def test_a_program_starts_after_the_inputs_sent_before_it(rtde, server, monkeypatch):
    """ur_rtde stops a running program with command 255 in input_int_register_0, clears the
    register and uploads its script. A reader thread kept waiting (a loaded machine) handled
    the clear only after the new program had started, which read the stale 255 and stopped:
    now a program that arrives on a script port starts after the inputs sent before it."""
    ctl = server.controller
    rtde.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # (as ur_rtde's client)
    recipe, _ = rtde.setup_inputs(["input_int_register_0"])
    rtde.send("S")
    rtde.recv_kind("S")
    rtde.send("U", struct.pack(">Bi", recipe, 255))
    deadline = time.monotonic() + 1.0
    while ctl.input_int[0] != 255 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert ctl.input_int[0] == 255
    applied = ctl.apply_inputs

    def kept_waiting(values):  # the reader thread runs 0.3 s late
        time.sleep(0.3)
        applied(values)

    monkeypatch.setattr(ctl, "apply_inputs", kept_waiting)
    rtde.send("U", struct.pack(">Bi", recipe, 0))  # the clear, then at once the script
    script = "def rtde_control():\n# HEADER_BEGIN\n  x = 1\nend\n"  # (offset 0)
    with socket.create_connection((server.host, 30003), timeout=2.0) as s:
        s.sendall(script.encode())
        deadline = time.monotonic() + 2.0
        while not ctl.program_running and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.1)  # (a few control cycles: a stale 255 would have stopped it)
    log = [message for _, message in list(ctl.text_log)[-5:]]
    assert ctl.program_running and ctl.input_int[0] == 0, log
    assert "Received stop script!" not in log
    ctl.stop_program("test over")
