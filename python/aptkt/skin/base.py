"""The interface every skin source implements (serial adapter, TSU over UDP, simulator)."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from aptkt.skin.samples import Recording, SkinSamples

__all__ = ["SkinSource"]


@runtime_checkable
class SkinSource(Protocol):
    """A running stream of parsed, calibrated skin samples.

    Sources are context managers: ``with SerialSkin(...) as skin: ...`` opens and closes the
    link. A recording window collects every sample that arrives between
    :meth:`start_recording` and :meth:`stop_recording`.
    """

    def open(self) -> None: ...

    def close(self) -> None: ...

    def __enter__(self) -> SkinSource: ...

    def __exit__(self, *exc: object) -> None: ...

    def read(self) -> SkinSamples:
        """Samples that arrived since the previous call (may be empty)."""
        ...

    def total_normal_force(self) -> float:
        """Sum over all cells of the latest calibrated normal forces, in newtons."""
        ...

    def start_recording(self, metadata: dict[str, Any] | None = None) -> None: ...

    def stop_recording(self) -> Recording: ...

    @property
    def stats(self) -> dict[str, Any]:
        """Link health: packets, bytes skipped, rejects by reason, overflows, rate per cell."""
        ...
