"""Wavefront OBJ reading and writing that keeps vertex order.

We read ``v`` and ``f`` records ourselves, in file order. General mesh loaders (trimesh, pyvista)
split vertices at UV seams and material groups, which silently breaks blendshape correspondence
(DESIGN.md, Readers). Everything else in the file (vt, vn, usemtl, g, s) is ignored.
"""
from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import RigInputError
from .rig import CornerAttributes

# The start of a 'v' line and of any other line: finding the one run of consecutive "v x y z" lines
# this way is the fast path for files written by every DCC we know.
_V_NEXT = re.compile(rb"\nv[ \t]")
_NOT_V_NEXT = re.compile(rb"\n(?!v[ \t])")
_V_LINE = re.compile(rb"^v[ \t]+([^\n]*)", re.M)
_F_LINE = re.compile(rb"^f[ \t]+([^\n]*)", re.M)


_VT_LINE = re.compile(rb"^vt[ \t]+([^\n]*)", re.M)
_VN_LINE = re.compile(rb"^vn[ \t]+([^\n]*)", re.M)


@dataclass
class ObjMesh:
    vertices: np.ndarray        # (V, 3) float64
    face_counts: np.ndarray     # (F,) int32
    face_indices: np.ndarray    # (sum counts,) int32, 0-based
    face_section: bytes         # raw bytes from the first face record on, for fast equality checks
    corners: CornerAttributes | None = None  # vt/vn per corner and group records, when the file has them


def _read_bytes(path: Path) -> bytes:
    try:
        data = Path(path).read_bytes()
    except IsADirectoryError:
        raise RigInputError(f"{path}: is a folder, not an OBJ file.") from None
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror}).") from None
    if not data or data.isspace():      # (no copy of the file, unlike strip())
        raise RigInputError(f"{path}: the file is empty.")
    if b"\0" in data[:65536]:
        raise RigInputError(f"{path}: is a binary file, not a text OBJ.")
    try:
        if not data.isascii():    # ASCII is UTF-8: the check is one fast scan; only other text is decoded
            data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RigInputError(f"{path}: is not UTF-8 text (bad byte at offset {exc.start}).") from None
    return data


def _vertex_block(data: bytes) -> bytes | None:
    """The bytes of the one run of consecutive 'v' lines, or None when 'v' records are scattered."""
    start = 0 if data[:2] in (b"v ", b"v\t") else -1
    if start < 0:
        m = _V_NEXT.search(data)
        if m is None:
            return None
        start = m.start() + 1
    m = _NOT_V_NEXT.search(data, start)
    end = m.start() + 1 if m else len(data)
    if _V_NEXT.search(data, end - 1) is not None:
        return None  # more 'v' records later in the file
    return data[start:end]


def _parse_vertices(path: Path, data: bytes) -> np.ndarray:
    block = _vertex_block(data)
    if block is None and _V_NEXT.search(data) is None and data[:2] not in (b"v ", b"v\t"):
        raise RigInputError(f"{path}: has no vertex ('v') records.")
    verts = None
    if block is not None:
        try:
            verts = np.loadtxt(io.BytesIO(block), usecols=(1, 2, 3), dtype=np.float64, ndmin=2,
                               comments=None)
        except ValueError:
            verts = None  # ragged lines (colours on some, w on others): take the careful path
    if verts is None:
        rows = []
        for i, line in enumerate(_V_LINE.findall(data)):
            parts = line.split()
            if len(parts) < 3:
                raise RigInputError(f"{path}: vertex record {i + 1} has fewer than 3 coordinates "
                                    "(the file may be truncated).")
            try:
                rows.append([float(parts[0]), float(parts[1]), float(parts[2])])
            except ValueError:
                raise RigInputError(f"{path}: vertex record {i + 1} is not a number: "
                                    f"{line[:40].decode(errors='replace')!r}.") from None
        verts = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    bad = ~np.isfinite(verts).all(axis=1)
    if bad.any():
        raise RigInputError(f"{path}: vertex {int(np.argmax(bad))} has a NaN or infinite coordinate.")
    return verts


