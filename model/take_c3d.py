"""C3D reader (and a minimal writer) with numpy.

The C3D layout (c3d.org, "The C3D File Format User Guide"): a 512-byte header block, a parameter section
of groups and parameters, then the 3D point data. Each frame stores, per point, X, Y, Z and a fourth
word whose low byte is the residual and high byte the camera mask; a negative residual marks a missing
sample (read as NaN here). Points are int16 scaled by POINT:SCALE, or float32 when the scale is negative.
Analog samples that follow each frame are skipped. Byte order from the processor type: 84 Intel
(little endian), 85 DEC (little endian words, VAX floats), 86 MIPS/SGI (big endian).

Real files bend the standard: the header and the parameters may disagree about where the data starts, how
many points and frames there are and how many analog samples follow each frame (some writers put the
analog layout only in the ANALOG group, others leave the parameters zero). The reader therefore derives the
frame layout from the parameters, cross-checks it with the header and the file size, and takes the reading
whose frames fill the data exactly (parameters first, the header where they do not fit); a file that ends
early is read to its last whole frame. Every decision that changes what a plain reading would give is a
sentence in ``MarkerTake.warnings``; a file no layout fits is refused in one sentence. Where POINT:SCALE and the
header's scale disagree in an integer file, the header's is used (as BTK does), with a warning. Points that are
model outputs rather than markers (the labels POINT:ANGLES, FORCES, MOMENTS, POWERS, SCALARS and REACTIONS list)
are left out, the markers keeping their order; ``MarkerTake.model_outputs`` names them. The own reader is kept
rather than ezc3d: it also reads SGI/MIPS files, which ezc3d 1.7 refuses.
"""
from __future__ import annotations

import itertools
import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import RigInputError
from .input_files import read_input_bytes
from .rig import UNIT_IN_METRES
from .take_data import MarkerTake, unique_labels, units_from_text

BLOCK = 512
SHORT_FILE_FRACTION = 0.5   # a short file holding less than this share of its declared frames is refused
# No optical capture volume is a kilometre across: points spreading further (in the file's own units) were sized by
# damaged parameters (an integer file's POINT:SCALE, POINT:UNITS) or read from damaged data. The 77 real files of
# ../shared/data/thirdparty span at most 8.7 m (a Codamotion gait-wand trial).
MAX_SPAN_METRES = 1000.0
_TYPES = {-1: 1, 1: 1, 2: 2, 4: 4}   # parameter data type -> bytes per element


def _vax_to_ieee(raw: np.ndarray) -> np.ndarray:
    """DEC (VAX F) floats, 4 bytes each as two little-endian 16-bit words -> float32 (swap words, / 4)."""
    u = np.ascontiguousarray(raw, dtype=np.uint8).reshape(-1, 4).view("<u2").astype(np.uint32)
    bits = ((u[:, 0] << 16) | u[:, 1]).astype("<u4")
    with np.errstate(invalid="ignore", over="ignore"):   # damaged words decode to NaN/inf, read as missing
        return bits.view("<f4") / np.float32(4.0)


def _text(raw: bytes) -> str:
    """A C3D string: NUL padding and surrounding spaces removed."""
    return raw.decode("latin-1").replace("\x00", " ").strip()


