"""Progress of long work: a bar on a terminal, plain lines where output goes to a log.

A redirected run would otherwise show its first line and nothing until it ends; here it writes
a line when another tenth of the work is done or half a minute has passed since the last line,
with the time spent and an estimate of the time left."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

__all__ = ["Progress"]

#: Seconds between two lines at most, and the share of the work between two lines at most.
LINE_EVERY_SECONDS = 30.0
LINE_EVERY_SHARE = 0.1


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
    ) -> None:
        self.total = max(int(total), 1)
        self.unit, self.desc = unit, desc
        self.stream = sys.stderr if stream is None else stream
        self.done = 0
        self._start = self._last_time = time.monotonic()
        self._last_done = 0
        self._bar: Any = None
        self.enabled = enabled
        if enabled and _is_terminal(self.stream):
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, unit=unit, desc=desc, leave=False, file=self.stream)

    def update(self, n: int = 1) -> None:
        self.done += n
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
            return
        now = time.monotonic()
        share = (self.done - self._last_done) / self.total
        if (
            self.done >= self.total
            or share >= LINE_EVERY_SHARE
            or now - self._last_time >= LINE_EVERY_SECONDS
        ):
            self._last_time, self._last_done = now, self.done
            print(self.line(now - self._start), file=self.stream, flush=True)

    def line(self, elapsed: float) -> str:
        """``benchmark: 12/60 groups (20 %), 1 min 3 s, about 4 min 12 s left``."""
        text = (
            f"{self.desc}: {self.done}/{self.total} {self.unit}s "
            f"({100 * self.done / self.total:.0f} %), {_duration(elapsed)}"
        )
        if 0 < self.done < self.total:
            text += f", about {_duration(elapsed * (self.total - self.done) / self.done)} left"
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
