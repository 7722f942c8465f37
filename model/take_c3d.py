"""C3D reader (and a minimal writer) with numpy.

The C3D layout (c3d.org, "The C3D File Format User Guide"): a 512-byte header block, a parameter section
of groups and parameters, then the 3D point data. Each frame stores, per point, X, Y, Z and a fourth
word whose low byte is the residual and high byte the camera mask; a negative residual marks a missing
sample (read as NaN here). Points are int16 scaled by POINT:SCALE, or float32 when the scale is negative.
Analog samples that follow each frame are skipped. Byte order from the processor type: 84 Intel
(little endian), 85 DEC (little endian words, VAX floats), 86 MIPS/SGI (big endian).
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from .errors import RigInputError
from .takes import MarkerTake

BLOCK = 512
_UNITS = {"mm": "mm", "millimeter": "mm", "millimeters": "mm", "millimetre": "mm", "millimetres": "mm",
          "cm": "cm", "centimeter": "cm", "centimeters": "cm", "m": "m", "meter": "m", "meters": "m",
          "metre": "m", "metres": "m"}


def _vax_to_ieee(raw: np.ndarray) -> np.ndarray:
    """DEC (VAX F) floats, 4 bytes each as two little-endian 16-bit words -> float32 (swap words, / 4)."""
    u = np.ascontiguousarray(raw, dtype=np.uint8).reshape(-1, 4).view("<u2").astype(np.uint32)
    bits = ((u[:, 0] << 16) | u[:, 1]).astype("<u4")
    return bits.view("<f4") / np.float32(4.0)


class _Params:
    """The parameter section: {GROUP: {PARAM: value}}."""

    def __init__(self, data: bytes, start: int, path: Path) -> None:
        self.path = path
        if len(data) < start + 4:
            raise RigInputError(f"{path}: the C3D file is truncated before its parameter section.")
        n_blocks, proc = data[start + 2], data[start + 3]
        if proc not in (84, 85, 86):
            raise RigInputError(f"{path}: unknown C3D processor type {proc} (expected 84, 85 or 86).")
        self.processor = proc
        self.endian = ">" if proc == 86 else "<"
        end = min(len(data), start + max(n_blocks, 1) * BLOCK)
        self.groups: dict[int, str] = {}
        self.raw: dict[tuple[int, str], tuple[int, tuple, bytes]] = {}
        pos = start + 4
        e = self.endian
        while pos + 2 <= end:
            name_len = abs(struct.unpack("b", data[pos:pos + 1])[0])
            gid = struct.unpack("b", data[pos + 1:pos + 2])[0]
            if name_len == 0 or gid == 0:
                break
            name = data[pos + 2:pos + 2 + name_len].decode("latin-1").upper()
            p = pos + 2 + name_len
            if p + 2 > len(data):
                raise RigInputError(f"{path}: the C3D parameter section is truncated.")
            offset = struct.unpack(e + "h", data[p:p + 2])[0]
            body = p + 2
            if gid < 0:
                self.groups[-gid] = name
            else:
                dtype = struct.unpack("b", data[body:body + 1])[0]
                ndim = data[body + 1]
                dims = tuple(data[body + 2:body + 2 + ndim])
                size = abs(dtype) * int(np.prod(dims)) if ndim else abs(dtype)
                vstart = body + 2 + ndim
                if vstart + size > len(data):
                    raise RigInputError(f"{path}: the C3D parameter section is truncated (parameter {name}).")
                self.raw[(gid, name)] = (dtype, dims, data[vstart:vstart + size])
            if offset == 0:
                break
            pos = p + offset
        self.by_group: dict[str, dict[str, tuple]] = {}
        for (gid, name), v in self.raw.items():
            self.by_group.setdefault(self.groups.get(gid, str(gid)), {})[name] = v

    def get(self, group: str, name: str, default=None):
        v = self.by_group.get(group, {}).get(name)
        if v is None:
            return default
        dtype, dims, raw = v
        e = self.endian
        if dtype == -1:  # characters: dims[0] is the string length
            if not dims:
                return raw.decode("latin-1").strip()
            n = dims[0]
            strings = [raw[i:i + n].decode("latin-1").strip() for i in range(0, len(raw), n)] if n else []
            return strings if len(dims) > 1 else (strings[0] if strings else "")
        if dtype == 1:
            arr = np.frombuffer(raw, dtype=np.uint8)
        elif dtype == 2:
            arr = np.frombuffer(raw, dtype=e + "i2")
        elif dtype == 4:
            arr = _vax_to_ieee(np.frombuffer(raw, dtype=np.uint8)) if self.processor == 85 \
                else np.frombuffer(raw, dtype=e + "f4")
        else:
            raise RigInputError(f"{self.path}: parameter {group}:{name} has unknown data type {dtype}.")
        return arr.reshape(dims[::-1]) if len(dims) > 1 else (arr if dims else arr[0])


def _frame_count(params: _Params, first: int, last: int) -> int:
    """Frames in the file. POINT:FRAMES is a 16-bit word: past 32,767 frames writers store it unsigned (read
    back here as such), and past 65,535 the 32-bit TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD (two 16-bit
    words each, low word first) give the range."""
    frames = params.get("POINT", "FRAMES")
    n = int(frames) % 65536 if frames is not None else last - first + 1
    start, end = params.get("TRIAL", "ACTUAL_START_FIELD"), params.get("TRIAL", "ACTUAL_END_FIELD")
    if start is not None and end is not None and np.size(start) == 2 and np.size(end) == 2:
        def value(words) -> int:
            low, high = (int(w) % 65536 for w in np.asarray(words).ravel())
            return low + 65536 * high
        n = max(n, value(end) - value(start) + 1)
    return n


def read_c3d(path: str | Path) -> MarkerTake:
    """Read the 3D points of a C3D file into a MarkerTake (NaN where the residual is negative)."""
    path = Path(path)
    data = path.read_bytes()
    if not data:
        raise RigInputError(f"{path}: the file is empty.")
    if len(data) < BLOCK or data[1] != 0x50:
        raise RigInputError(f"{path}: is not a C3D file (no C3D header).")
    pstart = (data[0] - 1) * BLOCK
    params = _Params(data, pstart, path)
    e = params.endian
    h = np.frombuffer(data[:BLOCK], dtype=e + "i2")
    hu = np.frombuffer(data[:BLOCK], dtype=e + "u2")
    n_points = int(params.get("POINT", "USED", hu[1]))
    analog_per_frame = int(hu[2])
    first, last = int(hu[3]), int(hu[4])
    if params.processor == 85:
        hscale = float(_vax_to_ieee(np.frombuffer(data[12:16], dtype=np.uint8))[0])
        hrate = float(_vax_to_ieee(np.frombuffer(data[20:24], dtype=np.uint8))[0])
    else:
        hscale = float(np.frombuffer(data[12:16], dtype=e + "f4")[0])
        hrate = float(np.frombuffer(data[20:24], dtype=e + "f4")[0])
    scale = float(params.get("POINT", "SCALE", hscale))
    rate = float(params.get("POINT", "RATE", hrate))
    data_start = int(params.get("POINT", "DATA_START", h[8]))
    n_frames = _frame_count(params, first, last)
    if n_frames <= 0:
        raise RigInputError(f"{path}: the C3D file holds no frames.")
    labels = params.get("POINT", "LABELS", [])
    if isinstance(labels, str):
        labels = [labels]
    labels = list(labels)[:n_points]
    labels += [f"M{i:02d}" for i in range(len(labels), n_points)]
    units_raw = str(params.get("POINT", "UNITS", "mm") or "mm").strip().lower()
    if units_raw not in _UNITS:
        raise RigInputError(f"{path}: unknown units '{units_raw}' in POINT:UNITS (use mm, cm or m).")
    units = _UNITS[units_raw]
    is_float = scale < 0
    word = 4 if is_float else 2
    frame_bytes = n_points * 4 * word + analog_per_frame * word
    start = (data_start - 1) * BLOCK
    need = start + n_frames * frame_bytes
    if len(data) < need:
        got = max(0, (len(data) - start) // frame_bytes) if frame_bytes else 0
        raise RigInputError(f"{path}: the C3D file is truncated: {n_frames} frames declared "
                            f"but only {got} complete frames present.")
    raw = np.frombuffer(data[start:need], dtype=np.uint8).reshape(n_frames, frame_bytes)
    pts = raw[:, :n_points * 4 * word].reshape(n_frames, n_points, 4, word)
    if is_float:
        if params.processor == 85:
            vals = _vax_to_ieee(pts).reshape(n_frames, n_points, 4)
        else:
            vals = np.ascontiguousarray(pts).view(e + "f4").reshape(n_frames, n_points, 4)
        xyz = vals[..., :3].astype(np.float64)
        fourth = vals[..., 3]
        # The fourth float holds (camera mask << 8 | residual) as an integer; negative = missing.
        missing = fourth < 0
    else:
        vals = np.ascontiguousarray(pts).view(e + "i2").reshape(n_frames, n_points, 4)
        xyz = vals[..., :3].astype(np.float64) * abs(scale)
        missing = vals[..., 3] < 0
    xyz[missing] = np.nan
    return MarkerTake(positions=xyz, labels=labels, rate=rate, units=units, source=str(path), first_frame=first)


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
