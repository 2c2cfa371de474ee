"""The skin through the Ethernet "Tactile Section Unit" (TSU), over UDP.

Framing (hardware contract): the TSU sends from port 1336 to the PC's port 1337; each datagram
is one byte, the TSU port number (1..32), followed by one skin packet *without* its trailing
0xAA. The PC sends an "alive" datagram to the TSU every 100 ms.
"""

from __future__ import annotations

import socket
import time
from collections import Counter
from pathlib import Path
from typing import Any

from aptkt.errors import SkinDisconnectedError
from aptkt.skin.config import PatchConfig
from aptkt.skin.protocol import PACKET_LEN
from aptkt.skin.source import Clock, ThreadedSkinSource

__all__ = ["TsuSkin", "TSU_ADDRESS", "LISTEN_ADDRESS", "ALIVE_INTERVAL_S", "DATAGRAM_LEN"]

TSU_ADDRESS = ("192.168.0.10", 1336)
LISTEN_ADDRESS = ("0.0.0.0", 1337)
ALIVE_INTERVAL_S = 0.1
#: Port byte + a packet without its end marker.
DATAGRAM_LEN = PACKET_LEN
_END = b"\xaa"
#: Datagrams drained per wake-up before parsing them together.
_BATCH = 256


class TsuSkin(ThreadedSkinSource):
    """Skin source on UDP from a TSU.

    ``tsu_address`` is where the alive datagrams go and whose datagrams are accepted (others
    are counted as ``foreign_datagrams`` and ignored); ``listen_address`` is the local
    socket (port 0 picks a free port, see :attr:`local_address`). The contract does not fix
    the alive datagram's content: ``alive_payload`` (default one zero byte) is sent as is.
    Datagrams of the wrong length are counted as ``bad_datagrams`` and dropped whole.
    UDP has no disconnect signal: a TSU that stops sending shows up as silent cells; a
    failing network interface (send errors) raises :class:`~aptkt.errors.SkinDisconnectedError`.
    """

    def __init__(
        self,
        patch: PatchConfig | str | Path | None = None,
        *,
        tsu_address: tuple[str, int] = TSU_ADDRESS,
        listen_address: tuple[str, int] = LISTEN_ADDRESS,
        alive_interval_s: float = ALIVE_INTERVAL_S,
        alive_payload: bytes = b"\x00",
        buffer_rows: int = 1 << 16,
        clock: Clock = time.monotonic_ns,
    ) -> None:
        super().__init__(patch, buffer_rows=buffer_rows, clock=clock)
        self.tsu_address = (tsu_address[0], int(tsu_address[1]))
        self.listen_address = (listen_address[0], int(listen_address[1]))
        self.alive_interval_s = alive_interval_s
        self.alive_payload = bytes(alive_payload)
        self._sock: socket.socket | None = None
        self._tsu_ip = ""
        self._counts: Counter[str] = Counter()
        self._per_port: Counter[int] = Counter()

    @property
    def local_address(self) -> tuple[str, int] | None:
        """The bound local (host, port), once open."""
        return None if self._sock is None else self._sock.getsockname()[:2]

    def open(self) -> None:
        if self._sock is not None:
            return
        where = f"{self.listen_address[0]}:{self.listen_address[1]}"
        try:
            self._tsu_ip = socket.gethostbyname(self.tsu_address[0])
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        except OSError as exc:
            raise SkinDisconnectedError(
                f"TSU skin: cannot resolve {self.tsu_address[0]!r}: {exc}"
            ) from exc
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.bind(self.listen_address)
        except OSError as exc:
            sock.close()
            raise SkinDisconnectedError(
                f"TSU skin: cannot listen on udp {where}: {exc.strerror or exc}"
            ) from exc
        self._sock = sock
        self._mark_opened()
        self._start_reader("TsuSkin")

    def close(self) -> None:
        self._stop_reader()
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _send_alive(self, sock: socket.socket) -> None:
        sock.sendto(self.alive_payload, self.tsu_address)
        self._counts["alive_sent"] += 1

    def _reader(self) -> None:
        sock = self._sock
        if sock is None:
            return
        next_alive = time.monotonic()
        while not self._stopping():
            try:
                now = time.monotonic()
                if now >= next_alive:
                    self._send_alive(sock)
                    next_alive = max(next_alive + self.alive_interval_s, now)
                # Sleep in recvfrom no longer than until the next alive datagram is due.
                batch = self._receive(sock, max(next_alive - time.monotonic(), 0.001))
            except OSError as exc:
                if not self._stopping():
                    self._fail(
                        SkinDisconnectedError(f"TSU skin {self.tsu_address[0]}: link failed: {exc}")
                    )
                return
            if batch:
                self._ingest_bytes(b"".join(batch), self._now())

    def _receive(self, sock: socket.socket, timeout_s: float) -> list[bytes]:
        """Wait for one datagram, then drain what else is queued; returns re-framed packets."""
        packets: list[bytes] = []
        sock.settimeout(timeout_s)
        try:
            datagram, sender = sock.recvfrom(2048)
        except TimeoutError:
            return packets
        except ConnectionRefusedError:
            return packets  # ICMP port-unreachable for an alive datagram: the TSU is not up yet
        self._accept(datagram, sender, packets)
        sock.setblocking(False)
        for _ in range(_BATCH - 1):
            try:
                datagram, sender = sock.recvfrom(2048)
            except (BlockingIOError, ConnectionRefusedError):
                break
            self._accept(datagram, sender, packets)
        return packets

    def _accept(self, datagram: bytes, sender: tuple[str, int], out: list[bytes]) -> None:
        if sender[0] != self._tsu_ip or sender[1] != self.tsu_address[1]:
            self._counts["foreign_datagrams"] += 1
            return
        self._counts["datagrams"] += 1
        if len(datagram) != DATAGRAM_LEN:
            self._counts["bad_datagrams"] += 1
            return
        self._per_port[datagram[0]] += 1
        out.append(datagram[1:] + _END)

    def _extra_stats(self) -> dict[str, Any]:
        return {
            "datagrams": self._counts["datagrams"],
            "bad_datagrams": self._counts["bad_datagrams"],
            "foreign_datagrams": self._counts["foreign_datagrams"],
            "alive_sent": self._counts["alive_sent"],
            "datagrams_per_tsu_port": dict(self._per_port),
        }
