"""Live Link Face CSV weight takes (Epic's iPhone app; ARKit face tracking).

Columns: ``Timecode, BlendShapeCount``, 52 ARKit blendshape weights (``EyeBlinkLeft``, ``JawOpen``, ...),
then head and eye yaw/pitch/roll.

Timing comes from the timecodes, ``HH:MM:SS:FF.fff`` (FF the frame within the second, ``.fff`` the fraction
of a frame): the timecode rate is the smallest standard rate above the largest FF (30 or 60 for the iPhone
app), the take's rate is the step between rows (60 fps recorded under a 30 fps timecode steps half a frame),
and a frame the phone dropped leaves a gap in the timecodes. Such gaps are filled by interpolating the
neighbouring frames, so that frame k is always at k / rate seconds and the take plays in time. ``default_arkit_mapping`` maps each ARKit column to rig shape names:
``...Left``/``...Right`` become ``..._L``/``..._R`` with a lower-case first letter (ICT / ARKit-on-Maya
naming); a column without a side drives the rig's unsided shape, or both ``_L`` and ``_R`` when the rig
splits it (``BrowInnerUp``, ``CheekPuff`` on ICT). The mapping is a plain dict the GUI can edit.
"""
from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from .errors import RigInputError, shown
from .input_files import regular_file
from .take_data import WeightTake

ROTATION_COLUMNS = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
                    "RightEyeYaw", "RightEyePitch", "RightEyeRoll")


FILE_FORMAT = "Live Link Face CSV"   # what a take this module reads is (``WeightTake.file_format``)
_TIMECODE = re.compile(r"^(\d+):(\d{1,2}):(\d{1,2})[:;](\d+)(\.\d+)?$")
_RATES = (24.0, 25.0, 30.0, 48.0, 50.0, 60.0, 120.0)


def _standard(rate: float) -> float:
    """The standard rate within 1 % of ``rate``, or ``rate`` itself."""
    near = min(_RATES, key=lambda r: abs(r - rate))
    return near if abs(near - rate) <= 0.01 * near else rate


def livelink_timing(timecodes: list[str], path: str | Path) -> tuple[float, np.ndarray, list[str]]:
    """(frame rate, frame index of each row, warnings) from Live Link Face timecodes.

    Row i lands on frame ``index[i]`` of an evenly spaced take; indices skip where the phone dropped frames.
    """
    parts = []
    for i, code in enumerate(timecodes):
        m = _TIMECODE.match(code.strip())
        if not m:
            raise RigInputError(f"{path}: row {i + 2} has the timecode '{shown(code, 30)}', not HH:MM:SS:FF.")
        h, mi, sec, ff, frac = m.groups()
        parts.append((int(h) * 3600 + int(mi) * 60 + int(sec), int(ff) + (float(frac) if frac else 0.0)))
    whole = np.array([p[0] for p in parts], dtype=np.float64)
    frames = np.array([p[1] for p in parts])
    warnings = []
    tc_rate = next((r for r in _RATES if r > frames.max()), None)
    if tc_rate is None:
        raise RigInputError(f"{path}: its timecodes count {int(frames.max()) + 1} frames a second, "
                            "more than any timecode rate.")
    if len(set(whole)) == 1 and len(timecodes) > 1:
        warnings.append(f"{path}: the take is shorter than a second, so its timecodes do not show their rate; "
                        f"{tc_rate:g} frames a second assumed.")
    t = whole + frames / tc_rate
    t = np.where(t < t[0] - 43200, t + 86400, t)   # past midnight
    if len(t) == 1:
        return tc_rate, np.zeros(1, dtype=np.int64), warnings
    dt = np.diff(t)
    back = np.flatnonzero(dt <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise RigInputError(f"{path}: row {i + 2}'s timecode {timecodes[i]} does not come after row {i + 1}'s "
                            f"({timecodes[i - 1]}).")
    rate = _standard(1.0 / float(np.median(dt)))
    steps = np.maximum(1, np.rint(dt * rate)).astype(np.int64)
    index = np.concatenate([[0], np.cumsum(steps)])
    dropped = int(index[-1] + 1 - len(t))
    if dropped > len(t):
        i = int(np.argmax(steps)) + 1
        raise RigInputError(f"{path}: the timecodes jump by {dt[i - 1]:.2f} s at row {i + 2}; more frames are "
                            "missing than recorded.")
    if dropped:
        rows = [str(int(i) + 2) for i in np.flatnonzero(steps > 1)[:5] + 1]
        warnings.append(f"{path}: {dropped} dropped frames (before row {', '.join(rows)}"
                        f"{' ...' if (steps > 1).sum() > 5 else ''}) were filled by interpolating their "
                        "neighbours, so the take keeps time with its timecodes.")
    return rate, index, warnings


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
    path = regular_file(path)   # a missing file, a folder, a FIFO or a device: one sentence, nothing read
    try:
        with open(path, newline="", encoding="utf-8", errors="replace") as f:
            rows = [r for r in csv.reader(f) if any(c.strip() for c in r)]
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror}).") from None
    except csv.Error as exc:   # a cell over the csv module's 131,072 characters, a NUL byte, ...
        raise RigInputError(f"{path}: is not a readable CSV ({shown(exc, 80)}).") from None
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


def _in_time(times: list[str], vals: np.ndarray, path: Path, rate: float | None):
    """Rows placed on an evenly spaced take by their timecodes: (rate, timecodes, values, filled, warnings).
    Dropped frames get values interpolated between their neighbours and an empty timecode."""
    if rate is not None:   # the caller knows better: rows are frames
        return rate, times, vals, np.zeros(len(times), dtype=bool), []
    rate, index, warnings = livelink_timing(times, path)
    F = int(index[-1]) + 1
    filled = np.ones(F, dtype=bool)
    filled[index] = False
    if not filled.any():
        return rate, times, vals, filled, warnings
    full = np.empty((F, vals.shape[1]))
    for j in range(vals.shape[1]):
        full[:, j] = np.interp(np.arange(F), index, vals[:, j])
    codes = [""] * F
    for i, k in enumerate(index):
        codes[k] = times[i]
    return rate, codes, full, filled, warnings


def read_livelink_csv(path: str | Path, shape_names: list[str] | None = None,
                      mapping: dict[str, list[str] | str] | None = None, *, rate: float | None = None) -> WeightTake:
    """Read a Live Link Face CSV as per-frame weights for ``shape_names`` (a rig's shapes).

    Without ``shape_names`` the weights keep the ARKit column names. ``mapping`` ({column: rig name or
    [names]}) overrides the default; shapes no column drives stay 0; columns driving nothing are listed in
    ``unmapped``. Head/eye rotations are kept in ``channels``. The rate and the frames' times come from the
    timecodes (dropped frames filled in, see the module text) unless ``rate`` is given.
    """
    path = Path(path)
    times, cols, vals = read_livelink_raw(path)
    rate, times, vals, filled, warnings = _in_time(times, vals, path, rate)
    channels = {c: vals[:, j] for j, c in enumerate(cols) if c in ROTATION_COLUMNS}
    weight_cols = [c for c in cols if c not in ROTATION_COLUMNS]
    if shape_names is None:
        idx = [cols.index(c) for c in weight_cols]
        return WeightTake(weights=vals[:, idx], names=weight_cols, rate=rate, timecodes=times,
                          channels=channels, source=str(path), warnings=warnings, filled=filled,
                          file_format=FILE_FORMAT)
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
                      channels=channels, source=str(path), warnings=warnings, filled=filled, file_format=FILE_FORMAT)