class _Params:
    """The parameter section: {GROUP: {PARAM: (type, dims, bytes)}}, read defensively.

    Every declared size is checked against the bytes that are there before anything is sliced; a "next
    entry" offset that points backwards or out of the file ends the section (with a warning) instead of
    looping; a parameter whose group or type is unknown, or whose data runs past the file, is skipped.
    """

    def __init__(self, data: bytes, start: int, path: Path, warnings: list[str]) -> None:
        self.path = path
        if len(data) < start + 4:
            raise RigInputError(f"{path}: the C3D file is truncated before its parameter section.")
        self.n_blocks, proc = data[start + 2], data[start + 3]
        if proc not in (84, 85, 86):
            raise RigInputError(f"{path}: unknown C3D processor type {proc} (expected 84, 85 or 86).")
        self.processor = proc
        self.endian = ">" if proc == 86 else "<"
        groups: dict[int, str] = {}
        raw: dict[tuple[int, str], tuple[int, tuple, bytes]] = {}
        # The section ends where the header says the data starts (word 9): some writers declare fewer
        # parameter blocks than they fill, others more, so that the last entry runs on into the frames
        # without an end marker. Without that the declared blocks bound it, and without those the file's end.
        e = self.endian
        data_start = (struct.unpack_from(e + "H", data, 16)[0] - 1) * BLOCK
        end = data_start if data_start > start + 4 else start + self.n_blocks * BLOCK
        end = min(len(data), end) if end > start + 4 else len(data)
        pos = start + 4
        while pos + 4 <= end:
            name_len = abs(struct.unpack_from("b", data, pos)[0])
            gid = struct.unpack_from("b", data, pos + 1)[0]
            p = pos + 2 + name_len
            if name_len == 0 or gid == 0 or p + 2 > end:
                break
            name = data[pos + 2:p].decode("latin-1")
            if not (name.isascii() and name.isprintable()):
                break   # bytes after the last entry, not a parameter
            name = name.strip().upper()
            offset = struct.unpack_from(e + "h", data, p)[0]
            body = p + 2
            if gid < 0:
                groups.setdefault(-gid, name)
            elif body + 2 <= end:
                dtype, ndim = struct.unpack_from("b", data, body)[0], data[body + 1]
                dims = tuple(data[body + 2:body + 2 + ndim])
                size = _TYPES.get(dtype, 0) * math.prod(dims)   # exact: 8 dims of 255 wrap int64 (to 0 for 10 of 128)
                vstart = body + 2 + ndim
                if dtype in _TYPES and len(dims) == ndim and vstart + size <= end:
                    raw.setdefault((gid, name), (dtype, dims, data[vstart:vstart + size]))
            if offset == 0:
                break
            if offset < 2:   # the next entry would start inside this one: a loop, not a section
                warnings.append(f"{path}: the entry after parameter {name} points backwards; "
                                "the parameter section was read up to it.")
                break
            pos = p + offset
        self.by_group: dict[str, dict[str, tuple]] = {}
        for (gid, name), v in raw.items():
            self.by_group.setdefault(groups.get(gid, str(gid)), {}).setdefault(name, v)

    def array(self, group: str, name: str) -> np.ndarray | None:
        """A numeric parameter as a flat float64 array (None if absent or not numeric)."""
        v = self.by_group.get(group, {}).get(name)
        if v is None or v[0] == -1:
            return None
        dtype, _, raw = v
        if dtype == 1:
            arr = np.frombuffer(raw, dtype=np.int8)
        elif dtype == 2:
            arr = np.frombuffer(raw, dtype=self.endian + "i2")
        elif self.processor == 85:
            arr = _vax_to_ieee(np.frombuffer(raw, dtype=np.uint8))
        else:
            arr = np.frombuffer(raw, dtype=self.endian + "f4")
        return arr.astype(np.float64)

    def number(self, group: str, name: str, *, unsigned: bool = False) -> float | None:
        """The first value of a numeric parameter (a scalar or a one-element array), None if absent/empty.
        ``unsigned`` reads a 16-bit integer as 0..65535 (counts past 32,767)."""
        v = self.by_group.get(group, {}).get(name)
        arr = self.array(group, name)
        if arr is None or arr.size == 0 or not np.isfinite(arr[0]):
            return None
        if unsigned and v[0] == 2:
            return float(int(arr[0]) % 65536)
        return float(arr[0])

    def strings(self, group: str, name: str) -> list[str] | None:
        """A character parameter as a list of strings (one for a plain string), None if absent."""
        v = self.by_group.get(group, {}).get(name)
        if v is None or v[0] != -1:
            return None
        _, dims, raw = v
        if len(dims) <= 1:
            return [_text(raw)]
        n = dims[0]
        return [_text(raw[i:i + n]) for i in range(0, len(raw), n)] if n else []

    def labels(self, name: str = "LABELS") -> list[str]:
        """POINT:LABELS, then LABELS2, LABELS3, ... (writers split more than 255 labels that way); the same for
        another list of point labels (``name`` ANGLES: POINT:ANGLES, ANGLES2, ...)."""
        out = list(self.strings("POINT", name) or [])
        k = 2
        while (more := self.strings("POINT", f"{name}{k}")) is not None:
            out += more
            k += 1
        return out


