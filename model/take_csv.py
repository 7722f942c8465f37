"""Generic CSV of marker trajectories: a frame column, then ``name_X, name_Y, name_Z`` per marker.

Empty cells are missing samples (NaN). Units and frame rate are not in the file; pass them.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .errors import RigInputError
from .takes import MarkerTake


def read_marker_csv(path: str | Path, *, rate: float = 60.0, units: str = "mm") -> MarkerTake:
    """Read ``frame, A_X, A_Y, A_Z, B_X, ...`` into a MarkerTake (``rate`` fps, ``units``)."""
    path = Path(path)
    with open(path, newline="", encoding="utf-8", errors="replace") as f:
        rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
    if not rows:
        raise RigInputError(f"{path}: the file is empty.")
    head = [c.strip() for c in rows[0]]
    cols = head[1:]
    if not cols or len(cols) % 3:
        raise RigInputError(f"{path}: after the frame column the header needs X, Y and Z columns per marker.")
    labels = []
    for i in range(0, len(cols), 3):
        trip = cols[i:i + 3]
        stems = {c.rsplit("_", 1)[0] for c in trip}
        axes = [c.rsplit("_", 1)[-1].upper() if "_" in c else "" for c in trip]
        if len(stems) != 1 or axes != ["X", "Y", "Z"]:
            raise RigInputError(f"{path}: columns {', '.join(trip)} are not one marker's name_X, name_Y, name_Z.")
        labels.append(stems.pop())
    body = rows[1:]
    if not body:
        raise RigInputError(f"{path}: holds no frames.")
    table = np.full((len(body), len(head)), np.nan)
    for i, r in enumerate(body):
        if len(r) > len(head):
            raise RigInputError(f"{path}: row {i + 2} has more columns than the header.")
        try:
            table[i, :len(r)] = [float(c) if c.strip() else np.nan for c in r]
        except ValueError:
            raise RigInputError(f"{path}: row {i + 2} has a cell that is not a number.") from None
    pos = table[:, 1:].reshape(len(body), len(labels), 3)
    pos[~np.isfinite(pos).all(axis=2)] = np.nan
    return MarkerTake(positions=pos, labels=labels, rate=rate, units=units, source=str(path))


def write_marker_csv(path: str | Path, take: MarkerTake) -> None:
    """Write a MarkerTake as ``frame, name_X, name_Y, name_Z, ...`` (empty cells where missing)."""
    from .atomic import atomic_write
    lines = ["frame," + ",".join(f"{n}_{a}" for n in take.labels for a in "XYZ")]
    flat = take.positions.reshape(take.n_frames, -1)
    for i, row in enumerate(flat):
        lines.append(str(i) + "," + ",".join("" if not np.isfinite(v) else f"{v:.6f}" for v in row))
    atomic_write(path, ("\n".join(lines) + "\n").encode())
