"""Takes as data: marker trajectories (``MarkerTake``) and weight takes (``WeightTake``), with the helpers every
take reader shares (units from text, unique labels) and the summary ``take-info`` prints. The readers
(``model.take_c3d``, ``take_trc``, ``take_csv``, ``livelink``) build these; ``model.takes.load_take`` picks the
reader.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import RigInputError, repeated, shown
from .rig import MAX_COORDINATE, MAX_WEIGHT, UNIT_IN_METRES, unit_scale

MAX_RATE = 100_000.0   # frames per second: no capture system records faster
MIN_RATE = 0.001       # frames per second given for a take (--rate): a frame every 1000 s; slower, times overflow


def given_rate(rate, where: str = "--rate") -> float | None:
    """A frame rate the user gives for a take whose file states none (None: none given), checked: a number from
    ``MIN_RATE`` to ``MAX_RATE`` frames a second, else RigInputError (one sentence)."""
    if rate is None:
        return None
    try:
        value = float(rate)
    except (TypeError, ValueError):
        value = float("nan")
    if not (np.isfinite(value) and MIN_RATE <= value <= MAX_RATE):
        text = f"{value:g}" if value == value or isinstance(rate, float) else shown(rate, 20)
        raise RigInputError(f"{where}: {text} is not a frame rate; give frames a second from {MIN_RATE:g} to "
                            f"{MAX_RATE:g}.")
    return value


def rate_not_used(source, own: float | None, given: float | None) -> list[str]:
    """The warning for a rate given (``given_rate``) to a take whose file has its own (``own``; None: its own times
    without one rate), or none when none was given or the two agree."""
    if given is None or (own is not None and abs(own - given) <= 1e-9 * given):
        return []
    return [f"{source}: --rate {given:g} is not used: the file gives its own frame "
            f"{'times' if own is None else f'rate ({own:g} fps)'}."]


@dataclass
class MarkerTake:
    """Marker trajectories: ``positions`` (F, M, 3) float64, NaN where a marker is missing."""

    positions: np.ndarray
    labels: list[str]
    rate: float
    units: str = "mm"
    source: str = ""
    first_frame: int = 1
    warnings: list[str] = field(default_factory=list)
    model_outputs: list[str] = field(default_factory=list)   # labels of points the reader left out (not markers)
    rate_from_file: bool = True   # False: the file gives no rate (a plain marker CSV): ``rate`` was given or assumed

    def __post_init__(self) -> None:
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float64)
        self.labels = [str(s) for s in self.labels]
        where = self.source or "take"
        if self.positions.ndim != 3 or self.positions.shape[2] != 3:
            raise RigInputError(f"{where}: marker positions must be frames x markers x 3.")
        if self.positions.shape[1] != len(self.labels):
            raise RigInputError(f"{where}: {len(self.labels)} labels but {self.positions.shape[1]} markers.")
        dup = repeated(self.labels)
        if dup:
            raise RigInputError(f"{where}: duplicate marker labels: {', '.join(dup)}.")
        if self.units not in UNIT_IN_METRES:
            raise RigInputError(f"{where}: unknown units '{self.units}' (use mm, cm or m).")
        if not (np.isfinite(self.rate) and 0 < self.rate <= MAX_RATE):
            raise RigInputError(f"{where}: the frame rate must be a number above 0 and at most {MAX_RATE:g} fps, "
                                f"not {shown(self.rate, 20)}.")
        if np.isinf(self.positions).any():
            raise RigInputError(f"{where}: holds infinite coordinates; the file is damaged.")
        if self.positions.size and np.nanmax(np.abs(self.positions), initial=0.0) > MAX_COORDINATE:
            raise RigInputError(f"{where}: holds coordinates beyond ±{MAX_COORDINATE:g} {self.units}; "
                                "the file is damaged.")

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_markers(self) -> int:
        return int(self.positions.shape[1])

    @property
    def missing(self) -> np.ndarray:
        """(F, M) bool, True where a marker has no sample."""
        return ~np.isfinite(self.positions).all(axis=2)

    def times(self) -> np.ndarray:
        return np.arange(self.n_frames) / self.rate

    def in_units(self, units: str) -> np.ndarray:
        """Positions converted to ``units``."""
        return self.positions * unit_scale(self.units, units)

    def marker_index(self, label: str) -> int:
        try:
            return self.labels.index(label)
        except ValueError:
            raise RigInputError(f"{self.source or 'take'}: has no marker labelled '{label}'.") from None


@dataclass
class WeightTake:
    """Per-frame shape weights (F, K) for ``names``; e.g. a Live Link Face recording mapped to a rig.

    ``unmapped`` lists source columns that drive no shape of the rig; ``channels`` keeps the other
    per-frame columns (head and eye rotations) by name; ``file_format`` says what the file is ("Live Link Face
    CSV", "weights CSV": each reader's ``FILE_FORMAT``), for whoever describes the take.
    """

    weights: np.ndarray
    names: list[str]
    rate: float
    timecodes: list[str] = field(default_factory=list)
    unmapped: list[str] = field(default_factory=list)
    channels: dict[str, np.ndarray] = field(default_factory=dict)
    source: str = ""
    warnings: list[str] = field(default_factory=list)
    filled: np.ndarray | None = None   # (F,) bool: frames the recording dropped, interpolated in time
    rate_from_file: bool = True   # False: the file gives no rate (a weights CSV without times): given or assumed
    file_format: str = "weight take"   # what the file is, in the user's words: its reader's ``FILE_FORMAT``

    def __post_init__(self) -> None:
        self.weights = np.ascontiguousarray(self.weights, dtype=np.float64)
        where = self.source or "take"
        if self.weights.ndim != 2 or self.weights.shape[1] != len(self.names):
            raise RigInputError(f"{where}: weights do not match the {len(self.names)} shape names.")
        if not np.isfinite(self.weights).all() or np.abs(self.weights).max(initial=0.0) > MAX_WEIGHT:
            raise RigInputError(f"{where}: holds a weight that is not a number within ±{MAX_WEIGHT:g}.")
        if not (np.isfinite(self.rate) and 0 < self.rate <= MAX_RATE):
            raise RigInputError(f"{where}: the frame rate must be above 0 and at most {MAX_RATE:g} fps.")

    @property
    def n_frames(self) -> int:
        return int(self.weights.shape[0])

    def times(self) -> np.ndarray:
        """Seconds from the first frame; frames are evenly spaced (dropped frames are filled in)."""
        return np.arange(self.n_frames) / self.rate


SHORT_ROWS = 4   # a text take whose rows hold less than 1/SHORT_ROWS of the cells its header implies is refused


def check_row_cells(path, rows: list[tuple[int, list[str]]], columns: int, markers: int) -> None:
    """Refuse a text take (TRC, marker CSV) whose rows stop far short of its header's columns, before the
    (rows x columns) table is filled in with NaN: a few MB of header and short rows would ask for GBs. Rows that
    end early here and there (a truncated last row, trailing markers left out) stay readable."""
    present = sum(min(len(r), columns) for _, r in rows)
    if len(rows) * columns > SHORT_ROWS * present + columns:
        raise RigInputError(f"{path}: its {len(rows)} rows hold {present} cells, not the {len(rows) * columns} "
                            f"its header's {markers} markers need; the header or the rows are damaged.")


def text_table(path, rows: list[tuple[int, list[str]]], columns: list[int]) -> np.ndarray:
    """(rows, columns) numbers of the given columns of a text take's (line number, cells) rows (TRC, marker CSV):
    empty or absent cells and NaN in any spelling are missing samples (NaN). A cell that is not a number, or that
    is infinite (``inf``, ``-inf``, ``1e999``: no position, and no spelling of a gap either), is refused in one
    sentence naming the line."""
    out = np.full((len(rows), len(columns)), np.nan)
    for i, (line_no, r) in enumerate(rows):
        try:
            out[i] = [float(r[c]) if c < len(r) and r[c] else np.nan for c in columns]
        except ValueError:
            raise RigInputError(f"{path}: line {line_no} has a cell that is not a number.") from None
        if np.isinf(out[i]).any():
            cell = r[columns[int(np.argmax(np.isinf(out[i])))]]
            raise RigInputError(f"{path}: line {line_no} has an infinite number ('{shown(cell, 20)}'); a missing "
                                "sample is an empty cell.")
    return out


_UNIT_WORDS = {"mm": ("millimeters", "millimetres"), "cm": ("centimeters", "centimetres"), "m": ("meters", "metres")}


def units_from_text(text: str) -> str | None:
    """'mm', 'cm' or 'm' from how files spell a length unit: 'mm', 'Millimeters', 'metres', NUL-padded
    'mm\\0\\0', or cut short ('mete', 'milli'); None if the text names no length unit."""
    word = str(text).replace("\x00", " ").strip().lower().rstrip(".")
    if word in _UNIT_WORDS:
        return word
    if len(word) >= 3:
        for unit, spellings in _UNIT_WORDS.items():
            if any(s.startswith(word) for s in spellings):
                return unit
    return None


def unique_labels(labels: list[str], where: str) -> tuple[list[str], str | None]:
    """Labels made unique: a repeated label's later copies become LABEL_2, LABEL_3, ... (never clashing
    with another label). Returns the labels and a warning sentence, or None if all were unique."""
    labels = [str(s) for s in labels]
    taken = set(labels)
    seen: dict[str, int] = {}
    out, renamed = [], []
    for s in labels:
        seen[s] = seen.get(s, 0) + 1
        if seen[s] == 1:
            out.append(s)
            continue
        k = seen[s]
        while f"{s}_{k}" in taken:
            k += 1
        new = f"{s}_{k}"
        taken.add(new)
        out.append(new)
        renamed.append(f"{s or repr(s)} -> {new}")
    if not renamed:
        return out, None
    shown = ", ".join(renamed[:6]) + (f" and {len(renamed) - 6} more" if len(renamed) > 6 else "")
    what = "repeated marker label was" if len(renamed) == 1 else "repeated marker labels were"
    return out, f"{where}: {len(renamed)} {what} made unique ({shown})."


def take_summary(take: MarkerTake | WeightTake) -> dict:
    """What a take holds, as the readers see it (``take-info --json``): frames, rate, units, labels, missing
    samples per label, the coordinates' bounds per axis, how many points the reader left out as model outputs
    (computed angles, forces, ... that a C3D stores as points: not markers) and the readers' warnings."""
    if isinstance(take, MarkerTake):
        miss = take.missing
        seen = take.positions[~miss]
        bounds = ({"min": seen.min(axis=0).round(6).tolist(), "max": seen.max(axis=0).round(6).tolist()}
                  if seen.size else None)
        return {"path": take.source, "kind": "markers", "frames": take.n_frames, "rate": take.rate,
                "units": take.units, "labels": list(take.labels),
                "missing": {label: int(n) for label, n in zip(take.labels, miss.sum(axis=0))},
                "bounds": bounds, "first_frame": take.first_frame, "model_outputs_left_out": len(take.model_outputs),
                "warnings": list(take.warnings)}
    filled = take.filled if take.filled is not None else np.zeros(take.n_frames, dtype=bool)
    return {"path": take.source, "kind": "weights", "format": take.file_format, "frames": take.n_frames,
            "rate": take.rate, "units": None,
            "labels": list(take.names), "missing": {}, "bounds": None, "dropped_frames": int(filled.sum()),
            "warnings": list(take.warnings)}
