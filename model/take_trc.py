"""TRC reader (the OpenSim / Motion Analysis tab-separated marker trajectory format).

Layout: ``PathFileType`` line; a line of header keys (DataRate, CameraRate, NumFrames, NumMarkers, Units,
...) and a line of their values; ``Frame#  Time  name1 <tab><tab> name2 ...``; ``X1 Y1 Z1 X2 ...``; then one
row per frame: frame number, time, then X, Y, Z per marker. Empty cells and NaN in any spelling (``nan``,
``NAN``, ``  NaN``) are missing samples and read as NaN.

Real files vary: spaces around values, CRLF line endings, blank lines, an extra tab before the first name,
e-notation, trailing tabs, and a header whose NumFrames (or NumMarkers) is not what the file holds. The rows
and the name line decide; a header that disagrees with them is reported in ``MarkerTake.warnings``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import RigInputError, shown
from .take_data import MarkerTake, check_row_cells, text_table, unique_labels, units_from_text


def _cells(line: str) -> list[str]:
    """Tab-separated cells, stripped; a line without tabs is split on runs of spaces."""
    line = line.rstrip("\r\n")
    return [c.strip() for c in line.split("\t")] if "\t" in line else line.split()


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
    warnings: list[str] = []
    header = {k: v for k, v in zip(_cells(lines[1]), _cells(lines[2])) if k}
    units = units_from_text(header.get("Units", ""))
    if units is None:
        raise RigInputError(f"{path}: unknown units '{shown(header.get('Units', ''), 20)}' (use mm, cm or m).")

    def number(key: str, kind=float):
        try:
            return kind(float(header[key])) if header.get(key) else None
        except (ValueError, OverflowError):
            raise RigInputError(f"{path}: the header's {key} is not a usable number: "
                                f"'{shown(header[key], 30)}'.") from None

    rate = number("DataRate") or number("CameraRate")
    if rate is None or not rate > 0:
        raise RigInputError(f"{path}: the header gives no positive DataRate or CameraRate.")
    declared_markers, declared_frames = number("NumMarkers", int), number("NumFrames", int)
    names_row = _cells(lines[3])
    if len(names_row) < 2 or names_row[0] not in ("Frame#", "Frame"):
        raise RigInputError(f"{path}: the fourth line must be 'Frame#, Time, marker names'.")
    labels = [s for s in names_row[2:] if s]
    M = len(labels)
    if M == 0:
        raise RigInputError(f"{path}: names no markers.")
    coords = [s for s in _cells(lines[4]) if s]
    if len(coords) != 3 * M:
        raise RigInputError(f"{path}: {M} markers need {3 * M} X/Y/Z columns but the header has {len(coords)}.")
    if declared_markers is not None and declared_markers != M:
        warnings.append(f"{path}: the header declares {declared_markers} markers but names {M}; read the {M} named.")
    labels, renamed = unique_labels(labels, str(path))
    if renamed:
        warnings.append(renamed)

    rows = [(n + 6, _cells(line)) for n, line in enumerate(lines[5:]) if line.strip()]
    if not rows:
        raise RigInputError(f"{path}: holds no frames.")
    ncol = 2 + 3 * M
    check_row_cells(path, rows, ncol, M)
    for line_no, r in rows:
        if len(r) > ncol and any(r[ncol:]):
            raise RigInputError(f"{path}: line {line_no} has {len(r)} columns, more than the {ncol} in the header.")
    table = text_table(path, rows, list(range(ncol)))
    if declared_frames is not None and declared_frames != len(rows):
        warnings.append(f"{path}: the header declares {declared_frames} frames but the file holds {len(rows)}; "
                        f"read the {len(rows)}.")
    pos = table[:, 2:].reshape(len(rows), M, 3)
    pos[~np.isfinite(pos).all(axis=2)] = np.nan
    first = int(table[0, 0]) if np.isfinite(table[0, 0]) else 1
    return MarkerTake(positions=pos, labels=labels, rate=rate, units=units, source=str(path),
                      first_frame=first, warnings=warnings)
