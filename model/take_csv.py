"""Marker trajectories in CSV: three layouts, told apart by their first rows.

- Plain: ``frame, A_X, A_Y, A_Z, B_X, ...``. Units and frame rate are not in the file; pass them (without a rate it is read at ``PLAIN_RATE``, with a warning naming ``--rate``).
- Vicon Nexus export, its ``Trajectories`` section::

      Trajectories
      100                                    (frame rate)
      ,,Subject:LASI,,,Subject:RASI,,,
      Frame,Sub Frame,X,Y,Z,X,Y,Z
      ,,mm,mm,mm,mm,mm,mm
      1,0,-391.9,-6180.0,1734.4,...

  (also this application's own export, ``write_marker_csv``; other sections, such as Devices or Model Outputs, may
  come before or after it, each ended by a blank line).
- OptiTrack Motive export (format 1.2x)::

      Format Version,1.23,...,Export Frame Rate,120.000000,...,Length Units,Millimeters,...
      ,Type,Marker,Marker,Marker,Rigid Body,...
      ,Name,Set:M1,Set:M1,Set:M1,...
      ,ID,1,1,1,...                            (and a Parent row in newer versions)
      ,,Position,Position,Position,Rotation,...
      Frame,Time (Seconds),X,Y,Z,...

  Only ``Marker`` columns' positions are read (rigid bodies, bones and their expected markers are not
  measurements).

Empty cells are missing samples (NaN). A marker named ``Subject:NAME`` keeps ``NAME`` when all markers share
the subject; repeated names are made unique with a warning.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .errors import RigInputError, shown
from .take_data import MarkerTake, check_row_cells, text_table, unique_labels, units_from_text

PLAIN_RATE = 60.0   # frames a second of a plain marker CSV read without a rate (it has none of its own)


def _rows(path: Path) -> list[list[str]]:
    try:
        with open(path, newline="", encoding="utf-8-sig", errors="replace") as f:
            sample = f.read(4096)
            f.seek(0)
            delimiter = ";" if sample.count(";") > sample.count(",") else ","
            return [[c.strip() for c in r] for r in csv.reader(f, delimiter=delimiter)]
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror}).") from None
    except csv.Error as exc:   # a cell over the csv module's 131,072 characters, a NUL byte, ...
        raise RigInputError(f"{path}: is not a readable CSV ({shown(exc, 80)}).") from None


def _names(raw: list[str], path: Path, warnings: list[str]) -> list[str]:
    """Subject prefixes dropped when all markers share one; repeated names made unique (with a warning)."""
    prefixes = {n.rsplit(":", 1)[0] for n in raw if ":" in n}
    if len(prefixes) == 1 and all(":" in n for n in raw):
        raw = [n.rsplit(":", 1)[1] for n in raw]
    labels, renamed = unique_labels(raw, str(path))
    if renamed:
        warnings.append(renamed)
    return labels


def _take(path, data_rows, xyz_columns, raw_names, rate, units, warnings, rate_from_file=True) -> MarkerTake:
    if not data_rows:
        raise RigInputError(f"{path}: holds no frames.")
    if not xyz_columns:
        raise RigInputError(f"{path}: names no marker positions.")
    labels = _names(raw_names, path, warnings)
    check_row_cells(path, data_rows, 1 + max(c for trip in xyz_columns for c in trip), len(labels))
    table = text_table(path, data_rows, [c for trip in xyz_columns for c in trip])
    pos = table.reshape(len(data_rows), len(labels), 3)
    pos[~np.isfinite(pos).all(axis=2)] = np.nan
    first = text_table(path, data_rows[:1], [0])[0, 0]
    return MarkerTake(positions=pos, labels=labels, rate=rate, units=units, source=str(path),
                      first_frame=int(first) if np.isfinite(first) else 1, warnings=warnings,
                      rate_from_file=rate_from_file)


def _units(text: str, path: Path, what: str) -> str:
    units = units_from_text(text)
    if units is None:
        raise RigInputError(f"{path}: unknown units '{shown(text, 20)}' in {what} (use mm, cm or m).")
    return units


def _read_vicon(path: Path, rows: list[list[str]], start: int) -> MarkerTake:
    """The Trajectories section starting at row ``start``."""
    warnings: list[str] = []
    try:
        rate = float(rows[start + 1][0])
        names, axes, unit_row = rows[start + 2], rows[start + 3], rows[start + 4]
    except (IndexError, ValueError):
        raise RigInputError(f"{path}: the Trajectories section needs its frame rate, names, axes and units rows.") from None
    if not (rate > 0) or axes[:2] != ["Frame", "Sub Frame"]:
        raise RigInputError(f"{path}: the Trajectories section needs a positive frame rate and a 'Frame, Sub Frame' row.")
    xyz, raw = [], []
    for c, name in enumerate(names):
        if name:
            if axes[c:c + 3] != ["X", "Y", "Z"]:
                raise RigInputError(f"{path}: marker {shown(name, 40)} has no X, Y, Z columns under it.")
            xyz.append((c, c + 1, c + 2))
            raw.append(name)
    units = {u for trip in xyz for u in (unit_row[k] if k < len(unit_row) else "" for k in trip)}
    if len(units) != 1:
        named = [f"'{shown(u, 20)}'" for u in sorted(units)[:4]] + ([f"{len(units) - 4} more"] if len(units) > 4 else [])
        raise RigInputError(f"{path}: the Trajectories section mixes units ({', '.join(named)}).")
    data = []
    for i in range(start + 5, len(rows)):
        if not any(rows[i]):
            break   # a blank line ends the section
        data.append((i + 1, rows[i]))
    return _take(path, data, xyz, raw, rate, _units(units.pop(), path, "the Trajectories units row"), warnings)


def _read_motive(path: Path, rows: list[list[str]]) -> MarkerTake:
    warnings: list[str] = []
    head = rows[0]
    meta = {head[i]: head[i + 1] for i in range(0, len(head) - 1, 2)}
    try:
        rate = float(meta.get("Export Frame Rate") or meta.get("Capture Frame Rate") or "nan")
    except ValueError:
        rate = float("nan")
    if not rate > 0:
        raise RigInputError(f"{path}: the Motive header gives no positive Export Frame Rate.")
    units = _units(meta.get("Length Units", "Meters"), path, "Length Units")
    axis_at = next((i for i, r in enumerate(rows) if r[:2] == ["Frame", "Time (Seconds)"]), None)
    if axis_at is None:
        raise RigInputError(f"{path}: the Motive export has no 'Frame, Time (Seconds)' row.")
    labelled = {r[1]: r for r in rows[1:axis_at] if len(r) > 1 and r[1] in ("Type", "Name")}
    kinds = labelled.get("Type") or next((r for r in rows[1:axis_at] if "Marker" in r), None)
    names = labelled.get("Name") or (rows[rows.index(kinds) + 1] if kinds else None)
    component = rows[axis_at - 1]
    axes = rows[axis_at]
    if kinds is None or names is None:
        raise RigInputError(f"{path}: the Motive export has no Type and Name rows.")
    xyz, raw = [], []
    for c in range(2, len(axes) - 2):
        if (c < len(kinds) and kinds[c] == "Marker" and c < len(component) and component[c] == "Position"
                and axes[c:c + 3] == ["X", "Y", "Z"]):
            xyz.append((c, c + 1, c + 2))
            raw.append(names[c] if c < len(names) else "")
    data = [(i + 1, r) for i, r in enumerate(rows[axis_at + 1:], start=axis_at + 1) if any(r)]
    return _take(path, data, xyz, raw, rate, units, warnings)


def _read_plain(path: Path, rows: list[list[str]], rate: float | None, units: str) -> MarkerTake:
    rows = [(i + 1, r) for i, r in enumerate(rows) if any(r)]
    head = rows[0][1]
    cols = head[1:]
    if not cols or len(cols) % 3:
        raise RigInputError(f"{path}: after the frame column the header needs X, Y and Z columns per marker.")
    raw = []
    for i in range(0, len(cols), 3):
        trip = cols[i:i + 3]
        stems = {c.rsplit("_", 1)[0] for c in trip}
        axes = [c.rsplit("_", 1)[-1].upper() if "_" in c else "" for c in trip]
        if len(stems) != 1 or axes != ["X", "Y", "Z"]:
            raise RigInputError(f"{path}: columns {shown(', '.join(trip), 80)} are not one marker's name_X, name_Y, "
                                  "name_Z.")
        raw.append(stems.pop())
    for line_no, r in rows[1:]:
        if len(r) > len(head) and any(r[len(head):]):
            raise RigInputError(f"{path}: line {line_no} has more columns than the header.")
    xyz = [(1 + 3 * k, 2 + 3 * k, 3 + 3 * k) for k in range(len(raw))]
    warnings = []
    if rate is None:
        rate = PLAIN_RATE
        warnings.append(f"{path}: a plain marker CSV gives no frame rate; {PLAIN_RATE:g} frames a second assumed "
                        "(--rate FPS gives its rate).")
    return _take(path, rows[1:], xyz, raw, rate, units, warnings, rate_from_file=False)


def check_is_csv(path: Path, sample: int = 1 << 16) -> None:
    """Refuse a .csv file that is no CSV at all before its header is read as markers' ("the header needs X, Y and Z
    columns" said nothing true of a binary file or of prose): binary data (a NUL byte, or more than 1% of its first
    64 KB no UTF-8 text), or text none of whose first lines is cut into cells by a comma or a semicolon. An empty
    file is left to say it is empty."""
    try:
        with open(path, "rb") as f:
            head = f.read(sample)
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror}).") from None
    if not head.strip():
        return
    text = head.decode("utf-8", errors="replace")
    if b"\0" in head or text.count("\ufffd") > 0.01 * len(text):
        raise RigInputError(f"{path}: is not a CSV take: it holds binary data, not lines of text.")
    if not any("," in line or ";" in line for line in text.splitlines()[:100]):
        raise RigInputError(f"{path}: is not a CSV take: none of its lines is cells separated by commas or "
                            "semicolons.")


def read_marker_csv(path: str | Path, *, rate: float | None = None, units: str = "mm") -> MarkerTake:
    """Read a marker CSV: a Vicon Nexus or OptiTrack Motive export (rate and units from the file), or the
    plain ``frame, A_X, A_Y, A_Z, ...`` layout (``rate`` fps; None: ``PLAIN_RATE``, with a warning; ``units``)."""
    path = Path(path)
    check_is_csv(path)
    rows = _rows(path)
    if not any(any(r) for r in rows):
        raise RigInputError(f"{path}: the file is empty.")
    if rows[0][:1] == ["Format Version"]:
        return _read_motive(path, rows)
    section = next((i for i, r in enumerate(rows) if r[:1] == ["Trajectories"] and not any(r[1:])), None)
    if section is not None:
        return _read_vicon(path, rows, section)
    return _read_plain(path, rows, rate, units)


def write_marker_csv(path: str | Path, take: MarkerTake) -> None:
    """Write a MarkerTake as a Vicon Nexus ``Trajectories`` section (the layout ``read_marker_csv`` reads with its
    rate and units): ``Trajectories``, the frame rate, the labels (one over each X, Y, Z), ``Frame, Sub Frame, X, Y,
    Z, ...``, the units, then one row per frame from ``take.first_frame`` (empty cells where missing). The plain
    ``frame, name_X, ...`` layout has no place for either: read back, a take written in it was at 60 fps and in mm
    whatever it had been."""
    import io

    from .atomic import atomic_write
    if any(not n for n in take.labels):
        raise RigInputError(f"{path}: a marker with no label cannot be written in a marker CSV.")
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["Trajectories"])
    w.writerow([repr(float(take.rate))])   # the shortest text that reads back as the same number
    w.writerow(["", ""] + [c for n in take.labels for c in (n, "", "")])
    w.writerow(["Frame", "Sub Frame"] + ["X", "Y", "Z"] * take.n_markers)
    w.writerow(["", ""] + [take.units] * (3 * take.n_markers))
    lines = [out.getvalue().rstrip("\n")]
    flat = take.positions.reshape(take.n_frames, -1)
    for i, row in enumerate(flat):
        lines.append(f"{take.first_frame + i},0," + ",".join("" if not np.isfinite(v) else f"{v:.6f}" for v in row))
    atomic_write(path, ("\n".join(lines) + "\n").encode())
