"""Per-frame weights as CSV: ``frame,time,<shape names...>``, one row per frame (written atomically)."""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .errors import RigInputError, shown
from .input_files import regular_file


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


def read_weights_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray]:
    """(frames (F,) int, times (F,), names (K), weights (F, K)) from a weights CSV."""
    path = regular_file(path)   # a missing file, a folder, a FIFO or a device: one sentence, nothing read
    text = path.read_text(encoding="utf-8-sig", errors="replace")
    try:
        rows = [r for r in csv.reader(io.StringIO(text)) if r and any(c.strip() for c in r)]
    except csv.Error as exc:   # a cell over the csv module's 131,072 characters, a NUL byte, ...
        raise RigInputError(f"{path}: is not a readable CSV ({shown(exc, 80)}).") from None
    if not rows:
        raise RigInputError(f"{path}: the file is empty.")
    header = [c.strip() for c in rows[0]]
    if len(header) < 3 or header[0].lower() != "frame" or header[1].lower() != "time":
        raise RigInputError(f"{path}: a weights CSV starts with the columns frame,time,<shape names>.")
    names = header[2:]
    if len(set(names)) != len(names):
        raise RigInputError(f"{path}: duplicate shape names in the header.")
    data = rows[1:]
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
    return frames.astype(np.int64), arr[:, 1], names, arr[:, 2:]


def is_weights_csv(path: str | Path) -> bool:
    """True if the CSV's header starts with ``frame,time`` (a weights CSV, as ``solve`` writes)."""
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        head = [c.strip().lower() for c in f.readline().split(",")]
    return len(head) >= 3 and head[0] == "frame" and head[1] == "time"


def read_weights_take(path: str | Path, shape_names: list[str]):
    """A weights CSV as a weight take (``model.take_data.WeightTake``) on a rig's ``shape_names``: each column in
    its shape's place, shapes without a column at 0. The rate comes from the time column, which must step evenly
    with the frame column (RigInputError, one sentence, otherwise, or for a column the rig has no shape for)."""
    from .take_data import WeightTake
    frames, times, names, W = read_weights_csv(path)
    unknown = [n for n in names if n not in shape_names]
    if unknown:
        raise RigInputError(f"{path}: names shapes the rig does not have: {', '.join(unknown[:5])}"
                            f"{' ...' if len(unknown) > 5 else ''}.")
    warnings = []
    if frames.size > 1:
        steps = np.diff(frames)
        if (steps != 1).any():
            raise RigInputError(f"{path}: its frame numbers do not count up one by one (row "
                                f"{int(np.argmax(steps != 1)) + 3}).")
        rate = 1.0 / float(np.median(np.diff(times)))
        if not np.isfinite(rate) or rate <= 0 or np.abs(times - times[0] - np.arange(frames.size) / rate).max() \
                > 1e-3 / rate:
            raise RigInputError(f"{path}: its times are not evenly spaced frames (a frame every 1/rate seconds).")
        rate = float(np.round(rate, 6))
    else:
        rate = 30.0
        warnings.append(f"{path}: one frame has no frame rate; 30 frames a second assumed.")
    pos = {n: k for k, n in enumerate(shape_names)}
    full = np.zeros((W.shape[0], len(shape_names)))
    full[:, [pos[n] for n in names]] = W
    return WeightTake(weights=full, names=list(shape_names), rate=rate, source=str(path), warnings=warnings)
