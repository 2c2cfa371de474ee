"""Run a loopback controller in its own process and drive it from the parent.

ur_rtde's constructors (``RTDEControlInterface(...)``, ``RTDEReceiveInterface(...)``) keep the
Python GIL while they wait for the controller's answers, so a controller served by threads of
the *same* interpreter can never answer them: the client would deadlock. The loopback
therefore always runs in a child process (``python -m aptkt.sim.loopback --stdio``);
:class:`Loopback` is the parent's handle. Commands cross the child's stdin/stdout as JSON lines.
"""

from __future__ import annotations

import json
import select
import subprocess
import sys
import tempfile
import threading
import traceback
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from typing import Any

from aptkt.errors import InvalidInputError
from aptkt.sim.loopback.config import CB3_VERSION, E_SERIES_VERSION, ControllerConfig
from aptkt.sim.loopback.controller import SimulatedController
from aptkt.sim.loopback.servers import LoopbackServer
from aptkt.sim.loopback.tcp_skin import SkinConfig

__all__ = ["Loopback", "LoopbackError"]


class LoopbackError(RuntimeError):
    """The loopback process failed to start or to execute a command."""


def serve_stdio(
    config: ControllerConfig, host: str, ports: Mapping[str, Any], stdin: Any, stdout: Any
) -> None:
    """Child side: serve the controller, read JSON commands from ``stdin``, answer on ``stdout``."""
    # Imported here so importing this module never builds a controller.

    def answer(reply: dict[str, Any]) -> None:
        stdout.write(json.dumps(reply) + "\n")
        stdout.flush()

    try:
        controller = SimulatedController(config)
        server = LoopbackServer(
            controller,
            host=host,
            rtde_port=ports["rtde"],
            dashboard_port=ports["dashboard"],
            script_ports=ports["script"],
        ).start()
    except Exception as exc:  # report start-up failures (port busy, bad config) to the parent
        answer({"ok": False, "error": f"{type(exc).__name__}: {exc}"})
        return
    answer({"ok": True, "result": "ready"})

    def dispatch(op: str, args: dict[str, Any]) -> Any:
        if op == "state":
            state = controller.snapshot()
            state["connections"] = server.connections
            return state
        if op == "normal_force":
            with controller.lock:
                return controller.normal_force()
        if op == "contact":
            with controller.lock:
                return {"time": controller.time, "normal_force": controller.normal_force()}
        if op == "reset":
            controller.reset(
                pose=args.get("pose"), keep_program=bool(args.get("keep_program", False))
            )
            server.restore()
            return None
        if op == "set_contact":
            controller.set_contact(args.get("spec"))
            return None
        if op == "protective_stop":
            controller.trigger_protective_stop(args.get("reason", "injected by test"))
            return None
        if op == "stop_program":
            controller.stop_program(args.get("reason", "injected by test"))
            return None
        if op == "disturb":
            controller.disturb(args["velocity"], float(args["duration"]), args.get("acceleration"))
            return None
        if op == "drop_connections":
            return server.drop_connections(args.get("refuse_for", 0.0))
        if op == "freeze":
            server.freeze(bool(args.get("frozen", True)))
            return None
        if op == "restore":
            server.restore()
            return None
        if op == "scripts":
            with controller.lock:
                return list(controller.received_scripts)
        if op == "skin":
            with controller.lock:
                return None if controller.skin is None else controller.skin.stats()
        if op == "skin_silence":
            with controller.lock:
                _need_skin(controller).silence(args.get("cells"))
            return None
        if op == "skin_restore":
            with controller.lock:
                _need_skin(controller).restore()
            return None
        if op == "clock_lag":
            return server.take_worst_lag()
        if op == "ping":
            return "pong"
        raise InvalidInputError(f"unknown loopback command {op!r}")

    try:
        for line in stdin:
            if not line.strip():
                continue
            msg = json.loads(line)
            if msg.get("op") == "shutdown":
                answer({"ok": True, "result": None})
                break
            try:
                reply = {"ok": True, "result": dispatch(msg["op"], msg.get("args", {}))}
            except Exception as exc:
                reply = {
                    "ok": False,
                    "error": f"{type(exc).__name__}: {exc}",
                    "trace": traceback.format_exc(),
                }
            answer(reply)
    finally:  # the parent closed the pipe or asked to stop
        server.close()
        if controller.skin is not None:
            controller.skin.close()


