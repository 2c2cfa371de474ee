"""Simulated time for one placed object: the TCP trajectory, the physics state, and delivery of
sensor frames to whoever listens (the in-process skin, or a pty that a real SerialSkin reads).

Two drivers own the clock:

* :class:`FastDriver` — simulated time jumps: a 15 s hold costs only its computation. Motions
  that may be cut short (a guarded approach, a safety stop) are computed speculatively over a
  window, delivered tick by tick, and rolled back to the tick where they stopped; the physics is
  exact at sample times and its randomness is addressed by sample index, so the result is the
  same as stepping tick by tick.
* :class:`RealTimeDriver` — a thread advances simulated time with the wall clock and streams
  the bytes as the hardware would; robot motions wait in real time.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from aptkt._core import ForceControl, ForcePhase, LeanQueue
from aptkt.errors import InvalidStateError
from aptkt.sim.kinematics import Trajectory
from aptkt.sim.physics import ContactPhysics, ForceTrace, Frames, MechChunk

__all__ = ["FrameSink", "SimEngine", "Driver", "FastDriver", "RealTimeDriver", "StopReason"]

#: Samples of a lean force-control stretch after which its packets are made (the compiled
#: core's FLUSH_SAMPLES is the same number).
_FLUSH_SAMPLES = 2000
#: Speculation window of guarded moves (ns): short, because they stop early.
_GUARD_WINDOW_NS = 250_000_000


class FrameSink(Protocol):
    """Receives the frames that have arrived by now, in arrival order."""

    def deliver(self, frames: Frames) -> None: ...

    def wants_detail(self) -> bool:
        """True if every sample is wanted (recording, streaming); False: the newest per cell do."""
        ...


class StopReason:
    DONE = "done"
    PREDICATE = "predicate"
    WRENCH = "wrench"


class SimEngine:
    """Physics state + trajectory + undelivered frames of one placed object. Not thread-safe on
    its own; drivers serialise access with :attr:`lock`."""

    def __init__(
        self, physics: ContactPhysics, sink: FrameSink, start_position: np.ndarray, t0_ns: int = 0
    ):
        self.physics = physics
        self.sink = sink
        self.state = physics.initial_state(t0_ns, np.asarray(start_position, dtype=np.float64))
        self.trajectory = Trajectory.resting(t0_ns, start_position)
        self._pending = Frames.empty()
        self._lean: _Lean | None = None
        self.lock = threading.RLock()

    @property
    def now_ns(self) -> int:
        return self.state.t_ns

    def tcp(self) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity of the TCP now."""
        return self.trajectory.state_at(self.now_ns)

    def wrench(self) -> float:
        """True total normal force now (the robot's own force sensing, not the skin)."""
        return float(self.state.latest_force.sum())

    def _deliver_until(self, frames: Frames, t_ns: int) -> None:
        if len(frames):
            frames = _merge(self._pending, frames) if len(self._pending) else frames
        else:
            frames = self._pending
        cut = int(np.searchsorted(frames.t_ns, t_ns, side="right"))
        if cut:
            self.sink.deliver(frames.take(slice(0, cut)))
        self._pending = frames.take(slice(cut, None))

    def advance(self, t_ns: int, detail: bool | None = None) -> ForceTrace:
        """Move simulated time to ``t_ns`` and deliver what has arrived by then."""
        if t_ns <= self.now_ns:
            return ForceTrace.empty()
        want = self.sink.wants_detail() if detail is None else detail
        self.state, frames, trace = self.physics.step(
            self.state, self.trajectory, t_ns, detail=want
        )
        self._deliver_until(frames, t_ns)
        self.trajectory.forget_before(t_ns)
        return trace

    def run(
        self,
        t_end_ns: int,
        tick_ns: int,
        *,
        stop: Callable[[], bool] | None = None,
        wrench_limit: float | None = None,
        window_ns: int | None = None,
    ) -> tuple[int, str]:
        """Advance to ``t_end_ns`` checking every ``tick_ns``: ``stop()`` (which reads the skin, so
        frames are delivered tick by tick) and the true wrench against ``wrench_limit``. Returns
        the time reached and why it ended; after a stop the state is exactly that at the
        stopping tick."""
        if window_ns is None:  # guarded moves stop early: keep their speculation short
            window_ns = _GUARD_WINDOW_NS if stop is not None else 4_000_000_000
        while self.now_ns < t_end_ns:
            start = self.state
            w_end = min(t_end_ns, self.now_ns + window_ns)
            ticks = np.arange(self.now_ns + tick_ns, w_end + 1, tick_ns, dtype=np.int64)
            if ticks.size == 0 or ticks[-1] != w_end:
                ticks = np.append(ticks, np.int64(w_end))
            detail = stop is not None or self.sink.wants_detail()
            new, frames, trace = self.physics.step(
                start, self.trajectory, int(w_end), detail=detail
            )
            hit: tuple[int, str] | None = None
            if wrench_limit is not None:
                over = np.flatnonzero(trace.total_at(ticks, start.latest_force) > wrench_limit)
                if over.size:
                    hit = (int(over[0]), StopReason.WRENCH)
            if stop is None:
                if hit is None:
                    self.state = new
                    self._deliver_until(frames, int(w_end))
                    self.trajectory.forget_before(int(w_end))
                    continue
            else:
                last = hit[0] if hit is not None else ticks.size - 1
                delivered = 0
                for i in range(last + 1):
                    arrived = int(np.searchsorted(frames.t_ns, ticks[i], side="right"))
                    self._deliver_until(frames.take(slice(delivered, arrived)), int(ticks[i]))
                    delivered = arrived
                    if hit is not None and i == hit[0]:
                        break
                    try:
                        stopped = stop()
                    except BaseException:
                        # The reader failed (e.g. a silent cell): keep the state consistent with
                        # what was delivered, then let the robot handle the error.
                        self.state, rest, _ = self.physics.step(
                            start, self.trajectory, int(ticks[i]), detail=detail
                        )
                        self._pending = _merge(self._pending, rest.take(rest.t_ns > ticks[i]))
                        raise
                    if stopped:
                        hit = (i, StopReason.PREDICATE)
                        break
                if hit is None:
                    self.state = new
                    self._pending = _merge(self._pending, frames.take(slice(delivered, None)))
                    self.trajectory.forget_before(int(w_end))
                    continue
            # Cut the window at the stopping tick. Frames already delivered are exactly the ones
            # of the shorter step that arrived by then (same samples, same random numbers).
            t_hit = int(ticks[hit[0]])
            self.state, frames2, _ = self.physics.step(start, self.trajectory, t_hit, detail=detail)
            if stop is None:
                self._deliver_until(frames2, t_hit)
            else:
                self._pending = _merge(self._pending, frames2.take(frames2.t_ns > t_hit))
            return t_hit, hit[1]
        return self.now_ns, StopReason.DONE

    # ------------------------------------------------------------------ lean force control
    def lean_begin(
        self, calibration_gain: np.ndarray, calibration_offset: np.ndarray, latest_force: np.ndarray
    ) -> None:
        """Start a closed-loop stretch in which the controller reads the skin's total normal
        force every tick but the packets are computed once per window (:meth:`lean_flush`).

        The reading is computed exactly as the skin computes it — the packets' force fields,
        quantised to the wire's 12 bits, calibrated with the skin's calibration, newest packet
        per cell by arrival time — starting from the skin's ``latest_force`` (n_cells, 3, N).
        """
        if self._lean is not None:
            raise InvalidStateError("lean force control is already running")
        self._lean = _Lean(
            LeanQueue(
                np.ascontiguousarray(calibration_gain, dtype=np.float64),
                np.ascontiguousarray(calibration_offset, dtype=np.float64),
                np.ascontiguousarray(latest_force, dtype=np.float64),
            )
        )
        if len(self._pending):
            self._lean.queue.push(self._pending.t_ns, self._pending.cell_index, self._pending.force)

    def lean_advance(self, t_end_ns: int, wrench_limit: float | None = None) -> str:
        """Advance the mechanics to ``t_end_ns`` (one control tick) without making packets."""
        lean = self._lean
        assert lean is not None  # between lean_begin and lean_end
        chunk = self.physics.mechanics(self.state, self.trajectory, t_end_ns)
        if chunk.size:
            lean.chunks.append(chunk)
            lean.queue.samples += chunk.size
            arrival, force_norm = self.physics.force_readings(chunk)
            lean.queue.push(arrival, chunk.cells, force_norm)
        lean.queue.deliver(t_end_ns)  # the newest packet of each cell wins, as in the skin
        if lean.queue.samples > _FLUSH_SAMPLES:  # keep the window bounded; packets every ~1 s
            self.lean_flush()
            lean.queue.samples = 0
        self.trajectory.forget_before(self.now_ns)  # the chunks hold the motion they need
        # Each cell's newest sample is at or before the tick: the wrench now is their sum.
        if wrench_limit is not None and self.wrench() > wrench_limit:
            return StopReason.WRENCH
        return StopReason.DONE

    def lean_ticks(self, control: ForceControl, phase: ForcePhase) -> tuple[str, float]:
        """Run force-control ticks in the compiled core (``aptkt_sim::control``): the same
        admittance law, mechanics, packets' force fields and flushes as ticking through
        :meth:`lean_advance` from Python, one call per phase instead of one per tick.

        ``phase`` settles on the target force, ramps along a direction, or is a guarded move
        on the planned trajectory, ticked as :meth:`run` ticks it. Returns the status ("done",
        "timeout", "too_deep", "wrench", "triggered") and the force error of the last tick."""
        lean = self._lean
        if lean is None:
            raise InvalidStateError("lean_ticks needs a running lean force loop")
        st = self.state
        while True:
            # Force phases start from the segment in force; a guard follows the plan from it.
            i = max(int(np.searchsorted(self.trajectory.t0, st.t_ns, side="right")) - 1, 0)
            before = st.t_ns
            segments = self.trajectory.segments(i, None if phase.guarded else i + 1)
            out = self.physics.core.force_ticks(st, segments, lean.queue, control, phase)
            if out.chunk.size:
                lean.chunks.append(out.chunk)
            if st.t_ns != before and not phase.guarded:
                seg = out.segment
                self.trajectory.append(int(seg.t0[0]), seg.p0[0], seg.v0[0], seg.a[0])
            if lean.queue.samples > _FLUSH_SAMPLES:
                self.lean_flush()
                lean.queue.samples = 0
            self.trajectory.forget_before(st.t_ns)
            if out.status != "flush":
                return out.status, float(out.error)
            # The phase carries its progress (settled ticks, the current speculation window).

    def lean_reading(self) -> float:
        """The skin's total normal force as it reads now (same arithmetic as the skin source)."""
        assert self._lean is not None  # between lean_begin and lean_end
        return self._lean.queue.reading()

    def lean_flush(self) -> None:
        """Make the packets of the stretch so far and deliver those that have arrived."""
        lean = self._lean
        if lean is None or not lean.chunks:
            return
        chunk = MechChunk.concat(lean.chunks)
        lean.chunks = []
        frames, _ = self.physics.finish(self.state, chunk, detail=True)
        self._deliver_until(frames, self.now_ns)
        self.trajectory.forget_before(self.now_ns)

    def lean_end(self) -> None:
        self.lean_flush()
        self._lean = None


