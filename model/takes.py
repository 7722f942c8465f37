"""Takes: marker trajectories (C3D, TRC, CSV) and weight takes (Live Link Face CSV, weights CSV).

A ``MarkerTake`` holds positions (F, M, 3) float64 with NaN where a marker is missing, its labels,
frame rate and units. A ``WeightTake`` holds per-frame weights (F, K) for named shapes.
``load_take(path)`` picks the reader from the file's extension (and, for CSV, its header).

Both carry ``warnings``: one sentence each about what a reader had to decide for a file that bends its
format (labels renamed, a short file read to its last whole frame, units guessed); ``take-info`` prints
them, and any caller can show them beside the take.
"""
from __future__ import annotations

from pathlib import Path

from .errors import RigInputError
from .input_files import regular_file
from .take_data import MarkerTake, WeightTake, rate_not_used, take_summary, unique_labels, units_from_text

TAKE_SUFFIXES = (".c3d", ".trc", ".csv")   # the files a folder of takes holds (``batch``'s TAKES)

__all__ = ["MarkerTake", "TAKE_SUFFIXES", "WeightTake", "load_take", "take_summary", "unique_labels",
           "units_from_text"]


def load_take(path: str | Path, *, rate: float | None = None, **kwargs) -> MarkerTake | WeightTake:
    """Open a take: ``.c3d``, ``.trc``, or ``.csv`` (marker trajectories, a Live Link Face recording, or a weights CSV
    read on its own columns: ``model.take_workspace.read_take`` reads one onto a rig's shapes). ``rate``: the frame
    rate of a take whose file gives none (a weights CSV without times, a plain marker CSV), checked by
    ``model.take_data.given_rate``; a file with its own rate keeps it, with a warning when the two differ."""
    take = _load_take(path, rate, **kwargs)
    take.warnings += rate_not_used(take.source or path, take.rate, rate)
    return take


def _load_take(path, rate, **kwargs) -> MarkerTake | WeightTake:
    path = regular_file(path)   # a missing file, a folder, a FIFO or a device: one sentence, nothing read
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        from .take_c3d import read_c3d
        return read_c3d(path)
    if suffix == ".trc":
        from .take_trc import read_trc
        return read_trc(path, **kwargs)
    if suffix == ".csv":
        from .livelink import is_livelink_csv, read_livelink_csv
        if is_livelink_csv(path):
            return read_livelink_csv(path, **kwargs)
        from .weights_csv import is_weights_csv, read_weights_take
        if is_weights_csv(path):       # frame,time,<shapes> as solve writes, or frame,<shapes>: on its own columns
            return read_weights_take(path, None, rate=rate)
        from .take_csv import read_marker_csv
        return read_marker_csv(path, **({"rate": rate} if rate is not None else {}), **kwargs)
    raise RigInputError(f"{path}: unknown take format '{path.suffix}'; open a .c3d, .trc or .csv file.")
