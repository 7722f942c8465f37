"""Counts in the user's words: "1 region", "3 regions" (never "1 region(s)")."""
from __future__ import annotations


def count(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, plural unless n is 1, thousands separated: count(1, "region") -> "1 region"."""
    n = int(n)
    return f"{n:,} {noun if n == 1 else (plural or noun + 's')}"
