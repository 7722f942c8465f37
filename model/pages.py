"""Ordinary memory pages for work that writes large arrays once.

numpy asks Linux for transparent huge pages (``madvise``) for every array of 4 MB or more. Where the kernel has free
2 MB blocks at hand that saves a little (one fault per 2 MB instead of 512). Where it must compact memory first to
find them (THP defrag ``madvise``, a common default), or where the machine is a VM whose host backs the guest's
memory lazily, each huge page's first touch costs milliseconds instead:
- on the eighteenth session's VM a segmentation of ICT took 82–228 ms (median 124, 72 ms of it in the kernel) with
  them against 72–123 ms (median 92, 19 ms) without, and the 106k-vertex rig 1.0–2.4 s against 0.41–0.52 s;
- on the nineteenth's, touching 2.15 GB of new memory took 7.5 s with them against 0.9 s without, and reading the
  422k-vertex, 228-shape studio project (2.15 GiB of deltas) 10.4–19.7 s against 5.7–6.0 s.
Where compaction was cheap they had saved little (another VM: the 106k rig's segmentation 0.39 s without, 0.29 s
with; ICT 78 / 73 ms). So what writes large arrays once and then streams through them (a segmentation, reading a
studio-scale rig, a display evaluator's copy of its deltas) asks for ordinary pages while it runs. The command line
asks numpy for them for its whole run (``app.launch``: ``NUMPY_MADVISE_HUGEPAGE=0``); the window keeps numpy's
setting for the rest, where ICT-sized arrays gain a little from huge pages (its load: 207-212 ms with them against
230-273 ms without on the nineteenth session's VM).
"""
from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np

LARGE = 256 << 20
"""Bytes of arrays from which a load or a display evaluator asks for ordinary pages (``small_pages_for``):
a studio-scale rig's (106k vertices x 228 shapes: 0.54 GiB of deltas), not ICT's (37 MB). Arrays this large always
get a mapping of their own, made with the advice asked for then: glibc serves only smaller ones from its heap's free
room (at most ~64 MB before it trims), whose pages keep whatever advice an earlier array there was given."""

_LOCK = threading.Lock()
_STATE = [0, None]   # runs asking for ordinary pages now, numpy's setting before the first of them


def _toggle():
    core = getattr(np, "_core", None) or getattr(np, "core", None)  # numpy 2 / numpy 1
    return getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)


@contextmanager
def small_pages(when: bool = True):
    """numpy's large arrays made inside the block get ordinary pages (as ``NUMPY_MADVISE_HUGEPAGE=0`` would for
    the whole process); numpy's setting comes back when the last overlapping block (in any thread) ends. An array
    keeps the pages it was made with. ``when`` False: nothing changes."""
    toggle = _toggle() if when else None
    if toggle is None:
        yield
        return
    with _LOCK:
        before = toggle(False)   # off on every entry: whatever set it on meanwhile, this block gets ordinary pages
        if _STATE[0] == 0:
            _STATE[1] = before
        _STATE[0] += 1
    try:
        yield
    finally:
        with _LOCK:
            _STATE[0] -= 1
            if _STATE[0] == 0:
                toggle(_STATE[1])


def small_pages_for(nbytes: int):
    """``small_pages`` for work that makes ``nbytes`` of arrays: ordinary pages from ``LARGE`` on, numpy's own
    setting below it."""
    return small_pages(nbytes >= LARGE)


def active() -> int:
    """How many ``small_pages`` blocks are running now, in all threads (numpy's setting comes back when none is)."""
    with _LOCK:
        return _STATE[0]


def available_memory() -> int | None:
    """Bytes of memory the system can give now without swapping (Linux's ``MemAvailable``), None where unknown."""
    try:
        with open("/proc/meminfo", "rb") as f:
            for line in f:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def memory_shortfall(nbytes: int) -> str | None:
    """Why ``nbytes`` cannot be allocated now (the words after "needs"/"need": "5.7 GB of memory, more than the
    3.1 GB available"), or None when it can or the memory available is unknown. For a reader to refuse, in one
    sentence and before allocating, a small file that unfolds into arrays larger than the machine holds (a glTF
    whose morph targets all share one accessor, a project member that deflates to gigabytes): allocated, Linux
    hands out the pages lazily and kills the process as they fill (the window, and what the user had open, with it),
    or numpy raises MemoryError part way."""
    free = available_memory()
    if free is None or nbytes <= free:
        return None
    return f"{_amount(nbytes)} of memory, more than the {_amount(free)} available"


def _amount(nbytes: int) -> str:
    return f"{nbytes / 1e9:.1f} GB" if nbytes >= 1e9 else f"{nbytes / 1e6:.0f} MB"
