"""The RTDE input watchdog (URScript ``rtde_set_watchdog``): an input variable the client
must keep writing at a minimum frequency, or the controller ignores, pauses or stops."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Watchdog"]


@dataclass
class Watchdog:
    variable: str
    min_frequency: float
    action: str  # "ignore" | "pause" | "stop"
    last_update: float  # time.monotonic() of the variable's last write

    def expired(self, now: float) -> str | None:
        """The controller's message when the variable has not been written for longer than
        the period allowed (None: in time, or the watchdog is off)."""
        if self.min_frequency <= 0 or now - self.last_update <= 1.0 / self.min_frequency:
            return None
        return (
            f"RTDE input watchdog: no update of {self.variable} for "
            f"{1.0 / self.min_frequency:.3f} s"
        )

    def describe(self) -> dict[str, object]:
        return {
            "variable": self.variable,
            "min_frequency": self.min_frequency,
            "action": self.action,
        }
