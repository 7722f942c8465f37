"""Per-frame weights as CSV: ``frame,time,<shape names...>``, one row per frame (written atomically).

Read back, the time column may be left out: ``frame,<shape names...>`` (as a script or another tool writes the
weights of a take: the shared data's ``truth_weights.csv``) is a weights CSV too, at ``UNTIMED_RATE`` frames a
second with a warning, unless its columns are marker coordinates (``name_X, name_Y, name_Z``: a marker CSV,
``model.take_csv``)."""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .errors import RigInputError, shown
from .input_files import regular_file

FILE_FORMAT = "weights CSV"   # what a take this module reads is (``WeightTake.file_format``): as ``solve`` writes
UNTIMED_RATE = 30.0      # frames a second of a weights CSV without a time column (as of a one-frame weights CSV)
_AXIS_SEPARATORS = "_.:- "


def write_weights_csv(path: str | Path, weights: np.ndarray, names: list[str], *, rate: float | None = None,
                      times: np.ndarray | None = None, frames: np.ndarray | None = None) -> None:
    """Write weights (F, K) with ``names`` (K); times from ``times`` or ``frame / rate`` (rate in fps)."""
    atomic_write(path, weights_csv_bytes(path, weights, names, rate=rate, times=times, frames=frames))


def weights_csv_bytes(path: str | Path, weights: np.ndarray, names: list[str], *, rate: float | None = None,
                      times: np.ndarray | None = None, frames: np.ndarray | None = None) -> bytes:
    """The weights CSV's content (``path`` names it in messages); see ``write_weights_csv``."""
    W = np.asarray(weights, dtype=np.float64)
    if W.ndim != 2 or W.shape[1] != len(names):
        raise RigInputError(f"{path}: {len(names)} shape names but weights of shape {W.shape}.")
    if len(set(names)) != len(names):
        raise RigInputError(f"{path}: duplicate shape names in the weights.")
    F = W.shape[0]
    fr = np.arange(F) if frames is None else np.asarray(frames)
    if times is None:
        if rate is None or rate <= 0:
            raise RigInputError(f"{path}: give the frame rate (fps > 0) or the frame times.")
        times = fr / float(rate)
    times = np.asarray(times, dtype=np.float64)
    if fr.shape != (F,) or times.shape != (F,):
        raise RigInputError(f"{path}: frames and times must have one entry per row of weights ({F}).")
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(["frame", "time", *names])   # names quoted where a CSV needs it
    # The numbers as the csv module writes them (shortest round-trip repr; a number never needs quoting), joined
    # directly: a csv writer over numpy scalars cost ~25 ms for the shared 358 x 57 take, a third of that here.
    buf.write("".join(f"{f},{t!r},{','.join(map(repr, row))}\n"
                      for f, t, row in zip(fr.astype(np.int64).tolist(), times.tolist(), W.tolist())))
    return buf.getvalue().encode("utf-8")


def _looks_like_axes(names: list[str]) -> bool:
    """Whether columns are marker coordinates: ``X``, ``name_X`` (any of ``_.:- `` before the axis), or three in a
    row that differ only in a last letter x, y, z (``M00x, M00y, M00z``)."""
    low = [n.strip().lower() for n in names]
    if any(n in ("x", "y", "z") or (len(n) > 1 and n[-1] in "xyz" and n[-2] in _AXIS_SEPARATORS) for n in low):
        return True
    return any(len(a) > 1 and a[:-1] == b[:-1] == c[:-1] and a[-1] + b[-1] + c[-1] == "xyz"
               for a, b, c in zip(low, low[1:], low[2:]))


def weights_header(header: list[str]) -> str | None:
    """'timed' for ``frame,time,<names>``, 'untimed' for ``frame,<names>`` whose names are not marker coordinates,
    None for any other header."""
    head = [c.strip().lower() for c in header]
    if len(head) < 2 or head[0] != "frame":
        return None
    if head[1] == "time":
        return "timed" if len(head) >= 3 else None
    return None if _looks_like_axes(header[1:]) else "untimed"


def read_weights_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray]:
    """(frames (F,) int, times (F,), names (K), weights (F, K)) from a weights CSV; the times of one without a time
    column are frame steps at ``UNTIMED_RATE`` from its first frame (``read_weights_table`` tells them apart)."""
    frames, times, names, W = read_weights_table(path)
    if times is None:
        times = (frames - frames[0]) / UNTIMED_RATE if frames.size else np.zeros(0)
    return frames, times, names, W


