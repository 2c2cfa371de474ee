"""The network side of the loopback controller: RTDE (30004), dashboard (29999) and the
script ports (30001-30003), plus the control-cycle clock and connection faults.

ur_rtde's RTDE and script ports are fixed in the client (only the dashboard port is a
parameter), so a loopback binds the real port numbers. Any address of the 127.0.0.0/8
loopback network works, which lets two loopbacks run side by side on 127.0.0.1 and 127.0.0.2.
"""

from __future__ import annotations

import itertools
import select
import socket
import struct
import threading
import time
from collections.abc import Sequence

from aptkt.errors import InvalidInputError
from aptkt.sim.loopback import rtde
from aptkt.sim.loopback.controller import SimulatedController

__all__ = ["LoopbackServer", "DEFAULT_PORTS"]

DEFAULT_PORTS = {"rtde": 30004, "dashboard": 29999, "script": (30001, 30002, 30003)}

_ids = itertools.count(1)


#: How long an RTDE reader waits for data before looking at its connection again (s).
_IDLE_WAIT = 0.5


class _Client:
    """One accepted connection with its own reader thread."""

    def __init__(self, server: LoopbackServer, sock: socket.socket, kind: str, port: int):
        self.server = server
        self.sock = sock
        self.kind = kind
        self.port = port
        self.id = next(_ids)
        self.send_lock = threading.Lock()
        self.closed = False
        self.thread = threading.Thread(
            target=self._run, name=f"loopback-{kind}-{self.id}", daemon=True
        )

    def send(self, data: bytes) -> None:
        if self.closed:
            return
        try:
            with self.send_lock:
                self.sock.sendall(data)
        except OSError:
            self.close()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.sock.close()
        self.server._forget(self)

    def _run(self) -> None:
        try:
            self.serve()
        except (OSError, ConnectionError, struct.error, ValueError):
            pass
        finally:
            self.close()

    def serve(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError


class _RtdeClient(_Client):
    def __init__(self, *args: object):
        super().__init__(*args)  # type: ignore[arg-type]
        self.protocol_version = 1
        self.outputs: list[rtde.Recipe] = []
        self.inputs: dict[int, rtde.Recipe] = {}
        self.started = False
        # Bytes are taken off the socket and their packages handled only under this lock, by
        # the reader thread or by a program's start (:meth:`take_input`): whatever has left
        # the kernel's buffer is then handled before the lock is let go.
        self._input_lock = threading.Lock()
        self._pending = b""

    def close(self) -> None:
        self.started = False
        if not self.closed:
            self.server.controller.release_inputs(self.id)
        super().close()

    def serve(self) -> None:
        while not self.closed:
            select.select([self.sock], [], [], _IDLE_WAIT)  # (data stays in the kernel's buffer)
            self.take_input()

    def take_input(self) -> None:
        """Take every byte that has arrived and handle each complete package."""
        with self._input_lock:
            while True:
                try:
                    chunk = self.sock.recv(65536, socket.MSG_DONTWAIT)
                except BlockingIOError:
                    break
                if not chunk:
                    raise ConnectionError("peer closed")
                self._pending += chunk
            while len(self._pending) >= rtde.HEADER.size:
                size, kind = rtde.HEADER.unpack(self._pending[: rtde.HEADER.size])
                if size < rtde.HEADER.size:
                    raise InvalidInputError("bad RTDE package size")
                if len(self._pending) < size:
                    break
                payload, self._pending = (
                    self._pending[rtde.HEADER.size : size],
                    self._pending[size:],
                )
                if not self.server.frozen:  # (a pulled cable: nothing arrives)
                    self._handle(kind, payload)

    def _handle(self, kind: int, payload: bytes) -> None:
        ctl = self.server.controller
        if kind == rtde.REQUEST_PROTOCOL_VERSION:
            (version,) = struct.unpack(">H", payload[:2])
            accepted = version == 2
            if accepted:
                self.protocol_version = 2
            self.send(rtde.pack(kind, struct.pack(">B", 1 if accepted else 0)))
        elif kind == rtde.GET_URCONTROL_VERSION:
            self.send(rtde.pack(kind, struct.pack(">IIII", *ctl.config.version)))
        elif kind == rtde.SETUP_OUTPUTS:
            (frequency,) = struct.unpack(">d", payload[:8])
            names = [n for n in payload[8:].decode("ascii").split(",") if n]
            types = [rtde.output_type(n) or "NOT_FOUND" for n in names]
            ok = names and "NOT_FOUND" not in types and 0 < frequency <= ctl.config.frequency
            recipe_id = len(self.outputs) + 1 if ok else 0
            if ok:
                recipe = rtde.Recipe(recipe_id, names, types, frequency)
                recipe.divisor = max(1, round(ctl.config.frequency / frequency))  # type: ignore[attr-defined]
                self.outputs.append(recipe)
            self.send(
                rtde.pack(kind, struct.pack(">B", recipe_id) + ",".join(types).encode("ascii"))
            )
        elif kind == rtde.SETUP_INPUTS:
            names = [n for n in payload.decode("ascii").split(",") if n]
            types = ctl.claim_inputs(self.id, names)
            ok = names and all(t not in ("NOT_FOUND", "IN_USE") for t in types)
            recipe_id = len(self.inputs) + 1 if ok else 0
            if ok:
                self.inputs[recipe_id] = rtde.Recipe(recipe_id, names, types)
            self.send(
                rtde.pack(kind, struct.pack(">B", recipe_id) + ",".join(types).encode("ascii"))
            )
        elif kind == rtde.START:
            self.started = bool(self.outputs) or bool(self.inputs)
            self.send(rtde.pack(kind, struct.pack(">B", 1 if self.started else 0)))
        elif kind == rtde.PAUSE:
            self.started = False
            self.send(rtde.pack(kind, struct.pack(">B", 1)))
        elif kind == rtde.DATA_PACKAGE:
            in_recipe = self.inputs.get(payload[0]) if payload else None
            if in_recipe is not None and len(payload) >= in_recipe.struct.size:
                ctl.apply_inputs(in_recipe.decode(payload))
            else:
                ctl.log(f"RTDE: data package for unknown input recipe {payload[:1]!r}")
        elif kind == rtde.TEXT_MESSAGE:
            ctl.log(
                f"RTDE text from client: {payload[1 : 1 + payload[0]].decode('latin-1', 'replace')}"
            )
        else:
            ctl.log(f"RTDE: unknown package type {kind}")


class _DashboardClient(_Client):
    def serve(self) -> None:
        self.send(b"Connected: Universal Robots Dashboard Server\n")
        buf = b""
        while not self.closed:
            chunk = self.sock.recv(4096)
            if not chunk:
                return
            if self.server.frozen:
                continue
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                reply = self.server.controller.dashboard(line.decode("utf-8", "replace"))
                if reply is None:
                    self.send(b"Disconnected\n")
                    return
                self.send(reply.encode("utf-8") + b"\n")


class _ScriptClient(_Client):
    """Collects URScript text; each complete top-level program goes to the controller."""

    def serve(self) -> None:
        text = ""
        while not self.closed:
            chunk = self.sock.recv(65536)
            if not chunk:
                return
            if self.server.frozen:
                continue
            text += chunk.decode("utf-8", "replace")
            while True:
                program, text = _split_program(text)
                if program is None:
                    break
                self.server.catch_up_inputs()
                self.server.controller.load_script(program, self.port)


def _split_program(text: str) -> tuple[str | None, str]:
    """The first complete program in ``text`` and the rest, or ``(None, text)``.

    A program is ``def``/``sec`` at column 0 up to a column-0 ``end`` line; anything else is
    a one-line script (the controller runs a single line as a program too).
    """
    stripped = text.lstrip("\r\n ")
    if not stripped:
        return None, ""
    lines = stripped.split("\n")
    head = lines[0]
    if head.startswith(("def ", "sec ")):
        for i, line in enumerate(lines[1:], start=1):
            if line.rstrip() == "end" and i < len(lines) - 1:
                return "\n".join(lines[: i + 1]) + "\n", "\n".join(lines[i + 1 :])
        return None, text
    if len(lines) > 1:
        return head + "\n", "\n".join(lines[1:])
    return None, text


class LoopbackServer:
    """Serves a :class:`SimulatedController` on ``host`` and runs its control-cycle clock.

    Use as a context manager or call :meth:`start` / :meth:`close`. The clock runs in real
    time: ur_rtde's timeouts and the backend's durations are wall-clock.
    """

    def __init__(
        self,
        controller: SimulatedController,
        host: str = "127.0.0.1",
        rtde_port: int = 30004,
        dashboard_port: int = 29999,
        script_ports: Sequence[int] = (30001, 30002, 30003),
    ):
        self.controller = controller
        self.host = host
        self.ports: dict[int, str] = {rtde_port: "rtde", dashboard_port: "dashboard"}
        for p in script_ports:
            self.ports[p] = "script"
        self._listeners: dict[int, socket.socket] = {}
        self._clients: set[_Client] = set()
        self._lock = threading.Lock()
        self._running = False
        self._refusing = False
        self.frozen = False
        self._reopen_timer: threading.Timer | None = None
        self._threads: list[threading.Thread] = []
        self.ticks = 0
        self._worst_lag = 0.0

    # ------------------------------------------------------------ lifecycle
    def start(self) -> LoopbackServer:
        self._running = True
        try:
            self._open_listeners()
        except OSError:
            self._running = False
            raise
        clock = threading.Thread(target=self._clock, name="loopback-clock", daemon=True)
        clock.start()
        self._threads.append(clock)
        return self

    def __enter__(self) -> LoopbackServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._running = False
        if self._reopen_timer is not None:
            self._reopen_timer.cancel()
        self._close_listeners()
        for client in list(self._clients):
            client.close()
        for t in self._threads:
            t.join(timeout=2.0)

    def _open_listeners(self, retry_for: float = 0.0) -> None:
        opened: dict[int, socket.socket] = {}
        try:
            for port in self.ports:
                s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                deadline = time.monotonic() + retry_for
                while True:
                    try:
                        s.bind((self.host, port))
                        break
                    except OSError:
                        if time.monotonic() >= deadline:
                            s.close()
                            raise
                        time.sleep(0.01)
                s.listen(16)
                s.settimeout(0.05)
                opened[port] = s
        except OSError:
            for s in opened.values():
                s.close()
            raise
        self._listeners = opened
        for port, s in opened.items():
            t = threading.Thread(
                target=self._accept, args=(s, port), name=f"loopback-accept-{port}", daemon=True
            )
            t.start()
            self._threads.append(t)

    def _close_listeners(self) -> None:
        listeners, self._listeners = self._listeners, {}
        for s in listeners.values():
            # shutdown() stops listening at once; close() alone leaves the socket accepting
            # into its backlog until the accept thread's poll returns.
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()

    def _accept(self, listener: socket.socket, port: int) -> None:
        kind = self.ports[port]
        cls = {"rtde": _RtdeClient, "dashboard": _DashboardClient, "script": _ScriptClient}[kind]
        while self._running and self._listeners.get(port) is listener:
            try:
                sock, _ = listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            sock.setblocking(True)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client = cls(self, sock, kind, port)
            with self._lock:
                self._clients.add(client)
            client.thread.start()

    def _forget(self, client: _Client) -> None:
        with self._lock:
            self._clients.discard(client)

    # ------------------------------------------------------------ clock
    def _clock(self) -> None:
        ctl = self.controller
        dt = ctl.dt
        next_t = time.monotonic()
        while self._running:
            ctl.tick()
            self.ticks += 1
            if not self.frozen:
                self._publish()
            next_t += dt
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                self._worst_lag = max(self._worst_lag, -delay)
                if delay < -0.25:
                    next_t = time.monotonic()  # fell far behind (loaded machine): do not burst

    def take_worst_lag(self) -> float:
        """The most the control cycle has run behind real time (s) since the previous call:
        how long a loaded machine kept the controller — its motions, its skin's packets —
        waiting. Tests derive their timing margins from it."""
        worst, self._worst_lag = self._worst_lag, 0.0
        return worst

    def _publish(self) -> None:
        with self._lock:
            clients = [c for c in self._clients if isinstance(c, _RtdeClient) and c.started]
        for client in clients:
            for recipe in client.outputs:
                if self.ticks % recipe.divisor == 0:  # type: ignore[attr-defined]
                    client.send(recipe.encode(self.controller.output_values(recipe.names)))

    # ------------------------------------------------------------ faults
    def catch_up_inputs(self) -> None:
        """Handle every RTDE input package that has arrived, now. A real controller applies an
        input package in the control cycle it arrives in; here a reader thread kept waiting (a
        loaded machine) handled it only after a program that arrived later on a script port had
        started: ur_rtde stops a running program (stop command 255 in input_int_register_0),
        clears the register and uploads its script, and the new program read the stale 255
        and stopped at once."""
        with self._lock:
            readers = [c for c in self._clients if isinstance(c, _RtdeClient)]
        for reader in readers:
            try:
                reader.take_input()
            except (OSError, ConnectionError, struct.error, ValueError):
                pass  # (the connection's own reader ends it)

    def drop_connections(self, refuse_for: float | None = 0.0) -> int:
        """Close every client connection (the controller went away from the network).

        ``refuse_for`` seconds new connections are refused (``None``: until :meth:`restore`),
        so a client's automatic reconnect fails as it would against an unreachable robot.
        Returns how many connections were closed.
        """
        if refuse_for != 0.0:
            self._refusing = True
            self._close_listeners()
        with self._lock:
            clients = list(self._clients)
        for c in clients:
            c.close()
        self.controller.log(f"loopback: dropped {len(clients)} connection(s)")
        if refuse_for is not None and refuse_for > 0:
            self._reopen_timer = threading.Timer(refuse_for, self.restore)
            self._reopen_timer.daemon = True
            self._reopen_timer.start()
        return len(clients)

    def freeze(self, frozen: bool = True) -> None:
        """Silence without closing: nothing is read from or sent to any client (cable pulled)."""
        self.frozen = frozen
        self.controller.log(f"loopback: network {'frozen' if frozen else 'thawed'}")

    def restore(self) -> None:
        """Accept connections again after :meth:`drop_connections`."""
        self.frozen = False
        if self._refusing and self._running:
            self._refusing = False
            # The closed listeners may take an accept-poll period to release their ports.
            self._open_listeners(retry_for=1.0)

    @property
    def connections(self) -> dict[str, int]:
        with self._lock:
            out: dict[str, int] = {}
            for c in self._clients:
                out[c.kind] = out.get(c.kind, 0) + 1
            return out
