"""TRC reader (the OpenSim / Motion Analysis tab-separated marker trajectory format).

Layout: ``PathFileType`` line; a line of header keys (DataRate, CameraRate, NumFrames, NumMarkers, Units,
...) and a line of their values; ``Frame#  Time  name1 <tab><tab> name2 ...``; ``X1 Y1 Z1 X2 ...``; then one
row per frame. Empty cells are missing samples and read as NaN.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import RigInputError
from .takes import MarkerTake

_UNITS = {"mm": "mm", "cm": "cm", "m": "m", "millimeters": "mm", "centimeters": "cm", "meters": "m"}


def read_trc(path: str | Path) -> MarkerTake:
    """Read a TRC file into a MarkerTake (positions in the file's units, NaN for empty cells)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror}).") from None
    lines = text.splitlines()
    if not any(line.strip() for line in lines):
        raise RigInputError(f"{path}: the file is empty.")
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise RigInputError(f"{path}: is not a TRC file (it must start with a PathFileType line and four header lines).")
    keys = lines[1].rstrip("\r\n").split("\t")
    vals = lines[2].rstrip("\r\n").split("\t")
    header = {k.strip(): v.strip() for k, v in zip(keys, vals)}
    units_raw = header.get("Units", "").lower()
    if units_raw not in _UNITS:
        raise RigInputError(f"{path}: unknown units '{header.get('Units', '')}' (use mm, cm or m).")
    try:
        rate = float(header.get("DataRate") or header.get("CameraRate") or "nan")
        declared_markers = int(header["NumMarkers"]) if "NumMarkers" in header else None
        declared_frames = int(header["NumFrames"]) if "NumFrames" in header else None
    except ValueError:
        raise RigInputError(f"{path}: the TRC header has a non-numeric DataRate, NumFrames or NumMarkers.") from None
    names_row = lines[3].rstrip("\r\n").split("\t")
    if len(names_row) < 2 or names_row[0].strip() not in ("Frame#", "Frame"):
        raise RigInputError(f"{path}: the fourth line must be 'Frame#, Time, marker names'.")
    labels = [s.strip() for s in names_row[2:] if s.strip()]
    coord_row = [s.strip() for s in lines[4].rstrip("\r\n").split("\t")[2:] if s.strip()]
    M = len(labels)
    if M == 0:
        raise RigInputError(f"{path}: names no markers.")
    if declared_markers is not None and declared_markers != M:
        raise RigInputError(f"{path}: the header declares {declared_markers} markers but names {M}.")
    if len(coord_row) != 3 * M:
        raise RigInputError(f"{path}: {M} markers need {3 * M} X/Y/Z columns but the header has {len(coord_row)}.")
    rows = [line.rstrip("\r\n").split("\t") for line in lines[5:] if line.strip()]
    if not rows:
        raise RigInputError(f"{path}: holds no frames.")
    ncol = 2 + 3 * M
    table = np.full((len(rows), ncol), np.nan)
    for i, r in enumerate(rows):
        if len(r) > ncol and any(c.strip() for c in r[ncol:]):
            raise RigInputError(f"{path}: frame row {i + 1} has {len(r)} columns, more than the {ncol} in the header.")
        try:
            table[i, :min(len(r), ncol)] = [float(c) if c.strip() else np.nan for c in r[:ncol]]
        except ValueError:
            raise RigInputError(f"{path}: frame row {i + 1} has a cell that is not a number.") from None
    if declared_frames is not None and declared_frames != len(rows):
        raise RigInputError(f"{path}: the header declares {declared_frames} frames but the file has {len(rows)}.")
    pos = table[:, 2:].reshape(len(rows), M, 3)
    pos[~np.isfinite(pos).all(axis=2)] = np.nan
    first = int(table[0, 0]) if np.isfinite(table[0, 0]) else 1
    return MarkerTake(positions=pos, labels=labels, rate=rate, units=_UNITS[units_raw], source=str(path),
                      first_frame=first)