@dataclass(frozen=True)
class _Layout:
    """One way to read the data: where it starts and what one frame holds."""

    points: int
    analog_words: int       # analog samples (all channels) stored after each frame's points
    is_float: bool
    start_block: int        # 1-based block of the first frame
    frames: int             # frames declared

    @property
    def frame_bytes(self) -> int:
        return (4 * self.points + self.analog_words) * (4 if self.is_float else 2)

    def whole_frames(self, size: int) -> int:
        return max(0, (size - (self.start_block - 1) * BLOCK) // self.frame_bytes) if self.frame_bytes else 0

    def leftover(self, size: int) -> int:
        """Bytes after the declared frames (negative when the file is short)."""
        return size - (self.start_block - 1) * BLOCK - self.frames * self.frame_bytes


def _header(data: bytes, params: _Params) -> dict:
    e = params.endian
    hu = np.frombuffer(data[:BLOCK], dtype=e + "u2")
    if params.processor == 85:
        scale, rate = (float(x) for x in _vax_to_ieee(np.frombuffer(data[12:16] + data[20:24], dtype=np.uint8)))
    else:
        scale, rate = struct.unpack_from(e + "f", data, 12)[0], struct.unpack_from(e + "f", data, 20)[0]
    first, last = int(hu[3]), int(hu[4])
    return {"points": int(hu[1]), "analog_words": int(hu[2]), "first": first,
            "frames": last - first + 1 if last >= first else None, "start": int(hu[8]),
            "scale": scale if np.isfinite(scale) else None, "rate": rate if np.isfinite(rate) and rate > 0 else None}


def _declared_frames(params: _Params) -> int | None:
    """POINT:FRAMES, read unsigned (writers store 32,768..65,535 that way); when it is saturated at 65,535
    the 32-bit TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD (two 16-bit words each, low word first) count."""
    n = params.number("POINT", "FRAMES", unsigned=True)
    start, end = params.array("TRIAL", "ACTUAL_START_FIELD"), params.array("TRIAL", "ACTUAL_END_FIELD")
    if (n is None or n >= 65535) and start is not None and end is not None and start.size == 2 and end.size == 2:
        def value(words) -> int:
            low, high = (int(w) % 65536 for w in words)
            return low + 65536 * high
        trial = value(end) - value(start) + 1
        if trial > 0:
            return trial
    return int(n) if n is not None else None


def _param_analog_words(params: _Params, point_rate: float | None) -> list[int]:
    """Analog samples per 3D frame from ANALOG:USED and ANALOG:RATE / POINT:RATE: one value when the ratio
    is whole; when it is not, both whole numbers around it (writers differ in which they store)."""
    used = params.number("ANALOG", "USED", unsigned=True)
    if used is None:
        return []
    if used == 0:
        return [0]
    arate = params.number("ANALOG", "RATE")
    if not (arate and point_rate and arate > 0):
        return []
    ratio = arate / point_rate
    if abs(ratio - round(ratio)) < 1e-3:
        return [int(used) * round(ratio)] if round(ratio) >= 1 else []
    return [int(used) * k for k in (int(np.floor(ratio)), int(np.ceil(ratio))) if k >= 1]


def _points(data: bytes, lay: _Layout, params: _Params, frames: int, scale: float) -> np.ndarray:
    """(frames, points, 3) coordinates of the first ``frames`` frames of a layout; NaN where missing."""
    F, M, e = frames, lay.points, params.endian
    word = 4 if lay.is_float else 2
    raw = np.frombuffer(data, dtype=np.uint8, count=F * lay.frame_bytes,
                        offset=(lay.start_block - 1) * BLOCK).reshape(F, lay.frame_bytes)
    pts = raw[:, :M * 4 * word]
    with np.errstate(invalid="ignore", over="ignore"):   # NaN/inf bytes are missing samples, not news
        return _decode(pts, F, M, e, lay.is_float, params.processor == 85, scale)


def _decode(pts: np.ndarray, F: int, M: int, e: str, is_float: bool, vax: bool, scale: float) -> np.ndarray:
    """Points of (F, M * 4) words: int16 times |scale| or float32 (VAX floats on DEC); NaN where missing."""
    if is_float:
        vals = _vax_to_ieee(pts).reshape(F, M, 4) if vax else np.ascontiguousarray(pts).view(e + "f4").reshape(F, M, 4)
        xyz = vals[..., :3].astype(np.float64)
    else:
        vals = np.ascontiguousarray(pts).view(e + "i2").reshape(F, M, 4)
        xyz = vals[..., :3].astype(np.float64) * abs(scale)
    # The fourth word holds (camera mask << 8 | residual); negative = missing (as a float in float files).
    xyz[vals[..., 3] < 0] = np.nan
    xyz[~np.isfinite(xyz).all(axis=2)] = np.nan
    return xyz


def _coherence(xyz: np.ndarray) -> float:
    """How much the points behave like markers: the share of samples that lie nearer to the same marker in
    the frame before than to its neighbour in the list in that frame. Trajectories score near 1; bytes read
    with a wrong layout (points shifted between frames, analog words taken for points) score near 1/2 or
    less. Scale-free and robust to outliers. NaN when there are too few samples to tell."""
    if xyz.shape[1] < 2:
        return float("nan")
    xyz = np.where((xyz == 0).all(axis=-1, keepdims=True), np.nan, xyz)   # (0, 0, 0): unseen, in many writers
    own = np.linalg.norm(xyz[1:] - xyz[:-1], axis=-1)
    other = np.linalg.norm(xyz[1:] - np.roll(xyz[:-1], 1, axis=1), axis=-1)
    ok = np.isfinite(own) & np.isfinite(other)
    if ok.sum() < 30:
        return float("nan")
    return float(np.mean(own[ok] <= other[ok]))


_SCORED_FRAMES = 240


_PARAMETER_NAMES = {"points": "POINT:USED", "analog_words": "the ANALOG group (USED x RATE / POINT:RATE)",
                    "is_float": "POINT:SCALE's sign", "start_block": "POINT:DATA_START", "frames": "POINT:FRAMES"}


def _choose_layout(data: bytes, params: _Params, hdr: dict, path: Path, pblock: int,
                   warnings: list[str]) -> _Layout:
    """The consistent reading: the declared frames are in the file, the points form trajectories rather
    than noise, the parameters' values are preferred to the header's, and the data ends where the file does."""
    size = len(data)
    rate = params.number("POINT", "RATE") or None
    rate = rate if rate and rate > 0 else hdr["rate"]
    scale_p = params.number("POINT", "SCALE")
    declared = {   # what the parameters say (None or [] where they say nothing)
        "points": params.number("POINT", "USED", unsigned=True),
        "analog_words": _param_analog_words(params, rate),
        "is_float": None if not scale_p else scale_p < 0,
        "start_block": params.number("POINT", "DATA_START", unsigned=True),
        "frames": _declared_frames(params),
    }
    from_header = {"points": hdr["points"], "analog_words": hdr["analog_words"],
                   "is_float": None if not hdr["scale"] else hdr["scale"] < 0,
                   "start_block": hdr["start"], "frames": hdr["frames"]}
    valid = {
        "points": lambda v: v > 0, "analog_words": lambda v: v >= 0, "is_float": lambda v: True,
        "start_block": lambda v: pblock < v and (v - 1) * BLOCK < size, "frames": lambda v: v > 0,
    }
    said = {k: [v if isinstance(v, bool) else int(v)
                for v in (declared[k] if isinstance(declared[k], list) else [declared[k]]) if v is not None]
            for k in declared}
    choices = {}
    for key in declared:
        values = [v for v in said[key] + [from_header[key]] if v is not None and valid[key](v)]
        choices[key] = list(dict.fromkeys(bool(v) if key == "is_float" else int(v) for v in values))
    if not choices["points"]:
        raise RigInputError(f"{path}: holds no 3D points (POINT:USED and the header say 0 markers), only analog data.")
    choices["is_float"] = choices["is_float"] or [False]
    choices["analog_words"] = choices["analog_words"] or [0]
    for key in ("start_block", "frames"):
        if not choices[key]:
            what = "where the data starts" if key == "start_block" else "how many frames there are"
            raise RigInputError(f"{path}: neither the header nor the parameters say {what}.")

    def deviations(lay: _Layout) -> list[str]:   # where the reading departs from what the parameters say
        return [k for k in declared if said[k] and getattr(lay, k) not in said[k]]

    readable = []   # (layout, frames the file holds for it)
    for combo in itertools.product(*choices.values()):
        lay = _Layout(*combo)
        held = lay.frames if lay.leftover(size) >= 0 else lay.whole_frames(size)
        if held > 0:
            readable.append((lay, held))
    if not readable:
        raise RigInputError(f"{path}: the C3D file is truncated: it ends before its first whole frame.")
    coherence = {lay: _coherence(_points(data, lay, params, min(held, _SCORED_FRAMES), 1.0)) for lay, held in readable}
    finite = [c for c in coherence.values() if np.isfinite(c)]

    def rank(item):
        lay, held = item
        c = coherence[lay]
        noise = bool(finite) and not (np.isfinite(c) and c >= max(finite) - 0.1)
        left = lay.leftover(size)
        return (noise, held < lay.frames, left > max(BLOCK, lay.frame_bytes), len(deviations(lay)), abs(left))

    best, held = min(readable, key=rank)
    if held < SHORT_FILE_FRACTION * best.frames:
        raise RigInputError(f"{path}: the C3D file is truncated: {best.frames} frames declared "
                            f"but only {held} complete {'frame is' if held == 1 else 'frames are'} present.")
    for key in deviations(best):
        shown = " or ".join(str(v) for v in said[key])
        warnings.append(f"{path}: {_PARAMETER_NAMES[key]} says {shown}, which does not fit the data; "
                        f"the header's {getattr(best, key)} does and was used.")
    arate, used = params.number("ANALOG", "RATE"), params.number("ANALOG", "USED", unsigned=True)
    if used and arate and rate and abs(arate / rate - round(arate / rate)) >= 1e-3:
        warnings.append(f"{path}: ANALOG:RATE ({arate:g}) is not a whole multiple of the frame rate ({rate:g}); "
                        f"{best.analog_words} analog samples per frame fit the data and were used.")
    left = best.leftover(size)
    if held < best.frames:
        warnings.append(f"{path}: the file ends early: {best.frames} frames declared but {held} whole frames "
                        "present; read to the last whole frame.")
        best = _Layout(best.points, best.analog_words, best.is_float, best.start_block, held)
    elif left > max(BLOCK, best.frame_bytes):
        warnings.append(f"{path}: {left} bytes follow the {best.frames} frames the file declares; "
                        "they were not read.")
    return best


# POINT parameters in which Vicon Nexus / Plug-in Gait (and pyCGM2) list the points that are model outputs: joint
# angles, forces, moments, powers, scalars and ground reactions stored as points beside the markers, in degrees,
# newtons, newton-millimetres or watts (POINT:ANGLE_UNITS, FORCE_UNITS, ...), not positions.
MODEL_OUTPUTS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")


def _model_outputs(params: _Params, labels: list[str], path: Path) -> tuple[np.ndarray, str | None]:
    """Which of the points (by their labels in file order) are markers, and the sentence that says which points
    were left out as model outputs (None if none were)."""
    keep = np.ones(len(labels), dtype=bool)
    counts = []
    for name in MODEL_OUTPUTS:
        listed = {s for s in params.labels(name) if s}
        hit = keep & np.array([s in listed for s in labels], dtype=bool)
        if hit.any():
            keep &= ~hit
            counts.append(f"POINT:{name} ({int(hit.sum())})")
    if not counts:
        return keep, None
    if not keep.any():
        raise RigInputError(f"{path}: holds no markers: all {len(labels)} points are model outputs (listed in "
                            f"{', '.join(counts)}), not positions.")
    listed = ", ".join(counts[:-1]) + " and " + counts[-1] if len(counts) > 1 else counts[0]
    n = int((~keep).sum())
    return keep, (f"{path}: {n} of the {len(labels)} points are model outputs listed in {listed}, computed values "
                  f"rather than marker positions; they were left out and the other {int(keep.sum())} read as markers.")


def read_c3d(path: str | Path) -> MarkerTake:
    """Read the 3D points of a C3D file into a MarkerTake (NaN where the residual is negative, and where a sample
    is exactly (0, 0, 0): many writers mark a gap so, and a marker is never exactly at the origin)."""
    path = Path(path)
    data = read_input_bytes(path)
    if len(data) < BLOCK or data[1] != 0x50:
        raise RigInputError(f"{path}: is not a C3D file (no C3D header).")
    warnings: list[str] = []
    pblock = data[0] if data[0] >= 2 else 2
    params = _Params(data, (pblock - 1) * BLOCK, path, warnings)
    hdr = _header(data, params)
    lay = _choose_layout(data, params, hdr, path, pblock, warnings)

    rate = params.number("POINT", "RATE")
    if not (rate and rate > 0):
        rate = hdr["rate"]
        if rate is None:
            raise RigInputError(f"{path}: has no frame rate (POINT:RATE and the header's rate are not positive).")
        if params.number("POINT", "RATE") is not None:
            warnings.append(f"{path}: POINT:RATE is not positive; the header's rate ({rate:g}) was used.")
    scale = params.number("POINT", "SCALE") or hdr["scale"] or 1.0
    if not lay.is_float and hdr["scale"] and abs(abs(scale) - abs(hdr["scale"])) > 1e-5 * abs(scale):
        # Integer points: the scale sizes every coordinate. The header's is kept, as BTK (Mokka) keeps it: on the one
        # such file we know (a Motion Analysis gait trial), it gives an adult walking (1.46 m shoulders, 1.3 m
        # strides at 1.2 m/s), POINT:SCALE a 0.57 m tall figure taking 0.5 m strides at the same cadence.
        ratio = abs(hdr["scale"]) / abs(scale)
        warnings.append(f"{path}: POINT:SCALE ({abs(scale):.6g}) and the header's scale ({abs(hdr['scale']):.6g}) "
                        f"disagree; the header's was used (POINT:SCALE would make every coordinate "
                        f"{ratio if ratio > 1 else 1 / ratio:.3g} times {'smaller' if ratio > 1 else 'larger'}).")
        scale = hdr["scale"]
    labels = params.labels()[:lay.points]
    if len(labels) < lay.points:
        warnings.append(f"{path}: POINT:LABELS names {len(labels)} of the {lay.points} points; the others "
                        f"were named M{len(labels):02d}..M{lay.points - 1:02d}.")
    labels += [f"M{i:02d}" for i in range(len(labels), lay.points)]
    markers, left_out = _model_outputs(params, labels, path)
    if left_out:
        warnings.append(left_out)
    model_outputs = [s for s, marker in zip(labels, markers) if not marker]
    labels = [s for s, marker in zip(labels, markers) if marker]
    labels, renamed = unique_labels(labels, str(path))
    if renamed:
        warnings.append(renamed)
    units_text = params.strings("POINT", "UNITS")
    units = units_from_text(units_text[0]) if units_text else None
    if units is None:
        given = (units_text or [""])[0]
        if given:
            raise RigInputError(f"{path}: unknown units '{given}' in POINT:UNITS (use mm, cm or m).")
        units = "mm"
        warnings.append(f"{path}: POINT:UNITS is {'empty' if units_text else 'missing'}; read as millimetres, "
                        "the C3D default.")

    xyz = _points(data, lay, params, lay.frames, scale)[:, markers]
    origin = (xyz == 0.0).all(axis=2)
    if origin.any():    # a gap, as many writers mark one (residual 0, not negative), not a marker at the origin
        xyz[origin] = np.nan
        warnings.append(f"{path}: {int(origin.sum())} samples at exactly (0, 0, 0) were read as missing, the way "
                        "many writers mark a gap.")
    _check_span(xyz, units, scale, lay.is_float, path)
    return MarkerTake(positions=xyz, labels=labels, rate=float(rate), units=units, source=str(path),
                      first_frame=hdr["first"], warnings=warnings, model_outputs=model_outputs)


def _check_span(xyz: np.ndarray, units: str, scale: float, is_float: bool, path: Path) -> None:
    """Refuse points (F, M, 3), NaN where missing, in ``units`` spreading more than ``MAX_SPAN_METRES`` on an axis:
    no capture volume is that large (coordinates under the ±1e9 a take may hold otherwise loaded as a marker
    take kilometres wide)."""
    seen = xyz[np.isfinite(xyz).all(axis=2)]
    if not seen.size:
        return
    span = float((seen.max(axis=0) - seen.min(axis=0)).max())
    if span * UNIT_IN_METRES[units] > MAX_SPAN_METRES:
        sized = "its float points" if is_float else f"its integer points at POINT:SCALE {abs(scale):.6g}"
        raise RigInputError(f"{path}: its markers spread over {span:.4g} {units} ({sized}), "
                            f"{span * UNIT_IN_METRES[units] / 1000:.3g} km: no capture volume is that large, so its "
                            "scale, units or point data are damaged.")


# --- writer --------------------------------------------------------------------------------------
def _param(gid: int, name: str, dtype: int, dims: tuple, payload: bytes) -> bytes:
    nm = name.encode("latin-1")
    body = struct.pack("<bB", dtype, len(dims)) + bytes(dims) + payload + b"\x00"
    return struct.pack("<bb", len(nm), gid) + nm + struct.pack("<h", len(body) + 2) + body


def _group(gid: int, name: str) -> bytes:
    nm = name.encode("latin-1")
    return struct.pack("<bb", len(nm), -gid) + nm + struct.pack("<h", 3) + b"\x00"


def write_c3d(path: str | Path, take: MarkerTake, *, integer: bool = False, scale: float = 0.01) -> None:
    """Write a MarkerTake as an Intel C3D (float32 points, or int16 points times ``scale`` if ``integer``).

    Missing samples (NaN) are written with residual -1. Labels are at most 255 characters wide.
    """
    from .atomic import atomic_write
    F, M, _ = take.positions.shape
    width = max([len(s) for s in take.labels] + [1])
    pscale = abs(scale) if integer else -abs(scale)
    labels = b"".join(s.encode("latin-1").ljust(width) for s in take.labels)
    units = take.units.encode("latin-1")
    plist = [
        _group(1, "POINT"),
        _param(1, "USED", 2, (), struct.pack("<h", M)),
        _param(1, "FRAMES", 2, (), struct.pack("<H", min(F, 65535))),  # unsigned past 32,767, as readers expect
        _param(1, "SCALE", 4, (), struct.pack("<f", pscale)),
        _param(1, "RATE", 4, (), struct.pack("<f", take.rate)),
        _param(1, "UNITS", -1, (len(units),), units),
        _param(1, "LABELS", -1, (width, M), labels),
    ]
    if F > 65535:  # the 32-bit frame range (low word first) where 16 bits cannot hold the count
        plist += [_group(2, "TRIAL"),
                  _param(2, "ACTUAL_START_FIELD", 2, (2,), struct.pack("<HH", 1, 0)),
                  _param(2, "ACTUAL_END_FIELD", 2, (2,), struct.pack("<HH", F % 65536, F // 65536))]
    body = b"".join(plist)
    n_pblocks = (4 + len(body) + 2 + 6 + BLOCK - 1) // BLOCK  # room for DATA_START
    data_start = 2 + n_pblocks
    body += _param(1, "DATA_START", 2, (), struct.pack("<h", data_start))
    last = struct.pack("<bb", 0, 0)
    psec = (bytes([1, 80, n_pblocks, 84]) + body + last).ljust(n_pblocks * BLOCK, b"\x00")
    header = np.zeros(256, dtype="<u2")
    header[0] = 0x5002
    header[1], header[2], header[3], header[4], header[5] = M, 0, 1, min(F, 65535), 10
    hb = bytearray(header.tobytes())
    hb[12:16] = struct.pack("<f", pscale)
    hb[16:18] = struct.pack("<h", data_start)
    hb[20:24] = struct.pack("<f", take.rate)
    pos = take.positions
    miss = ~np.isfinite(pos).all(axis=2)
    if integer:
        out = np.zeros((F, M, 4), dtype="<i2")
        out[..., :3] = np.round(np.nan_to_num(pos) / abs(scale)).astype(np.int64).clip(-32768, 32767)
        out[..., 3] = np.where(miss, -1, 0)
    else:
        out = np.zeros((F, M, 4), dtype="<f4")
        out[..., :3] = np.nan_to_num(pos)
        out[..., 3] = np.where(miss, -1.0, 0.0)
    atomic_write(path, bytes(hb) + psec + out.tobytes())
