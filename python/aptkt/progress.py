"""Progress of long work: a bar on a terminal, plain lines where output goes to a log.

A redirected run would otherwise show its first line and nothing until it ends; here it writes
a line when another tenth of the work is done or half a minute has passed since the last line,
with the time spent and an estimate of the time left. Every long command reports through this
one class, so that a log shows the same lines whichever command wrote it."""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import Any, TextIO

__all__ = ["Progress"]

#: Seconds between two lines at most, and the share of the work between two lines at most.
LINE_EVERY_SECONDS = 30.0
LINE_EVERY_SHARE = 0.1
#: Seconds between two lines at least: work done in a moment needs no account of itself.
LINE_AFTER_SECONDS = 2.0


class Progress:
    """Counts ``total`` units of work (``update``), shown on ``stream`` (standard error by
    default): a tqdm bar when it is a terminal, lines otherwise; nothing with ``enabled=False``."""

    def __init__(
        self,
        total: int,
        unit: str,
        desc: str,
        *,
        stream: TextIO | None = None,
        enabled: bool = True,
        initial: int = 0,
    ) -> None:
        self.total = max(int(total), 1)
        self.unit, self.desc = unit, desc
        self.stream = sys.stderr if stream is None else stream
        # Work done before this run (a resumed data set) counts as done but not in the rate.
        self.done = self._last_done = self._initial = int(initial)
        self._start = self._last_time = time.monotonic()
        self._note = ""
        self._bar: Any = None
        self.enabled = enabled
        if enabled and _is_terminal(self.stream):
            from tqdm import tqdm

            self._bar = tqdm(
                total=self.total,
                initial=self._initial,
                unit=unit,
                desc=desc,
                leave=False,
                file=self.stream,
                smoothing=0.05,
            )

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def note(self, text: str) -> None:
        """What is being worked on (``rough_sponge P1 trial 3``): beside the bar, or at the end
        of the next line."""
        self._note = text
        if self._bar is not None:
            self._bar.set_postfix_str(text, refresh=False)

    def clear(self) -> None:
        """Clear the bar before other output goes to the same terminal; lines need nothing."""
        if self._bar is not None:
            self._bar.clear()

    def update(self, n: int = 1) -> None:
        self.done += n
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
            return
        now = time.monotonic()
        share = (self.done - self._last_done) / self.total
        since = now - self._last_time
        if since >= LINE_EVERY_SECONDS or (
            since >= LINE_AFTER_SECONDS and (self.done >= self.total or share >= LINE_EVERY_SHARE)
        ):
            self._last_time, self._last_done = now, self.done
            print(self.line(now - self._start), file=self.stream, flush=True)

    def line(self, elapsed: float) -> str:
        """``benchmark: 12/60 groups (20 %), 1 min 3 s, about 4 min 12 s left``."""
        text = (
            f"{self.desc}: {self.done}/{self.total} {self.unit}s "
            f"({100 * self.done / self.total:.0f} %), {_duration(elapsed)}"
        )
        done_now = self.done - self._initial
        if 0 < done_now and self.done < self.total:
            left = elapsed * (self.total - self.done) / done_now
            text += f", about {_duration(left)} left"
        if self._note:
            text += f" ({self._note})"
        return text

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def _is_terminal(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _duration(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    minutes, s = divmod(seconds, 60)
    hours, m = divmod(minutes, 60)
    if hours:
        return f"{hours} h {m} min"
    return f"{m} min {s} s" if m else f"{s} s"
