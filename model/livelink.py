"""Live Link Face CSV weight takes (Epic's iPhone app; ARKit face tracking).

Columns: ``Timecode, BlendShapeCount``, 52 ARKit blendshape weights (``EyeBlinkLeft``, ``JawOpen``, ...),
then head and eye yaw/pitch/roll. ``default_arkit_mapping`` maps each ARKit column to rig shape names:
``...Left``/``...Right`` become ``..._L``/``..._R`` with a lower-case first letter (ICT / ARKit-on-Maya
naming); a column without a side drives the rig's unsided shape, or both ``_L`` and ``_R`` when the rig
splits it (``BrowInnerUp``, ``CheekPuff`` on ICT). The mapping is a plain dict the GUI can edit.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .errors import RigInputError
from .takes import WeightTake

ROTATION_COLUMNS = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
                    "RightEyeYaw", "RightEyePitch", "RightEyeRoll")


def is_livelink_csv(path: str | Path) -> bool:
    """True if the CSV's header starts with ``Timecode, BlendShapeCount``."""
    with open(path, encoding="utf-8", errors="replace") as f:
        head = f.readline().replace(" ", "").split(",")
    return len(head) >= 2 and head[0] == "Timecode" and head[1] == "BlendShapeCount"


def _rig_name(arkit: str) -> tuple[str, str]:
    for suffix, side in (("Left", "_L"), ("Right", "_R")):
        if arkit.endswith(suffix) and len(arkit) > len(suffix):
            stem = arkit[: -len(suffix)]
            return stem[0].lower() + stem[1:], side
    return arkit[0].lower() + arkit[1:], ""


def default_arkit_mapping(columns: list[str], shape_names: list[str]) -> dict[str, list[str]]:
    """{ARKit column: [rig shape names it drives]} (empty list = unmapped), matched case-insensitively."""
    lower = {n.lower(): n for n in shape_names}
    mapping: dict[str, list[str]] = {}
    for col in columns:
        if col in ROTATION_COLUMNS:
            continue
        stem, side = _rig_name(col)
        cands = [stem + side] if side else [stem]
        if side:
            cands += [col, stem + side.replace("_", ""), stem + ("Left" if side == "_L" else "Right")]
        hit = [lower[c.lower()] for c in cands if c.lower() in lower][:1]
        if not hit and not side:
            hit = [lower[(stem + s).lower()] for s in ("_L", "_R") if (stem + s).lower() in lower]
        mapping[col] = hit
    return mapping


def read_livelink_raw(path: str | Path) -> tuple[list[str], list[str], np.ndarray]:
    """(timecodes, column names after BlendShapeCount, values (F, C)) of a Live Link Face CSV."""
    path = Path(path)
    if not path.is_file():
        raise RigInputError(f"{path}: does not exist.")
    with open(path, newline="", encoding="utf-8", errors="replace") as f:
        rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
    if not rows:
        raise RigInputError(f"{path}: the file is empty.")
    head = [c.strip() for c in rows[0]]
    if len(head) < 3 or head[0] != "Timecode" or head[1] != "BlendShapeCount":
        raise RigInputError(f"{path}: is not a Live Link Face CSV (the header must start with Timecode, BlendShapeCount).")
    if len(rows) < 2:
        raise RigInputError(f"{path}: holds no frames.")
    cols = head[2:]
    vals = np.full((len(rows) - 1, len(cols)), np.nan)
    times = []
    for i, r in enumerate(rows[1:]):
        if len(r) != len(head):
            raise RigInputError(f"{path}: row {i + 2} has {len(r)} columns but the header has {len(head)}.")
        times.append(r[0].strip())
        try:
            vals[i] = [float(c) for c in r[2:]]
        except ValueError:
            raise RigInputError(f"{path}: row {i + 2} has a value that is not a number.") from None
    return times, cols, vals


def read_livelink_csv(path: str | Path, shape_names: list[str] | None = None,
                      mapping: dict[str, list[str] | str] | None = None, *, rate: float = 60.0) -> WeightTake:
    """Read a Live Link Face CSV as per-frame weights for ``shape_names`` (a rig's shapes).

    Without ``shape_names`` the weights keep the ARKit column names. ``mapping`` ({column: rig name or
    [names]}) overrides the default; shapes no column drives stay 0; columns driving nothing are listed in
    ``unmapped``. Head/eye rotations are kept in ``channels``.
    """
    path = Path(path)
    times, cols, vals = read_livelink_raw(path)
    channels = {c: vals[:, j] for j, c in enumerate(cols) if c in ROTATION_COLUMNS}
    weight_cols = [c for c in cols if c not in ROTATION_COLUMNS]
    if shape_names is None:
        idx = [cols.index(c) for c in weight_cols]
        return WeightTake(weights=vals[:, idx], names=weight_cols, rate=rate, timecodes=times,
                          channels=channels, source=str(path))
    shape_names = list(shape_names)
    m = default_arkit_mapping(weight_cols, shape_names)
    for col, tgt in (mapping or {}).items():
        m[col] = [tgt] if isinstance(tgt, str) else list(tgt)
    pos = {n: k for k, n in enumerate(shape_names)}
    W = np.zeros((len(times), len(shape_names)))
    unmapped = []
    for col in weight_cols:
        targets = [t for t in m.get(col, []) if t in pos]
        bad = [t for t in m.get(col, []) if t not in pos]
        if bad:
            raise RigInputError(f"{path}: the mapping sends {col} to {', '.join(bad)}, which the rig does not have.")
        if not targets:
            unmapped.append(col)
        for t in targets:
            W[:, pos[t]] = vals[:, cols.index(col)]
    if len(unmapped) == len(weight_cols):
        raise RigInputError(f"{path}: no Live Link Face column matches a shape of the rig.")
    return WeightTake(weights=W, names=shape_names, rate=rate, timecodes=times, unmapped=unmapped,
                      channels=channels, source=str(path))
