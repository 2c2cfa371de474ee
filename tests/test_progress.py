"""Progress where output is not a terminal: lines with the time spent and the time left, often
enough to see that work goes on, rarely enough not to flood a log."""

from __future__ import annotations

import io

import pytest

from aptkt import progress as progress_module
from aptkt.progress import Progress


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch):
    c = Clock()
    monkeypatch.setattr(progress_module.time, "monotonic", c)
    return c


def test_a_line_per_tenth_of_the_work_with_the_time_left(clock):
    out = io.StringIO()
    bar = Progress(100, "group", "benchmark", stream=out)
    for _ in range(100):
        clock.now += 1.0
        bar.update()
    lines = out.getvalue().splitlines()
    assert len(lines) == 10
    assert lines[0] == "benchmark: 10/100 groups (10 %), 10 s, about 1 min 30 s left"
    assert lines[-1] == "benchmark: 100/100 groups (100 %), 1 min 40 s"


def test_a_line_after_half_a_minute_even_when_work_is_slow(clock):
    out = io.StringIO()
    bar = Progress(1000, "trial", "data.h5", stream=out)
    clock.now += 31
    bar.update()
    assert out.getvalue() == "data.h5: 1/1000 trials (0 %), 31 s, about 8 h 36 min left\n"


def test_resumed_work_counts_as_done_but_not_in_the_rate(clock):
    out = io.StringIO()
    bar = Progress(100, "trial", "data.h5", stream=out, initial=50)
    bar.note("rough_sponge P1")
    clock.now += 10
    for _ in range(10):
        bar.update()
    assert out.getvalue() == (
        "data.h5: 60/100 trials (60 %), 10 s, about 40 s left (rough_sponge P1)\n"
    )


def test_quick_work_writes_nothing(clock):
    out = io.StringIO()
    bar = Progress(6, "recording", "features d.h5", stream=out)
    for _ in range(6):
        clock.now += 0.1
        bar.update()
    assert out.getvalue() == ""


def test_disabled_writes_nothing_and_a_context_closes_it(clock):
    out = io.StringIO()
    with Progress(3, "run", "learning", stream=out, enabled=False) as bar:
        bar.update(3)
    assert out.getvalue() == "" and bar.done == 3


def test_a_terminal_gets_a_bar_not_lines(clock):
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    out = Terminal()
    with Progress(10, "run", "learning", stream=out) as bar:
        bar.update(10)
    assert "learning" in out.getvalue() and "about" not in out.getvalue()


def test_generation_lines_name_the_recording_just_counted(tmp_path, monkeypatch, capsys):
    """Each progress line of a simulated data set names the recording it has just counted
    (the note came one recording late, and a bar could show one object for most of a run)."""
    import itertools
    import re

    from aptkt.actions import PAPER_ACTIONS
    from aptkt.data import DatasetReader
    from aptkt.runtime.generation import GenerationPlan, generate

    ticks = itertools.count(0.0, 40.0)  # every update at least LINE_EVERY_SECONDS later
    monkeypatch.setattr(progress_module.time, "monotonic", lambda: next(ticks))
    plan = GenerationPlan(("towel", "metal_toolbox"), (PAPER_ACTIONS["P1"],), repetitions=2, seed=2)
    path = tmp_path / "d.h5"
    generate(path, plan, jobs=1, progress=True)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("d.h5:")]
    assert len(lines) == 4
    with DatasetReader(path) as rd:
        for line in lines:
            done, note = re.fullmatch(r"d\.h5: (\d+)/4 trials .*\(done: (.+)\)", line).groups()
            assert note == "{} {} trial {}".format(*rd.key(int(done) - 1)), line
