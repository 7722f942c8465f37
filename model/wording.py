"""Counts and durations in the user's words: "1 region", "3 regions" (never "1 region(s)"); "166 ms", "14.5 s"."""
from __future__ import annotations


def count(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, plural unless n is 1, thousands separated: count(1, "region") -> "1 region"."""
    n = int(n)
    return f"{n:,} {noun if n == 1 else (plural or noun + 's')}"


def duration(seconds: float) -> str:
    """A time a computation took: milliseconds under a second ("166 ms"), else seconds ("14.5 s")."""
    seconds = float(seconds)
    return f"{seconds * 1000:.0f} ms" if seconds < 0.9995 else f"{seconds:.1f} s"