@dataclass
class _Lean:
    """A lean force loop's state: the skin's reading from the packets in flight, and the
    mechanics' samples whose packets are not made yet."""

    queue: LeanQueue
    chunks: list[MechChunk] = field(default_factory=list)


def _merge(a: Frames, b: Frames) -> Frames:
    if not len(a):
        return b
    if not len(b):
        return a
    merged = Frames(
        **{k: np.concatenate([getattr(a, k), getattr(b, k)]) for k in Frames.__dataclass_fields__}
    )
    return merged.take(np.argsort(merged.t_ns, kind="stable"))


class Driver(Protocol):
    """Owns the clock of a :class:`SimEngine` (simulated or real time)."""

    engine: SimEngine

    def now_ns(self) -> int: ...

    def run(
        self,
        t_end_ns: int,
        tick_ns: int,
        *,
        stop: Callable[[], bool] | None = None,
        wrench_limit: float | None = None,
    ) -> tuple[int, str]: ...

    def set_motion(self, t_ns: int, p0: np.ndarray, v0: np.ndarray, a: np.ndarray) -> None: ...

    def force_loop(
        self, lean: bool = True
    ) -> AbstractContextManager[Callable[[], float] | None]: ...


class FastDriver:
    """Simulated time that costs only its computation."""

    realtime = False

    def __init__(self, engine: SimEngine):
        self.engine = engine

    def now_ns(self) -> int:
        return self.engine.now_ns

    def set_motion(self, t_ns: int, p0: np.ndarray, v0: np.ndarray, a: np.ndarray) -> None:
        self.engine.trajectory.append(t_ns, p0, v0, a)

    def run(
        self,
        t_end_ns: int,
        tick_ns: int,
        *,
        stop: Callable[[], bool] | None = None,
        wrench_limit: float | None = None,
    ) -> tuple[int, str]:
        if self.engine._lean is not None:
            if stop is not None:
                raise InvalidStateError("a guarded move inside a force-control loop")
            why = self.engine.lean_advance(t_end_ns, wrench_limit)
            return self.engine.now_ns, why
        return self.engine.run(t_end_ns, tick_ns, stop=stop, wrench_limit=wrench_limit)

    def force_ticks(self, control: ForceControl, phase: ForcePhase) -> tuple[str, float]:
        """A whole phase of a lean force loop in the compiled core (see SimEngine.lean_ticks)."""
        return self.engine.lean_ticks(control, phase)

    def guarded_ticks(
        self, t_end_ns: int, threshold: float, tick_ns: int, wrench_limit: float
    ) -> str:
        """A guarded move on the planned trajectory inside a lean force loop, in the compiled
        core: the same ticks, stop and wrench checks as :meth:`run` with a stop predicate on the
        skin's reading. Returns the StopReason."""
        control = ForceControl(0.0, 0.0, 0.0, 0.0, 0.0, int(tick_ns), float(wrench_limit))
        phase = ForcePhase.guard(int(t_end_ns), float(threshold), _GUARD_WINDOW_NS)
        why, _ = self.engine.lean_ticks(control, phase)
        return {"triggered": StopReason.PREDICATE, "wrench": StopReason.WRENCH}.get(
            why, StopReason.DONE
        )

    @contextmanager
    def force_loop(self, lean: bool = True) -> Iterator[Callable[[], float] | None]:
        """A closed force loop. With ``lean`` the controller gets the skin's reading computed
        from the packets before they are made (identical arithmetic, see SimEngine.lean_begin):
        one light mechanics step per tick, packets once per window. Yields the reading function,
        or None when the controller must read the skin itself."""
        sink = self.engine.sink
        cal = getattr(sink, "calibration", None)
        latest = getattr(sink, "latest", None)
        if not lean or cal is None or latest is None:
            yield None
            return
        self.engine.lean_begin(cal.gain, cal.offset, latest()["force"])
        try:
            yield self.engine.lean_reading
        finally:
            self.engine.lean_end()

    def flush(self) -> None:
        if self.engine._lean is not None:
            self.engine.lean_flush()


