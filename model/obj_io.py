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

# The start of a 'v' line and of any other line: finding the one run of consecutive "v x y z" lines
# this way is the fast path for files written by every DCC we know.
_V_NEXT = re.compile(rb"\nv[ \t]")
_NOT_V_NEXT = re.compile(rb"\n(?!v[ \t])")
_V_LINE = re.compile(rb"^v[ \t]+([^\n]*)", re.M)
_F_LINE = re.compile(rb"^f[ \t]+([^\n]*)", re.M)


@dataclass
class ObjMesh:
    vertices: np.ndarray        # (V, 3) float64
    face_counts: np.ndarray     # (F,) int32
    face_indices: np.ndarray    # (sum counts,) int32, 0-based
    face_section: bytes         # raw bytes from the first face record on, for fast equality checks


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


def _parse_faces(path: Path, data: bytes, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    records = _F_LINE.findall(data)
    if not records:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    # Keep only the vertex index of each corner ("12/5/7" -> "12"), then parse all at once.
    text = re.sub(rb"/[^\s]*", b"", b"\n".join(records))
    lines = text.split(b"\n")
    counts = np.fromiter((len(l.split()) for l in lines), dtype=np.int32, count=len(lines))
    try:
        idx = np.array(text.split(), dtype=np.int64)
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
    counts, idx = _parse_faces(path, data, len(verts))
    return ObjMesh(verts, counts, idx, _face_section(data))


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
              *, header: str = "") -> None:
    """Write vertices and polygons in the given order (1-based indices), atomically."""
    from .atomic import atomic_write
    out = io.StringIO()
    if header:
        for line in header.splitlines():
            out.write(f"# {line}\n")
    v = np.asarray(vertices, dtype=np.float64)
    out.write("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v.tolist()))
    idx = (np.asarray(face_indices) + 1).tolist()
    pos = 0
    lines = []
    for c in np.asarray(face_counts).tolist():
        lines.append("f " + " ".join(map(str, idx[pos:pos + c])) + "\n")
        pos += c
    out.write("".join(lines))
    atomic_write(path, out.getvalue().encode("utf-8"))
