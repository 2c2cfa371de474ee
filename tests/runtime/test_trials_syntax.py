"""``--trials``: one syntax of trial numbers and ranges for every command that reads a table or
a data set, written back as it is read."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aptkt.commands._inputs import parse_trials, trials_of
from aptkt.errors import ConfigError


def _numbers(text: str) -> set[int]:
    chosen = parse_trials(text)
    assert chosen is not None
    return {t for a, b in chosen.ranges for t in range(a, b + 1)}


@pytest.mark.parametrize(
    ("text", "numbers"),
    [
        ("3", {3}),
        ("25-49", set(range(25, 50))),
        ("0-9,20-29", set(range(10)) | set(range(20, 30))),
        (" 7 , 1-2 ", {1, 2, 7}),
        ("4-4", {4}),
        ("0-5,3-8", set(range(9))),
        ("0:25", set(range(25))),  # prior build's earlier spelling: STOP not included
        ("0:2,5", {0, 1, 5}),
    ],
)
def test_the_syntax(text, numbers):
    assert _numbers(text) == numbers


@given(st.sets(st.integers(min_value=0, max_value=300), min_size=1))
def test_any_set_written_as_ranges_reads_back(numbers):
    text = str(trials_of(numbers))
    assert _numbers(text) == numbers
    assert str(parse_trials(text)) == text  # the written form is the canonical one


@given(
    st.sets(st.integers(min_value=0, max_value=60), min_size=1),
    st.sets(st.integers(min_value=0, max_value=60)),
)
def test_missing_is_the_difference(chosen, available):
    missing = trials_of(chosen).missing(available)
    assert {t for a, b in missing.ranges for t in range(a, b + 1)} == chosen - available


def test_a_range_is_not_spelt_out():
    chosen = parse_trials("0-2000000000")
    assert chosen is not None and 1_999_999_999 in chosen and 2_000_000_001 not in chosen


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "give trial numbers and ranges"),
        (" , ", "give trial numbers and ranges"),
        ("a", "'a' is not a trial number or a range"),
        ("1-", "'1-' is not a trial number or a range"),
        ("1-2-3", "'1-2-3' is not"),
        ("1.5", "'1.5' is not"),
        ("-1", "'-1' is not"),
        ("9-2", "the range 9-2 runs backwards (write 2-9)"),
        ("3:3", "3:3 holds no trial"),
        ("0-3000000000", "trial numbers stop at 2147483647"),
    ],
)
def test_mistakes(text, fragment):
    with pytest.raises(ConfigError, match=None) as caught:
        parse_trials(text)
    message = str(caught.value)
    assert message.startswith("--trials") and "\n" not in message and fragment in message, message