def read_weights_table(path: str | Path) -> tuple[np.ndarray, np.ndarray | None, list[str], np.ndarray]:
    """(frames (F,) int, times (F,) or None where the file has no time column, names (K), weights (F, K))."""
    path = regular_file(path)   # a missing file, a folder, a FIFO or a device: one sentence, nothing read
    text = path.read_text(encoding="utf-8-sig", errors="replace")
    try:
        rows = [r for r in csv.reader(io.StringIO(text)) if r and any(c.strip() for c in r)]
    except csv.Error as exc:   # a cell over the csv module's 131,072 characters, a NUL byte, ...
        raise RigInputError(f"{path}: is not a readable CSV ({shown(exc, 80)}).") from None
    if not rows:
        raise RigInputError(f"{path}: the file is empty.")
    header = [c.strip() for c in rows[0]]
    kind = weights_header(header)
    if kind is None:
        raise RigInputError(f"{path}: a weights CSV starts with the columns frame,time,<shape names> (or "
                            "frame,<shape names>).")
    lead = 2 if kind == "timed" else 1
    names = header[lead:]
    if len(set(names)) != len(names):
        raise RigInputError(f"{path}: duplicate shape names in the header.")
    data = rows[1:]
    if not data:     # a header alone: a take of no frames, which nothing can play or solve
        raise RigInputError(f"{path}: holds no frames.")
    bad = next((i for i, r in enumerate(data) if len(r) != len(header)), None)
    if bad is not None:
        raise RigInputError(f"{path}: row {bad + 2} has {len(data[bad])} values, the header has {len(header)}.")
    try:
        arr = np.array([[float(c) for c in r] for r in data], dtype=np.float64).reshape(len(data), len(header))
    except ValueError:
        raise RigInputError(f"{path}: has a value that is not a number.") from None
    if not np.isfinite(arr).all():
        raise RigInputError(f"{path}: has NaN or infinite values.")
    frames = arr[:, 0]
    bad = (frames != np.round(frames)) | (np.abs(frames) > 2 ** 53)
    if bad.any():
        raise RigInputError(f"{path}: row {int(np.argmax(bad)) + 2} has a frame number that is not a whole number.")
    return frames.astype(np.int64), (arr[:, 1] if lead == 2 else None), names, arr[:, lead:]


def is_weights_csv(path: str | Path) -> bool:
    """True if the CSV's header is a weights CSV's (``weights_header``): ``frame,time,<names>`` as ``solve``
    writes, or ``frame,<names>`` whose names are not marker coordinates."""
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        line = f.readline(1 << 20)
    try:
        header = next(csv.reader([line]), [])
    except csv.Error:
        return False
    return weights_header(header) is not None


# How far (in frames) a row's time may be from its place on the even grid: the rounding of times written with few
# decimals (printf's %f: 6; milliseconds: 3, 0.03 of a frame at 60 fps); a frame dropped or repeated is 0.5-1.
TIME_JITTER_FRAMES = 0.1


def times_rate(times: np.ndarray) -> float | None:
    """The frame rate of evenly spaced ``times`` (seconds, two or more), or None if they are not. The rate is the
    whole span's (one rounded step, 0.016667 for 1/60, would be 60.0012 fps and drift a frame in 14 minutes); a
    whole or NTSC rate (n * 1000/1001) that places every row as well as it does is preferred."""
    times = np.asarray(times, dtype=np.float64)
    k = np.arange(times.size)
    span = float(times[-1] - times[0])
    if not (np.isfinite(span) and span > 0):
        return None
    rate = (times.size - 1) / span

    def off(r: float) -> float:            # the largest distance of a row from its place at rate r (seconds)
        return float(np.abs(times - times[0] - k / r).max())

    if off(rate) > TIME_JITTER_FRAMES / rate:
        return None
    for nice in (float(np.round(rate)), float(np.round(rate * 1.001)) / 1.001):
        if nice > 0 and off(nice) <= 2 * off(rate) + 1e-6:
            return nice
    return float(np.round(rate, 6))


def check_shapes_known(source, names, shape_names) -> None:
    """RigInputError naming ``source`` when a column of weights ``names`` a shape not in ``shape_names`` (the first
    five unknown names, and how many more)."""
    unknown = [n for n in names if n not in shape_names]
    if unknown:
        raise RigInputError(f"{source}: names shapes the rig does not have: {', '.join(unknown[:5])}"
                            f"{f' and {len(unknown) - 5} more' if len(unknown) > 5 else ''}.")


def read_weights_take(path: str | Path, shape_names: list[str] | None, *, rate: float | None = None):
    """A weights CSV as a weight take (``model.take_data.WeightTake``) on a rig's ``shape_names``: each column in
    its shape's place, shapes without a column at 0 (None: the file's own columns, for ``take-info``). The rate
    comes from the time column, which must step evenly with the frame column (RigInputError, one sentence,
    otherwise, or for a column the rig has no shape for); without a time column (or with one row) it is ``rate``
    (the user's, ``model.take_data.given_rate``), else ``UNTIMED_RATE`` with a warning."""
    from .take_data import WeightTake
    given = rate
    frames, times, names, W = read_weights_table(path)
    if shape_names is None:
        shape_names = list(names)
    check_shapes_known(path, names, shape_names)
    warnings = []
    if frames.size > 1:
        steps = np.diff(frames)
        if (steps != 1).any():
            raise RigInputError(f"{path}: its frame numbers do not count up one by one (row "
                                f"{int(np.argmax(steps != 1)) + 3}).")
    if times is not None and frames.size > 1:
        rate = times_rate(times)
        if rate is None:
            raise RigInputError(f"{path}: its times are not evenly spaced frames (a frame every 1/rate seconds).")
    elif given is not None:
        rate = given
    elif times is None:
        rate = UNTIMED_RATE
        warnings.append(f"{path}: has no time column; {UNTIMED_RATE:g} frames a second assumed.")
    else:
        rate = 30.0
        warnings.append(f"{path}: one frame has no frame rate; 30 frames a second assumed.")
    pos = {n: k for k, n in enumerate(shape_names)}
    full = np.zeros((W.shape[0], len(shape_names)))
    full[:, [pos[n] for n in names]] = W
    return WeightTake(weights=full, names=list(shape_names), rate=rate, source=str(path), warnings=warnings,
                      rate_from_file=times is not None and frames.size > 1, file_format=FILE_FORMAT)
