"""--scheduler pointing at something that answers but is not a Dask scheduler: one line, within
the greeting's wait, before any work (a web server used to leave the benchmark silent for 90 s,
a server answering with nothing a struct.error, a proxy an attempt to allocate 3 EiB)."""

from __future__ import annotations

import http.server
import socket
import socketserver
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from aptkt.cli import main
from aptkt.errors import ConfigError
from aptkt.experiments import executors


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True


@contextmanager
def _serving(handler: type[socketserver.BaseRequestHandler], scheme: str = "tcp") -> Iterator[str]:
    server = _Server(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"{scheme}://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


def _answering(payload: bytes) -> type[socketserver.BaseRequestHandler]:
    class Handler(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            self.request.sendall(payload)

    return Handler


class _Quiet(http.server.BaseHTTPRequestHandler):
    """A web server: it says nothing until it is asked."""

    def log_message(self, *args: object) -> None:
        pass


SERVICES: dict[str, type[socketserver.BaseRequestHandler]] = {
    "a web server": _Quiet,
    "a server answering with nothing": _answering(b""),
    "a proxy's error page": _answering(b"HTTP/1.1 502 Bad Gateway\r\nContent-Length: 0\r\n\r\n"),
    "a small frame that is no handshake": _answering((9).to_bytes(8, "little") + b"123456789"),
}


class _Page(http.server.BaseHTTPRequestHandler):
    """A web server answering every request with a page, a WebSocket upgrade included."""

    def do_GET(self) -> None:
        self.send_response(200)
        self.send_header("Content-Length", "2")
        self.end_headers()
        self.wfile.write(b"hi")

    def log_message(self, *args: object) -> None:
        pass


@pytest.mark.parametrize(
    ("scheme", "service"),
    [("tcp", s) for s in SERVICES] + [("ws", "a web server"), ("ws", "a page")],
)
def test_a_service_that_is_not_dask_is_one_line_before_any_work(
    scheme, service, tmp_path, capsys, monkeypatch
):
    pytest.importorskip("dask.distributed")
    monkeypatch.setattr(executors, "SCHEDULER_GREETING_SECONDS", 1.0)
    table = tmp_path / "t.csv"
    rows = [f"o{k},A,{t},{k + 0.1 * t}" for k in range(8) for t in range(4)]
    table.write_text("object,action,trial,f.0\n" + "\n".join(rows) + "\n")
    with _serving({**SERVICES, "a page": _Page}[service], scheme) as address:
        for argv in (
            ["benchmark", str(table), "--scheduler", address],
            ["prior", "build", str(table), "--scheduler", address],
        ):
            assert main([*argv, "-o", str(tmp_path / "out")]) == 1
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and address in err[0] and "Dask" in err[0], (service, err)
            assert not (tmp_path / "out").exists()


def test_the_python_api_checks_the_address_too(monkeypatch):
    monkeypatch.setattr(executors, "SCHEDULER_GREETING_SECONDS", 1.0)
    with _serving(_answering(b"")) as address:
        with pytest.raises(ConfigError, match="closed the connection"):
            executors.make_executor(scheduler=address)


@pytest.mark.parametrize("scheme", ["tcp", "ws"])
def test_a_dask_scheduler_passes_and_nothing_else_is_reached(scheme):
    pytest.importorskip("dask.distributed")
    from dask.distributed import LocalCluster

    with LocalCluster(
        n_workers=0, processes=False, protocol=f"{scheme}://", dashboard_address=None
    ) as cluster:
        assert cluster.scheduler_address.startswith(f"{scheme}://")
        executors.check_scheduler(cluster.scheduler_address)
    # A closed port: refused at once, named as unreachable (Dask's ws client waits 20 s).
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(ConfigError, match="cannot reach the Dask scheduler"):
        executors.check_scheduler(f"{scheme}://127.0.0.1:{port}")


def test_whatever_dasks_client_raises_is_a_config_error(monkeypatch):
    """Past the check (another transport, or a service that changed its mind), the client's
    own failure is one line too."""
    pytest.importorskip("dask.distributed")
    import dask.distributed

    class Unusable(RuntimeError):
        pass

    class Client:
        def __init__(self, *args: object, **kwargs: object) -> None:
            raise Unusable("Non-websocket response")

    monkeypatch.setattr(dask.distributed, "Client", Client)
    with pytest.raises(ConfigError, match="cannot use the Dask scheduler.*Unusable"):
        executors.make_executor(scheduler="tls://127.0.0.1:1")
