"""The shared source machinery (SkinSourceBase) on a fake, clock-driven source: calibration,
latest values, total force, silent cells, recordings, buffering and link failures."""

from __future__ import annotations

import numpy as np
import pytest
from skin_helpers import frames, take

from aptkt.errors import SilentCellError, SkinDisconnectedError, SkinError, TrialFault
from aptkt.skin import (
    PatchConfig,
    SkinSource,
    SkinSourceBase,
    encode_packet,
    encode_sensor_packets,
    quantize,
)

MS = 1_000_000


class FakeClock:
    def __init__(self) -> None:
        self.t = 1_000 * MS

    def __call__(self) -> int:
        return self.t


class FakeSkin(SkinSourceBase):
    """A source driven by the test: bytes go in through _ingest_bytes at simulated times."""

    def open(self) -> None:
        self._mark_opened()

    def close(self) -> None:
        pass

    def push(self, data: bytes, dt_ms: float = 4.0) -> int:
        self._clock.t += int(dt_ms * MS)
        return self._ingest_bytes(data, self._clock.t)


PATCH = PatchConfig.from_mapping(
    {
        "patch": {
            "name": "three",
            "silence_timeout_s": 0.1,
            "force_offset": 0.25,
            "force_gain": 2.0,
        },
        "cell": [{"id": i, "position_mm": [i, 0, 0]} for i in (1, 2, 3)],
    }
)


@pytest.fixture
def skin() -> FakeSkin:
    s = FakeSkin(PATCH, clock=FakeClock(), buffer_rows=100)
    s.open()
    return s


def frame(force: float = 0.5, cells=(1, 2, 3)) -> bytes:
    n = len(cells)
    return encode_sensor_packets(
        quantize(list(cells), 0.1, [[0, 0, 1.0]] * n, [[30, 31]] * n, [[force] * 3] * n)
    )


def test_is_a_skin_source(skin):
    assert isinstance(skin, SkinSource)


def test_read_returns_calibrated_samples_with_arrival_times(skin):
    skin.push(frame(0.5))
    t1 = skin._clock.t
    skin.push(frame(0.75)[:50])  # a packet split across reads
    skin.push(frame(0.75)[50:])
    t3 = skin._clock.t
    s = skin.read()
    assert s.cell_id.tolist() == [1, 2, 3, 1, 2, 3]
    np.testing.assert_allclose(s.force[:3], 2.0 * (0.5 - 0.25))  # gain * (normalised - offset)
    np.testing.assert_allclose(s.force[3:], 2.0 * (0.75 - 0.25))
    # the split packet (cell 3 of the second frame) completed at the third read
    assert s.t_ns.tolist() == [t1, t1, t1, t3 - 4 * MS, t3 - 4 * MS, t3]
    assert len(skin.read()) == 0


def test_total_normal_force_and_latest(skin):
    with pytest.raises(SilentCellError, match=r"\[1, 2, 3\]"):
        skin.total_normal_force()  # nothing received yet: no answer rather than 0 N
    skin.push(frame(0.5))
    skin.push(frame(1.0, cells=(2,)))
    assert skin.total_normal_force() == pytest.approx(3 * 3 * 0.5 + 3 * (1.5 - 0.5))
    latest = skin.latest()
    assert latest["cell_id"].tolist() == [1, 2, 3]
    np.testing.assert_allclose(latest["force"][1], [1.5, 1.5, 1.5])
    np.testing.assert_allclose(latest["acc"], [[0, 0, 1]] * 3)
    skin._clock.t += 150 * MS  # everyone falls silent
    with pytest.raises(SilentCellError):
        skin.total_normal_force()
    assert skin.silent_cells() == (1, 2, 3)


def test_recording_window_and_silent_cell(skin):
    skin.push(frame())
    skin.start_recording({"action": "P1"})
    for k in range(50):
        skin.push(frame(cells=(1, 2) if k >= 20 else (1, 2, 3)))  # cell 3 stops after 80 ms
    rec = skin.stop_recording()
    assert rec.metadata["action"] == "P1" and rec.metadata["patch"] == "three"
    assert rec.cells == (1, 2, 3)
    assert rec.silent_cells == (3,)
    counts = {c: int((rec.samples.cell_id == c).sum()) for c in (1, 2, 3)}
    assert counts == {1: 50, 2: 50, 3: 20}  # cell 3 is not zero-filled
    assert rec.samples.t_ns.min() >= rec.start_ns and rec.samples.t_ns.max() <= rec.stop_ns
    with pytest.raises(TrialFault, match="SilentCellError") as info:
        skin.start_recording()
        skin.push(frame(cells=(1, 2)))
        skin.stop_recording(strict=True)
    assert isinstance(info.value.cause, SilentCellError)
    assert info.value.recording.samples.cell_id.tolist() == [1, 2]


def test_recording_errors(skin):
    with pytest.raises(SkinError, match="without start_recording"):
        skin.stop_recording()
    skin.start_recording()
    with pytest.raises(SkinError, match="already"):
        skin.start_recording()


def test_unknown_cells_are_counted_not_passed_on(skin):
    skin.push(frame(cells=(1, 42, 2, 42, 3)))
    assert skin.read().cell_id.tolist() == [1, 2, 3]
    assert skin.stats["unknown_cells"] == {42: 2}


def test_ring_overflow_drops_oldest_and_counts(skin):
    rng = np.random.default_rng(0)
    raw = frames(rng, [1, 2, 3], 50)  # 150 rows into a 100-row buffer
    skin.push(encode_sensor_packets(take(raw, slice(0, 90))))
    skin.push(encode_sensor_packets(take(raw, slice(90, 150))))
    s = skin.read()
    assert len(s) == 100 and skin.stats["overflows"] == 50
    np.testing.assert_array_equal(s.proximity, raw["proximity"][50:] / 65536)
    skin.push(encode_sensor_packets(raw))  # larger than the buffer in one go
    assert len(skin.read()) == 100 and skin.stats["overflows"] == 100


def test_stats_rates_and_link_health(skin):
    for _ in range(100):  # 100 frames at 4 ms = 250 Hz per cell
        skin.push(frame() + b"\x00\x01", dt_ms=4.0)
        skin.read()  # a consumer that keeps up: no overflow
    skin.push(encode_packet("ping"), dt_ms=0)
    st = skin.stats
    assert st["packets"] == 300 and st["bytes_skipped"] == 200
    assert st["other_packets"]["ping"] == 1
    assert st["packets_per_cell"] == {1: 100, 2: 100, 3: 100}
    for c in (1, 2, 3):
        assert st["rate_hz"][c] == pytest.approx(250, rel=0.05)
    assert st["silent_cells"] == () and st["link_error"] is None and st["overflows"] == 0


def test_link_failure_keeps_data_and_recording(skin):
    skin.start_recording()
    skin.push(frame())
    skin.push(frame()[:10])  # half a packet in flight
    assert skin.stats["pending_bytes"] == 10
    skin._fail(SkinDisconnectedError("gone"))
    assert skin.stats["link_error"] == "gone"
    assert len(skin.read()) == 3  # buffered data first …
    with pytest.raises(SkinDisconnectedError, match="gone"):
        skin.read()  # … then the error
    with pytest.raises(SkinDisconnectedError):
        skin.total_normal_force()
    rec = skin.stop_recording()
    assert len(rec.samples) == 3 and rec.metadata["link_error"] == "gone"
    assert skin.stats["pending_bytes"] == 0  # the half packet is not glued to later bytes
