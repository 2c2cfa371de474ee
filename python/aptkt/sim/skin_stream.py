"""The simulated skin: the world's sensor frames become the protocol's bytes.

Every frame goes through :func:`aptkt.skin.quantize` (the protocol's resolutions) and
:func:`aptkt.skin.encode_sensor_packets` (the wire format), then either

* :class:`SimSkin` — parsed in-process by the shared skin-source machinery (the same parser,
  calibration, recording windows and silent-cell checks as every hardware source), on the
  simulated clock: the fast path for bulk data; or
* :class:`PtySkinLink` — written to a pseudo-terminal in real time, where an unmodified
  :class:`~aptkt.skin.SerialSkin` reads it exactly as it reads the USB adapter.
"""

from __future__ import annotations

import errno
import os
import tty
from collections.abc import Callable

from aptkt.sim.physics import Frames
from aptkt.skin import PatchConfig, encode_sensor_packets, quantize
from aptkt.skin.source import SkinSourceBase

__all__ = ["encode_frames", "SimSkin", "PtySkinLink"]


def encode_frames(frames: Frames) -> bytes:
    """Quantise frames to the protocol's raw integers and encode them as sensor packets."""
    raw = quantize(frames.cell_id, frames.proximity, frames.acc, frames.temp, frames.force)
    return encode_sensor_packets(raw)


class SimSkin(SkinSourceBase):
    """In-process skin source of the simulated world (simulated clock).

    ``stream_all=False`` (the default) lets the world skip synthesising packets nobody will see:
    outside recording windows, long open-loop stretches deliver only each cell's newest packet,
    so latest values and the total force stay exact while a 30 s thermal wait costs little.
    """

    def __init__(
        self,
        patch: PatchConfig,
        clock: Callable[[], int],
        *,
        stream_all: bool = False,
        buffer_rows: int = 1 << 16,
    ):
        super().__init__(patch, buffer_rows=buffer_rows, clock=clock)
        self.stream_all = stream_all
        self._open = False

    def open(self) -> None:
        self._open = True
        self._mark_opened()

    def close(self) -> None:
        self._open = False

    # FrameSink
    def deliver(self, frames: Frames) -> None:
        if len(frames) and self._open:
            self._ingest_bytes(encode_frames(frames), frames.t_ns)

    def wants_detail(self) -> bool:
        return self.stream_all or self.recording


class PtySkinLink:
    """The simulated adapter end of a pseudo-terminal: ``port`` is what SerialSkin opens.

    Writes never block the simulation: if the reader falls behind and the pty's buffer is
    full, bytes are dropped and counted (as an adapter's FIFO overflows). Bytes the reader
    sends (commands such as the update rate) are drained and counted.
    """

    def __init__(self) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.port = os.ttyname(self._slave)
        self.bytes_written = 0
        self.bytes_dropped = 0
        self.bytes_received = 0

    def deliver(self, frames: Frames) -> None:
        if not len(frames) or self.master < 0:
            return
        self.write(encode_frames(frames))

    def write(self, data: bytes) -> None:
        """Send wire bytes to the reader; what does not fit in the pty's buffer is dropped and
        counted (used directly by the loopback controller's skin)."""
        if self.master < 0:
            return
        view = memoryview(data)
        while view:
            try:
                n = os.write(self.master, view)
            except BlockingIOError:
                self.bytes_dropped += len(view)
                break
            except OSError as exc:
                if exc.errno in (errno.EIO, errno.EBADF):
                    self.bytes_dropped += len(view)
                    break
                raise
            self.bytes_written += n
            view = view[n:]
        self._drain()

    def _drain(self) -> None:
        try:
            while True:
                chunk = os.read(self.master, 4096)
                if not chunk:
                    return
                self.bytes_received += len(chunk)
        except (BlockingIOError, OSError):
            return

    def wants_detail(self) -> bool:
        return True

    def close(self) -> None:
        for fd in (self.master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master = self._slave = -1

    def __enter__(self) -> PtySkinLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