class RealTimeDriver:
    """Simulated time locked to the wall clock: a thread advances the engine every ``period_s``."""

    realtime = True

    def __init__(self, engine: SimEngine, period_s: float = 0.004):
        self.engine = engine
        self.period_s = period_s
        self._t0_wall = time.monotonic_ns()
        self._t0_sim = engine.now_ns
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._loop, name="aptkt-sim-clock", daemon=True)
        self._thread.start()

    def _sim_time(self) -> int:
        return self._t0_sim + (time.monotonic_ns() - self._t0_wall)

    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                with self.engine.lock:
                    self.engine.advance(self._sim_time(), detail=True)
                time.sleep(self.period_s)
        except BaseException as exc:  # surfaced to the robot thread by run()
            self._error = exc

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def force_loop(self, lean: bool = True):  # noqa: ARG002 - same signature as FastDriver's
        """Real time: the controller reads the skin itself."""
        return nullcontext(None)

    def flush(self) -> None:
        pass

    def now_ns(self) -> int:
        with self.engine.lock:
            return self.engine.now_ns

    def set_motion(self, t_ns: int, p0: np.ndarray, v0: np.ndarray, a: np.ndarray) -> None:
        with self.engine.lock:
            self.engine.trajectory.append(max(t_ns, self.engine.now_ns), p0, v0, a)

    def run(
        self,
        t_end_ns: int,
        tick_ns: int,
        *,
        stop: Callable[[], bool] | None = None,
        wrench_limit: float | None = None,
    ) -> tuple[int, str]:
        next_tick = self.now_ns() + tick_ns
        while True:
            if self._error is not None:
                raise InvalidStateError("simulation clock thread failed") from self._error
            now = self.now_ns()
            if now >= min(next_tick, t_end_ns):
                if wrench_limit is not None and self.engine.wrench() > wrench_limit:
                    return now, StopReason.WRENCH
                if stop is not None and stop():
                    return now, StopReason.PREDICATE
                if now >= t_end_ns:
                    return now, StopReason.DONE
                next_tick = now + tick_ns
            time.sleep(max(0.0, min(next_tick, t_end_ns) - now) * 1e-9)