def _need_skin(controller: Any) -> Any:
    if controller.skin is None:
        raise InvalidInputError(
            "this loopback has no simulated skin (start it with skin=True / --skin-pty)"
        )
    return controller.skin


class Loopback:
    """Handle on a loopback UR controller running in a child process.

    >>> with Loopback(contact={"type": "spring", "surface_z": 0.0}) as lb:   # doctest: +SKIP
    ...     rtde_r = rtde_receive.RTDEReceiveInterface(lb.host)
    ...     lb.state()["pose"]

    ``series="cb3"`` (125 Hz, PolyScope 3.15) or ``"e-series"`` (500 Hz, PolyScope 5.11), or an
    explicit ``version`` tuple. ``skin=True`` (or a mapping of
    :class:`~aptkt.sim.loopback.tcp_skin.SkinConfig` fields) puts a simulated skin patch on the
    TCP that streams the skin's wire protocol through a pty: open ``SerialSkin(lb.skin_port)``.
    Other keyword arguments are :class:`ControllerConfig` fields.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        *,
        series: str = "cb3",
        contact: Mapping[str, Any] | None = None,
        skin: bool | Mapping[str, Any] | None = None,
        ports: Mapping[str, Any] | None = None,
        start_timeout: float = 30.0,
        **config: Any,
    ):
        if skin is not None and skin is not False:
            skin_config = SkinConfig.from_spec(skin)  # validated here, in the parent
            if skin_config is not None:
                config["skin"] = skin_config.to_dict()
        self._skin_port: str | None = None
        if "version" not in config:
            if series not in ("cb3", "e-series"):
                raise InvalidInputError(f"series must be 'cb3' or 'e-series', got {series!r}")
            config["version"] = CB3_VERSION if series == "cb3" else E_SERIES_VERSION
        self.config = ControllerConfig(contact=None if contact is None else dict(contact), **config)
        self.host = host
        self.ports = {"rtde": 30004, "dashboard": 29999, "script": [30001, 30002, 30003]}
        if ports:
            self.ports.update(ports)
        self.start_timeout = start_timeout
        self._proc: subprocess.Popen[str] | None = None
        self._stderr: Any = None
        self._lock = threading.Lock()

    @property
    def frequency(self) -> float:
        return self.config.frequency

    def start(self) -> Loopback:
        cmd = [
            sys.executable,
            "-m",
            "aptkt.sim.loopback",
            "--stdio",
            "--host",
            self.host,
            "--config-json",
            json.dumps(asdict(self.config)),
            "--ports-json",
            json.dumps(self.ports),
        ]
        self._stderr = tempfile.TemporaryFile(mode="w+")
        self._proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            text=True,
            bufsize=1,
        )
        try:
            reply = self._read_reply(self.start_timeout, "start")
        except LoopbackError:
            self._kill()
            raise
        if not reply["ok"]:
            self._kill()
            raise LoopbackError(f"loopback on {self.host} failed to start: {reply['error']}")
        if self.config.skin is not None:
            stats = self.skin_stats()
            assert stats is not None  # the controller was started with a skin
            self._skin_port = stats["port"]
        return self

    def __enter__(self) -> Loopback:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def close(self) -> None:
        """Stop the controller process (its sockets close with it)."""
        if self._proc is None:
            return
        try:
            self.call("shutdown", timeout=5.0)
        except LoopbackError:
            pass
        self._kill()

    def _kill(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        for stream in (proc.stdin, proc.stdout):
            try:
                if stream is not None:
                    stream.close()
            except OSError:
                pass
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5.0)

    def _stderr_tail(self) -> str:
        try:
            self._stderr.seek(0)
            return self._stderr.read()[-2000:]
        except (OSError, ValueError, AttributeError):
            return ""

    def _read_reply(self, timeout: float, op: str) -> dict[str, Any]:
        assert self._proc is not None and self._proc.stdout is not None
        ready, _, _ = select.select([self._proc.stdout], [], [], timeout)
        if not ready:
            raise LoopbackError(f"loopback did not answer {op!r} within {timeout} s")
        line = self._proc.stdout.readline()
        if not line:
            raise LoopbackError(f"loopback process exited during {op!r}: {self._stderr_tail()}")
        return json.loads(line)

    def call(self, op: str, timeout: float = 10.0, **args: Any) -> Any:
        """Send one command to the controller process and return its result."""
        with self._lock:
            if self._proc is None or self._proc.stdin is None:
                raise LoopbackError("loopback is not running")
            try:
                self._proc.stdin.write(json.dumps({"op": op, "args": args}) + "\n")
                self._proc.stdin.flush()
            except (OSError, ValueError) as exc:
                raise LoopbackError(
                    f"loopback process is gone: {exc}: {self._stderr_tail()}"
                ) from None
            reply = self._read_reply(timeout, op)
        if not reply["ok"]:
            raise LoopbackError(f"loopback {op!r} failed: {reply['error']}")
        return reply["result"]

    # Convenience wrappers ------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """Pose, velocity, wrench, program and safety state, recent controller log lines."""
        return self.call("state")

    def normal_force(self) -> float:
        """Normal force of the contact model at the current TCP pose (what a skin would feel)."""
        return float(self.call("normal_force"))

    def contact(self) -> tuple[float, float]:
        """``(controller time, normal force)`` read together: when the force was felt, on the
        clock the RTDE samples carry."""
        reply = self.call("contact")
        return float(reply["time"]), float(reply["normal_force"])

    def reset(self, pose: Sequence[float] | None = None, keep_program: bool = False) -> None:
        self.call("reset", pose=None if pose is None else list(pose), keep_program=keep_program)

    def set_contact(self, spec: Mapping[str, Any] | None) -> None:
        self.call("set_contact", spec=None if spec is None else dict(spec))

    def protective_stop(self, reason: str = "injected by test") -> None:
        self.call("protective_stop", reason=reason)

    def stop_program(self, reason: str = "injected by test") -> None:
        self.call("stop_program", reason=reason)

    def disturb(
        self, velocity: Sequence[float], duration: float, acceleration: float | None = None
    ) -> None:
        """Push the TCP with an extra base-frame velocity (see SimulatedController.disturb)."""
        self.call("disturb", velocity=list(velocity), duration=duration, acceleration=acceleration)

    def drop_connections(self, refuse_for: float | None = 0.0) -> int:
        """Close every connection; refuse new ones for ``refuse_for`` s (None: until restore)."""
        return int(self.call("drop_connections", refuse_for=refuse_for))

    def freeze(self, frozen: bool = True) -> None:
        self.call("freeze", frozen=frozen)

    def restore(self) -> None:
        self.call("restore")

    # The simulated skin ------------------------------------------------------------------
    @property
    def skin_port(self) -> str | None:
        """The pty the simulated skin streams to (None without a skin)."""
        return self._skin_port

    def skin_stats(self) -> dict[str, Any] | None:
        """Packets written and dropped, silent cells, the object the cells last touched."""
        return self.call("skin")

    def silence_skin(self, cells: Sequence[int] | None = None) -> None:
        """Mute skin cells (ids; None: all of them, as if the patch were unplugged)."""
        self.call("skin_silence", cells=None if cells is None else [int(c) for c in cells])

    def restore_skin(self) -> None:
        """Every skin cell sends again."""
        self.call("skin_restore")

    def clock_lag(self) -> float:
        """The most the controller's control cycle has run behind real time (s) since the
        previous call (:meth:`LoopbackServer.take_worst_lag`)."""
        return float(self.call("clock_lag"))

    def scripts(self) -> list[str]:
        """The last programs received on the script ports (newest last)."""
        return list(self.call("scripts"))
