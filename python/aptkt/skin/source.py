"""What every skin source shares: parsing, calibration, latest values, recordings, link health.

Concrete sources (serial adapter, TSU over UDP, the simulator) only move bytes: they call
:meth:`SkinSourceBase._ingest_bytes` with each chunk and its arrival time, and
:meth:`SkinSourceBase._fail` when the link breaks. Everything the rest of aptkt sees —
:meth:`read`, :meth:`total_normal_force`, recording windows, silent-cell detection, ``stats`` —
lives here once.

Time: every timestamp comes from the source's ``clock`` (``time.monotonic_ns`` by default,
nanoseconds). A simulated source passes its simulated clock, so silence detection and
recording windows run on simulated time.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import SilentCellError, SkinError, TrialFault
from aptkt.skin.config import PatchConfig, default_patch, load_patch
from aptkt.skin.protocol import StreamParser, to_physical
from aptkt.skin.ring import SampleRing
from aptkt.skin.samples import Recording, SkinSamples

__all__ = ["SkinSourceBase", "Clock"]

Clock = Callable[[], int]

#: Rate estimates use counts from snapshots at least this far apart (ns) …
_SNAPSHOT_EVERY_NS = 250_000_000
#: … keeping this many, i.e. a window of about two seconds.
_SNAPSHOTS = 9


class SkinSourceBase:
    """Base class of skin sources; implements the :class:`~aptkt.skin.base.SkinSource` protocol
    except :meth:`open` and :meth:`close`, which subclasses provide.

    Samples from cells that the patch does not describe are not calibrated and therefore not
    passed on; they are counted in ``stats["unknown_cells"]`` (a patch file that misses a cell
    shows up there, and in ``aptkt skin monitor``).
    """

    def __init__(
        self,
        patch: PatchConfig | str | Path | None = None,
        *,
        buffer_rows: int = 1 << 16,
        clock: Clock = time.monotonic_ns,
    ) -> None:
        if patch is None:
            patch = default_patch()
        elif not isinstance(patch, PatchConfig):
            patch = load_patch(patch)
        self.patch = patch
        self.calibration = patch.calibration()
        self._clock = clock
        self._lock = threading.RLock()
        self._parser = StreamParser()
        self._ring = SampleRing(buffer_rows)
        k = len(patch.cells)
        self._count = np.zeros(k, dtype=np.int64)
        self._last_ns = np.full(k, -1, dtype=np.int64)
        self._latest = {
            "proximity": np.full(k, np.nan),
            "acc": np.full((k, 3), np.nan),
            "temp": np.full((k, 2), np.nan),
            "force": np.full((k, 3), np.nan),
        }
        self._unknown: Counter[int] = Counter()
        self._snapshots: deque[tuple[int, np.ndarray]] = deque(maxlen=_SNAPSHOTS)
        self._recording: list[SkinSamples] | None = None
        self._rec_start = 0
        self._rec_meta: dict[str, Any] = {}
        self._error: SkinError | None = None
        self._opened_ns: int | None = None

    # ------------------------------------------------------------------ for subclasses
    def _now(self) -> int:
        return int(self._clock())

    def _ingest_bytes(self, data: bytes, t_ns: int | np.ndarray) -> int:
        """Parse a chunk of the byte stream that arrived at ``t_ns`` and distribute its samples.

        ``t_ns`` is one arrival time for the whole chunk (hardware: taken when the read
        returned) or an array with one time per sensor packet the chunk completes (a simulator
        that knows when each packet was sent). Returns the number of sensor packets parsed.
        """
        with self._lock:
            parsed = self._parser.feed(data, raw=True)
            n = len(parsed["cell_id"])
            if n:
                t = np.broadcast_to(np.asarray(t_ns, dtype=np.int64), (n,))
                self._distribute(parsed, t)
            return n

    def _distribute(self, parsed: dict[str, np.ndarray], t_ns: np.ndarray) -> None:
        rows = self.calibration.rows(parsed["cell_id"])
        known = rows >= 0
        if not known.all():
            self._unknown.update(parsed["cell_id"][~known].tolist())
            parsed = {k: v[known] for k, v in parsed.items()}
            t_ns, rows = t_ns[known], rows[known]
            if not len(rows):
                return
        # The one conversion of these samples to physical units (the raw integers are kept
        # for the data set store).
        force_norm = to_physical("force", parsed["force"])
        force_n = self.calibration.gain[rows] * (force_norm - self.calibration.offset[rows])
        samples = SkinSamples(
            cell_id=parsed["cell_id"],
            t_ns=np.ascontiguousarray(t_ns),
            proximity=to_physical("proximity", parsed["proximity"]),
            acc=to_physical("acc", parsed["acc"]),
            temp=to_physical("temp", parsed["temp"]),
            force=force_n,
            raw=parsed,
        )
        # Latest value per cell: the last row of each cell in this batch.
        last = np.full(len(self._count), -1, dtype=np.intp)
        np.maximum.at(last, rows, np.arange(len(rows)))
        seen = np.flatnonzero(last >= 0)
        src = last[seen]
        self._latest["proximity"][seen] = samples.proximity[src]
        self._latest["acc"][seen] = samples.acc[src]
        self._latest["temp"][seen] = samples.temp[src]
        self._latest["force"][seen] = samples.force[src]
        self._last_ns[seen] = samples.t_ns[src]
        self._count += np.bincount(rows, minlength=len(self._count))
        self._snapshot(self._now())
        self._ring.push(samples)
        if self._recording is not None:
            keep = samples.t_ns >= self._rec_start
            self._recording.append(samples if keep.all() else samples.take(keep))

    def _fail(self, error: SkinError) -> None:
        """Record that the link broke (called from a reader thread). Buffered samples and an
        open recording are kept; the next :meth:`read` after the buffer is drained, and
        :meth:`total_normal_force`, raise ``error``."""
        with self._lock:
            if self._error is None:
                self._error = error
            self._parser.discard_pending()

    def _mark_opened(self) -> None:
        with self._lock:
            self._error = None
            self._opened_ns = self._now()
            self._parser.discard_pending()

    def _extra_stats(self) -> dict[str, Any]:
        """Source-specific counters merged into :attr:`stats` (override)."""
        return {}

    # ------------------------------------------------------------------ the SkinSource API
    def open(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def close(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def __enter__(self) -> SkinSourceBase:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def link_error(self) -> SkinError | None:
        """The error that broke the link, if it broke."""
        return self._error

    def read(self) -> SkinSamples:
        """Samples that arrived since the previous call (calibrated force in N), oldest first.

        After the link broke, buffered samples are still returned; once they are drained the
        link error (e.g. :class:`~aptkt.errors.SkinDisconnectedError`) is raised.
        """
        with self._lock:
            samples = self._ring.drain()
            if not len(samples) and self._error is not None:
                raise self._error
            return samples

    def latest(self) -> dict[str, np.ndarray]:
        """Latest values of each patch cell (rows in ``patch.cell_ids`` order; NaN before a
        cell's first packet) and ``t_ns`` of that packet (-1 before it)."""
        with self._lock:
            out = {k: v.copy() for k, v in self._latest.items()}
            out["t_ns"] = self._last_ns.copy()
            out["cell_id"] = np.array(self.patch.cell_ids, dtype=np.uint16)
            return out

    def silent_cells(self, now_ns: int | None = None) -> tuple[int, ...]:
        """Patch cells with no packet within the patch's ``silence_timeout_s`` of now."""
        with self._lock:
            now = self._now() if now_ns is None else now_ns
            timeout = int(self.patch.silence_timeout_s * 1e9)
            stale = (self._last_ns < 0) | (now - self._last_ns > timeout)
            return tuple(c for c, s in zip(self.patch.cell_ids, stale) if s)

    def wait_for_cells(self, timeout_s: float = 2.0, poll_s: float = 0.005) -> None:
        """Block (wall-clock) until every patch cell has sent recently; raises
        :class:`~aptkt.errors.SilentCellError` naming the cells that did not, or the link error."""
        deadline = time.monotonic() + timeout_s
        while True:
            if self._error is not None:
                raise self._error
            silent = self.silent_cells()
            if not silent:
                return
            if time.monotonic() >= deadline:
                raise SilentCellError(
                    f"{type(self).__name__}: no data from cell(s) {list(silent)} within {timeout_s} s"
                )
            time.sleep(poll_s)

    def total_normal_force(self) -> float:
        """Sum over all patch cells and their three sensors of the latest calibrated forces (N).

        Refuses to answer from stale data, because the robot stops on this value: raises
        :class:`~aptkt.errors.SilentCellError` if any patch cell is silent and the link error if
        the link broke.
        """
        with self._lock:
            if self._error is not None:
                raise self._error
            silent = self.silent_cells()
            if silent:
                raise SilentCellError(
                    f"{type(self).__name__}: cell(s) {list(silent)} silent for more than "
                    f"{self.patch.silence_timeout_s} s; total force unknown"
                )
            return float(self._latest["force"].sum())

    def start_recording(self, metadata: dict[str, Any] | None = None) -> None:
        """Start collecting every sample that arrives from now until :meth:`stop_recording`."""
        with self._lock:
            if self._recording is not None:
                raise SkinError(f"{type(self).__name__}: a recording is already running")
            self._rec_start = self._now()
            self._rec_meta = dict(metadata or {})
            self._recording = []

    @property
    def recording(self) -> bool:
        return self._recording is not None

    def stop_recording(self, strict: bool = False) -> Recording:
        """End the window and return its samples.

        Works after a link failure too: what arrived before it is returned and the error is in
        ``metadata["link_error"]``. Cells that sent nothing, or stopped for longer than the
        patch's ``silence_timeout_s``, are listed in ``silent_cells`` (never zero-filled). With
        ``strict=True`` that raises a :class:`~aptkt.errors.TrialFault` caused by
        :class:`~aptkt.errors.SilentCellError`, whose ``recording`` still holds the data.
        """
        with self._lock:
            if self._recording is None:
                raise SkinError(
                    f"{type(self).__name__}: stop_recording() without start_recording()"
                )
            stop = self._now()
            parts, start = self._recording, self._rec_start
            self._recording = None
            samples = SkinSamples.concat(parts)
            if len(samples):
                samples = samples.between(start, stop + 1)
            metadata = {
                "source": type(self).__name__,
                "patch": self.patch.name,
                **self._rec_meta,
            }
            if self._error is not None:
                metadata["link_error"] = str(self._error)
            silent = self._silent_in(samples, start, stop)
        rec = Recording(
            samples=samples,
            start_ns=start,
            stop_ns=stop,
            cells=self.patch.cell_ids,
            silent_cells=silent,
            metadata=metadata,
        )
        if strict and silent:
            err = SilentCellError(
                f"{type(self).__name__}: cell(s) {list(silent)} silent during the recording"
            )
            raise TrialFault(err, rec) from err
        return rec

    def _silent_in(self, samples: SkinSamples, start: int, stop: int) -> tuple[int, ...]:
        """Cells with a gap longer than the silence timeout anywhere in [start, stop]."""
        timeout = int(self.patch.silence_timeout_s * 1e9)
        silent = []
        for cid in self.patch.cell_ids:
            t = samples.t_ns[samples.cell_id == cid]
            if not len(t):
                silent.append(cid)
                continue
            gaps = np.diff(np.concatenate(([start], np.sort(t), [stop])))
            if gaps.max() > timeout:
                silent.append(cid)
        return tuple(silent)

    def _snapshot(self, now: int) -> None:
        if not self._snapshots or now - self._snapshots[-1][0] >= _SNAPSHOT_EVERY_NS:
            self._snapshots.append((now, self._count.copy()))

    @property
    def stats(self) -> dict[str, Any]:
        """Link health and traffic: the parser's counters (``packets``, ``bytes``,
        ``bytes_skipped``, ``rejected`` by reason, ``other_packets`` by type, ...) plus
        ``overflows`` (rows dropped from the full buffer), ``buffered``, ``packets_per_cell``,
        ``rate_hz`` per cell over the last ~2 s, ``unknown_cells``, ``silent_cells`` and
        ``link_error``."""
        with self._lock:
            now = self._now()
            self._snapshot(now)
            t0, c0 = self._snapshots[0]
            dt = (now - t0) * 1e-9
            rates = (self._count - c0) / dt if dt > 0.05 else np.full(len(self._count), np.nan)
            out: dict[str, Any] = dict(self._parser.stats)
            out.update(
                overflows=self._ring.overflows,
                buffered=len(self._ring),
                packets_per_cell=dict(zip(self.patch.cell_ids, self._count.tolist())),
                rate_hz=dict(zip(self.patch.cell_ids, rates.tolist())),
                unknown_cells=dict(self._unknown),
                silent_cells=self.silent_cells(now),
                link_error=None if self._error is None else str(self._error),
            )
            out.update(self._extra_stats())
            return out


class ThreadedSkinSource(SkinSourceBase):
    """A source whose link is read by one background thread (``_reader``, to be provided):
    starting and stopping that thread is the same for every link."""

    _thread: threading.Thread | None = None

    def _start_reader(self, name: str) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._reader, name=name, daemon=True)
        self._thread.start()

    def _stop_reader(self) -> None:
        stop = getattr(self, "_stop", None)
        if stop is not None:
            stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _stopping(self) -> bool:
        return self._stop.is_set()

    @property
    def is_open(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _reader(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError
