"""The skin through its USB serial adapter (FTDI FT232H "SkinCellAdapter", 4,000,000 baud)."""

from __future__ import annotations

import errno
import time
from pathlib import Path
from typing import Any

import serial

from aptkt.errors import SkinDisconnectedError
from aptkt.skin.config import PatchConfig
from aptkt.skin.source import Clock, ThreadedSkinSource

__all__ = ["SerialSkin", "BAUDRATE"]

#: The adapter's line rate: 8N1 → at most 400,000 bytes/s = 20,000 sensor packets/s.
BAUDRATE = 4_000_000


def _open_error(port: str, exc: Exception) -> SkinDisconnectedError:
    """Turn pyserial's open failure into a message that says what to do."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.ENOENT or "No such file" in text:
        why = "port not found (is the skin adapter plugged in? is the name right?)"
    elif (
        code in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in text or "Resource busy" in text
    ):
        why = "port is busy (another program, or another aptkt source, has it open)"
    elif code == errno.EACCES or "Permission denied" in text:
        why = "permission denied (is your user in the 'dialout' group?)"
    else:
        why = text
    return SkinDisconnectedError(f"serial skin {port}: cannot open: {why}")


class SerialSkin(ThreadedSkinSource):
    """Skin source on a serial port, read by a background thread.

    Each read's bytes are stamped with the arrival time (``clock``, ns) when the read
    returned and parsed at once; parsed samples wait in a bounded ring buffer
    (``buffer_rows``; overflow drops the oldest rows and is counted) until :meth:`read`.
    A missing, busy or unplugged port raises :class:`~aptkt.errors.SkinDisconnectedError`;
    an unplug mid-stream keeps the data already received and any open recording.
    """

    def __init__(
        self,
        port: str,
        patch: PatchConfig | str | Path | None = None,
        *,
        baudrate: int = BAUDRATE,
        read_timeout_s: float = 0.02,
        max_read: int = 1 << 16,
        buffer_rows: int = 1 << 16,
        clock: Clock = time.monotonic_ns,
    ) -> None:
        super().__init__(patch, buffer_rows=buffer_rows, clock=clock)
        self.port = port
        self.baudrate = baudrate
        self.read_timeout_s = read_timeout_s
        self.max_read = max_read
        self._serial: serial.Serial | None = None
        self._reads = 0

    def open(self) -> None:
        if self._serial is not None:
            return
        try:
            # exclusive=True takes an advisory lock, so a second reader fails loudly ("busy")
            # instead of silently stealing half the bytes.
            ser = serial.Serial(
                self.port, self.baudrate, timeout=self.read_timeout_s, exclusive=True
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise _open_error(self.port, exc) from exc
        self._serial = ser
        self._mark_opened()
        self._start_reader(f"SerialSkin({self.port})")

    def close(self) -> None:
        self._stop_reader()
        if self._serial is not None:
            try:
                self._serial.close()
            except (serial.SerialException, OSError):
                pass  # already gone (unplugged); nothing left to release
            self._serial = None

    def _reader(self) -> None:
        ser = self._serial
        if ser is None:
            return
        while not self._stopping():
            try:
                # Wait for at least one byte (or the timeout), then take all that is there.
                waiting = ser.in_waiting
                data = ser.read(min(max(waiting, 1), self.max_read))
            except (serial.SerialException, OSError, TypeError) as exc:
                # pyserial raises SerialException on EIO / "returned no data" when the device
                # disappears; TypeError/OSError come from reads racing a close.
                if not self._stopping():
                    self._fail(
                        SkinDisconnectedError(
                            f"serial skin {self.port}: link lost mid-stream: {exc}"
                        )
                    )
                return
            if data:
                self._reads += 1
                self._ingest_bytes(data, self._now())

    def _extra_stats(self) -> dict[str, Any]:
        return {"port": self.port, "reads": self._reads}
