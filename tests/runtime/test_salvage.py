"""The one salvage rule for a failed trial (shared by ``aptkt collect`` and ``aptkt learn``)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from aptkt.data import DatasetReader, DatasetWriter
from aptkt.errors import ProtectiveStopError, SkinDisconnectedError, TrialFault, TrialInterrupted
from aptkt.runtime.salvage import aborted_path, salvage
from aptkt.sim import SimWorld


@pytest.fixture(scope="module")
def recording():
    return SimWorld(seed=0).explore("towel", "P1", 0)


def copy(rec):
    return replace(rec, metadata=dict(rec.metadata))


def keys(path: Path) -> list:
    if not path.exists():
        return []
    with DatasetReader(path) as rd:
        return rd.keys()


def test_a_complete_recording_stays_in_the_data_set_with_the_fault_noted(tmp_path, recording):
    path = tmp_path / "data.h5"
    cause = SkinDisconnectedError("unplugged while lifting")
    with DatasetWriter(path, "w") as writer:
        kept = salvage(TrialFault(cause, copy(recording), complete=True), writer, path)
    assert kept.cause is cause and kept.saved == path and "complete" in kept.what
    assert keys(path) == [("towel", "P1", 0)] and keys(aborted_path(path)) == []
    with DatasetReader(path) as rd:
        rec = rd.recording(0)
    assert rec.metadata["fault_after_recording"] == "SkinDisconnectedError: unplugged while lifting"


def test_a_partial_recording_goes_to_the_side_file_flagged_aborted(tmp_path, recording):
    path = tmp_path / "data.h5"
    cause = ProtectiveStopError("mid-press")
    with DatasetWriter(path, "w") as writer:
        kept = salvage(TrialFault(cause, copy(recording)), writer, path)
        again = salvage(TrialInterrupted(KeyboardInterrupt(), copy(recording)), writer, path)
    assert keys(path) == []
    assert kept.saved == aborted_path(path) and "flagged 'aborted'" in kept.what
    assert again.saved == aborted_path(path, 2)  # the same trial again: the next side file
    with DatasetReader(kept.saved) as rd:
        rec = rd.recording(0)
    assert rec.metadata["aborted"] == "ProtectiveStopError: mid-press"
    assert rec.metadata["error_type"] == "ProtectiveStopError"
    with DatasetReader(again.saved) as rd:
        assert rd.recording(0).metadata["error_type"] == "KeyboardInterrupt"


def test_a_fault_before_the_recording_keeps_nothing(tmp_path):
    path = tmp_path / "data.h5"
    cause = ProtectiveStopError("during the approach")
    with DatasetWriter(path, "w") as writer:
        kept = salvage(cause, writer, path)
    assert kept.cause is cause and kept.saved is None
    assert kept.what == "nothing was being recorded" and keys(path) == []
