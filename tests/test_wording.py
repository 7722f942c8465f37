"""The user's words for counts and durations (status lines, the command line)."""
from __future__ import annotations

from model.wording import count, duration


def test_counts_are_singular_for_one_and_separate_thousands():
    assert count(1, "region") == "1 region"
    assert count(0, "region") == "0 regions"
    assert count(12345, "vertex", "vertices") == "12,345 vertices"


def test_durations_in_milliseconds_under_a_second_and_in_seconds_from_one():
    assert duration(0.1664) == "166 ms"
    assert duration(0.9994) == "999 ms"
    assert duration(0.9996) == "1.0 s"        # never "1000 ms"
    assert duration(14.473) == "14.5 s"       # a studio rig's segmentation, not "14473 ms"