def _parse_faces(path: Path, data: bytes, n_vertices: int, records: list[bytes] | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    records = _F_LINE.findall(data) if records is None else records
    if not records:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    # Keep only the vertex index of each corner ("12/5/7" -> "12"), then parse all at once.
    text = re.sub(rb"/[^\s]*", b"", b"\n".join(records))
    lines = text.split(b"\n")
    counts = np.fromiter((len(l.split()) for l in lines), dtype=np.int32, count=len(lines))
    try:
        idx = _whole_numbers(text, int(counts.sum()))
    except ValueError:
        raise RigInputError(f"{path}: a face record has an index that is not a whole number.") from None
    if (counts < 3).any():
        raise RigInputError(f"{path}: face {int(np.argmax(counts < 3)) + 1} has fewer than 3 corners "
                            "(the file may be truncated).")
    # OBJ indices are 1-based; negative ones count back from the last vertex defined so far. We
    # resolve negatives against the total count, which is right for files that list all v first.
    idx = np.where(idx < 0, n_vertices + idx, idx - 1)
    if (idx < 0).any() or (idx >= n_vertices).any():
        raise RigInputError(f"{path}: a face refers to vertex {int(idx[(idx < 0) | (idx >= n_vertices)][0]) + 1}, "
                            f"but the file has {n_vertices} vertices (the file may be truncated).")
    return counts, idx.astype(np.int32)


def _parse_table(path: Path, data: bytes, line: re.Pattern, what: str, width: tuple[int, int]) -> np.ndarray | None:
    key = line.pattern[1:3]  # b"vt" or b"vn"
    if not (data.startswith(key) or b"\n" + key in data):
        return None
    rows = line.findall(data)
    if not rows:
        return None
    try:
        table = np.loadtxt(io.BytesIO(b"\n".join(rows)), dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        raise RigInputError(f"{path}: a {what} record is not a list of numbers.") from None
    if not width[0] <= table.shape[1] <= max(width):
        table = table[:, :width[1]] if table.shape[1] > width[1] else None
        if table is None:
            raise RigInputError(f"{path}: its {what} records have too few numbers.")
    return table


def _whole_numbers(text: bytes, expected: int) -> np.ndarray:
    """The whitespace-separated whole numbers of ``text`` (ValueError unless there are ``expected`` of them)."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # fromstring stops early on a bad token: counted below
        out = np.fromstring(text, dtype=np.int64, sep=" ")
    if out.size != expected:
        out = np.array(text.split(), dtype=np.int64)  # the careful way; raises ValueError on a bad token
        if out.size != expected:
            raise ValueError("unexpected number count")
    return out


def _corner_index(path: Path, idx: np.ndarray, n: int, what: str) -> np.ndarray:
    """0-based indices into a vt/vn list from OBJ's 1-based (or negative) ones; -1 where a corner has none."""
    out = np.where(idx < 0, n + idx, idx - 1)
    out[idx == 0] = -1
    bad = (out < -1) | (out >= n)
    if bad.any():
        raise RigInputError(f"{path}: a face refers to {what} {int(idx[bad][0])}, but the file has {n}.")
    return out.astype(np.int32)


def _corner_columns(path: Path, tokens: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """The vt and vn numbers (0 = none) of face corners written ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``."""
    n = len(tokens)
    text = b" ".join(tokens)
    k = tokens[0].count(b"/") if tokens else 0
    if k in (1, 2):
        chars = np.frombuffer(text, np.uint8)
        token_of = np.cumsum(chars == ord(" "))
        per_token = np.bincount(token_of[chars == ord("/")], minlength=n)
        if (per_token == k).all():  # every corner written alike: one parse of all the numbers
            text = text.replace(b"//", b"/0/")
            try:
                if text.endswith(b"/") or b"/ " in text:
                    raise ValueError
                cols = _whole_numbers(text.replace(b"/", b" "), n * (k + 1)).reshape(n, k + 1)
                return cols[:, 1], (cols[:, 2] if k == 2 else np.zeros(n, np.int64))
            except ValueError:
                pass
    try:
        parts = [t.split(b"/") for t in tokens]
        return tuple(np.array([int(p[j]) if len(p) > j and p[j] else 0 for p in parts], dtype=np.int64)
                     for j in (1, 2))
    except ValueError:
        raise RigInputError(f"{path}: a face record has a texture or normal index that is not a whole number.") from None


def _records(data: bytes) -> list[tuple[int, str]]:
    """(byte offset, line) of the g/o/s/usemtl/mtllib lines, in file order (a find per keyword: fast)."""
    found = []
    for key in (b"g", b"o", b"s", b"usemtl", b"mtllib"):
        starts = [0] if data.startswith(key) else []
        pos = data.find(b"\n" + key)
        while pos >= 0:
            starts.append(pos + 1)
            pos = data.find(b"\n" + key, pos + 1)
        for start in starts:
            if data[start + len(key):start + len(key) + 1] in (b" ", b"\t", b"\r", b"\n", b""):
                end = data.find(b"\n", start)
                found.append((start, data[start:end if end >= 0 else len(data)].decode("utf-8").rstrip()))
    return sorted(found)


def _parse_corners(path: Path, data: bytes, n_corners: int, faces: list[bytes]) -> CornerAttributes | None:
    """The file's vt/vn lists, each face corner's vt/vn index and the group records, without touching v/f."""
    uvs = _parse_table(path, data, _VT_LINE, "texture coordinate ('vt')", (2, 3))
    normals = _parse_table(path, data, _VN_LINE, "normal ('vn')", (3, 3))
    records = _records(data)
    notes = []
    if uvs is not None and not np.isfinite(uvs).all():   # the geometry still loads; the texture cannot
        notes.append(f"{path}: its texture coordinates ('vt') hold NaN or infinite values; they are left out.")
        uvs = None
    if uvs is None and normals is None and not records and not notes:
        return None
    corner_uv = corner_normal = None
    tokens = b" ".join(faces).split()
    if len(tokens) == n_corners and (uvs is not None or normals is not None):
        vt, vn = _corner_columns(path, tokens)
        if uvs is not None:
            corner_uv = _corner_index(path, vt, len(uvs), "texture coordinate")
        if normals is not None:
            corner_normal = _corner_index(path, vn, len(normals), "normal")
    # the face number of each record: the face records before it (counted between consecutive records)
    at, count, prev = [], 0, 0
    for pos, _ in records:
        count += data.count(b"\nf ", prev, pos) + data.count(b"\nf\t", prev, pos) + (pos > 0 and data.startswith(b"f ") and prev == 0)
        at.append(count)
        prev = pos
    return CornerAttributes(uvs=uvs, corner_uv=corner_uv, normals=normals, corner_normal=corner_normal,
                            records=[(f, line) for f, (_, line) in zip(at, records)], notes=notes)


def _face_section(data: bytes) -> bytes:
    i = data.find(b"\nf ")
    return data[i:] if i >= 0 else b""


def _same_face_section(data: bytes, section: bytes) -> bool:
    """``_face_section(data) == section`` without copying the section out of ``data``."""
    i = data.find(b"\nf ")
    if i < 0:
        return section == b""
    return len(data) - i == len(section) and data.endswith(section)


def read_obj(path: str | Path) -> ObjMesh:
    """Read vertices and polygon faces of an OBJ in file order (vertex order is sacred)."""
    path = Path(path)
    data = _read_bytes(path)
    verts = _parse_vertices(path, data)
    faces = _F_LINE.findall(data)
    counts, idx = _parse_faces(path, data, len(verts), faces)
    return ObjMesh(verts, counts, idx, _face_section(data), _parse_corners(path, data, idx.size, faces))


def read_obj_target(path: str | Path, neutral: ObjMesh) -> np.ndarray:
    """Read a blendshape target OBJ and check it matches the neutral (vertex count and face list).

    Returns its (V, 3) vertices. Face records identical to the neutral's as bytes skip the face parse.
    """
    path = Path(path)
    data = _read_bytes(path)
    verts = _parse_vertices(path, data)
    if len(verts) != len(neutral.vertices):
        raise RigInputError(f"{path}: has {len(verts)} vertices but the neutral has "
                            f"{len(neutral.vertices)}; every shape must have the neutral's vertices in order.")
    if not _same_face_section(data, neutral.face_section):
        counts, idx = _parse_faces(path, data, len(verts))
        if counts.size == 0:
            pass  # points-only targets are fine: faces come from the neutral
        elif not (np.array_equal(counts, neutral.face_counts) and np.array_equal(idx, neutral.face_indices)):
            raise RigInputError(f"{path}: its face list differs from the neutral's "
                                f"({counts.size} faces vs {neutral.face_counts.size}).")
    return verts


def write_obj(path: str | Path, vertices: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
              *, header: str = "", corners: CornerAttributes | None = None, normals: bool = True) -> None:
    """Write vertices and polygons in the given order (1-based indices), atomically.

    With ``corners`` (a source OBJ's, ``Rig.corners``) its ``vt``/``vn`` lists, each corner's ``v/vt/vn``
    and the group, material and smoothing records are written back where they were (``normals=False``
    leaves the normals out, e.g. for a posed surface they no longer fit).
    """
    from .atomic import atomic_write
    out = io.StringIO()
    if header:
        for line in header.splitlines():
            out.write(f"# {line}\n")
    c = corners or CornerAttributes()
    records = sorted(c.records, key=lambda r: r[0])
    out.write("".join(line + "\n" for f, line in records if line.startswith("mtllib")))
    records = [(f, line) for f, line in records if not line.startswith("mtllib")]
    v = np.asarray(vertices, dtype=np.float64)
    out.write("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v.tolist()))
    uv = c.corner_uv if c.uvs is not None else None
    nv = c.corner_normal if (normals and c.normals is not None) else None
    if uv is not None:
        out.write("".join("vt " + " ".join(f"{t:.6f}" for t in row) + "\n" for row in c.uvs.tolist()))
    if nv is not None:
        out.write("".join(f"vn {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in c.normals.tolist()))
    corner = [str(i) for i in (np.asarray(face_indices) + 1).tolist()]
    if uv is not None or nv is not None:
        t = ["" if i < 0 else str(i + 1) for i in uv.tolist()] if uv is not None else None
        n = ["" if i < 0 else str(i + 1) for i in nv.tolist()] if nv is not None else None
        if n is None:
            corner = [a if not b else f"{a}/{b}" for a, b in zip(corner, t)]
        else:
            corner = [a if not b and not m else f"{a}/{b}/{m}" for a, b, m in zip(corner, t or [""] * len(n), n)]
    pos = 0
    lines = []
    r = 0
    for f, cnt in enumerate(np.asarray(face_counts).tolist()):
        while r < len(records) and records[r][0] <= f:
            lines.append(records[r][1] + "\n")
            r += 1
        lines.append("f " + " ".join(corner[pos:pos + cnt]) + "\n")
        pos += cnt
    lines.extend(line + "\n" for _, line in records[r:])
    out.write("".join(lines))
    atomic_write(path, out.getvalue().encode("utf-8"))
