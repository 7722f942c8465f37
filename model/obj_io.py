"""Wavefront OBJ reading and writing that keeps vertex order.

We read ``v`` and ``f`` records ourselves, in file order. General mesh loaders (trimesh, pyvista)
split vertices at UV seams and material groups, which silently breaks blendshape correspondence
(DESIGN.md, Readers). The neutral's vt/vn per corner and its g/o/s/usemtl/mtllib records are kept as
``CornerAttributes`` (written back on export; ``model.parts`` reads the materials from them); the targets' are not
read.
"""
from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import RigInputError
from .rig import MAX_COORDINATE, CornerAttributes

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
    # Everything after the one run of 'v' lines, when no face record comes before it: a target whose bytes
    # end with it has the neutral's faces, vt/vn and groups, and its own 'v' run just before it.
    vertex_tail: bytes | None = None
    path: str = ""              # the file, named when a target's faces differ from these


def _read_bytes(path: Path) -> bytes:
    try:
        data = Path(path).read_bytes()
    except IsADirectoryError:
        raise RigInputError(f"{path}: is a folder, not an OBJ file.") from None
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror}).") from None
    if not data or data.isspace():      # (no copy of the file, unlike strip())
        raise RigInputError(f"{path}: the file is empty.")
    kind = _other_format(Path(path), data)
    if kind:
        raise RigInputError(f"{path}: is {kind} file, not an OBJ mesh; save it as OBJ with the rig's vertices in the "
                            "rig's order.")
    if b"\0" in data[:65536]:
        raise RigInputError(f"{path}: is a binary file, not a text OBJ.")
    try:
        if not data.isascii():    # ASCII is UTF-8: the check is one fast scan; only other text is decoded
            data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RigInputError(f"{path}: is not UTF-8 text (bad byte at offset {exc.start}).") from None
    return data


# Other mesh and scene formats a user may hand over where an OBJ is read (a scan, a target), by their first bytes and
# then by their extension: named as what they are, not as an OBJ without 'v' records or a binary OBJ
_MAGIC = ((b"glTF", "a binary glTF (GLB)"), (b"ply", "a PLY"), (b"Kaydara FBX Binary", "an FBX"),
          (b"PK\x03\x04", "a zip (a .bsproj project or an archive)"), (b"#usda", "a USD"), (b"PXR-USDC", "a USD"),
          (b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"))
_SUFFIXES = {".glb": "a binary glTF (GLB)", ".gltf": "a glTF", ".ply": "a PLY", ".fbx": "an FBX", ".stl": "an STL",
             ".usd": "a USD", ".usda": "a USD", ".usdc": "a USD", ".usdz": "a USD", ".abc": "an Alembic",
             ".bsproj": "a Blendshape Studio project", ".dae": "a COLLADA", ".3ds": "a 3DS", ".blend": "a Blender",
             ".c3d": "a C3D (motion capture)", ".trc": "a TRC (motion capture)"}


def _other_format(path: Path, data: bytes) -> str | None:
    """What ``data`` is when it is plainly not an OBJ: its signature, else (with no 'v' record at all) its
    extension or, for JSON text, glTF. None for anything that may be an OBJ."""
    for magic, kind in _MAGIC:
        if data.startswith(magic):
            return kind
    if data[:2] in (b"v ", b"v\t") or _V_NEXT.search(data) is not None:
        return None
    suffix = path.suffix.lower()
    if suffix in _SUFFIXES:
        return _SUFFIXES[suffix]
    return "a JSON (glTF?)" if data.lstrip()[:1] == b"{" else None


# the start of a record of each kind, and of a line that is not one (runs of 'vt' and 'vn' lines)
_RUNS = {b"v": (_V_NEXT, _NOT_V_NEXT)}
_RUNS.update({key: (re.compile(rb"\n" + key + rb"[ \t]"), re.compile(rb"\n(?!" + key + rb"[ \t])"))
              for key in (b"vt", b"vn")})


def _vertex_span(data: bytes, key: bytes = b"v") -> tuple[int, int] | None:
    """(start, end) of the one run of consecutive ``key`` lines ('v' by default), or None when those records
    are scattered or absent."""
    is_next, not_next = _RUNS[key]
    start = 0 if data[:len(key) + 1] in (key + b" ", key + b"\t") else -1
    if start < 0:
        m = is_next.search(data)
        if m is None:
            return None
        start = m.start() + 1
    m = not_next.search(data, start)
    end = m.start() + 1 if m else len(data)
    if is_next.search(data, end - 1) is not None:
        return None  # more such records later in the file
    return start, end


def _vertex_block(data: bytes) -> bytes | None:
    """The bytes of the one run of consecutive 'v' lines, or None when 'v' records are scattered."""
    span = _vertex_span(data)
    return None if span is None else data[span[0]:span[1]]


def _parse_vertex_block(block: bytes) -> np.ndarray | None:
    """(V, 3) from a run of 'v' lines, None when some line does not parse (the caller's careful path).

    The compiled reader (``solvers.decimal_kernel_jit``: the same bits as ``strtod``, about eight times faster) when
    the take solver's kernel is built on this machine and the lines are plain decimal ``v x y z`` lines; numpy's
    text reader otherwise."""
    verts = _compiled_vertex_block(block)
    if verts is not None:
        return verts
    try:
        return np.loadtxt(io.BytesIO(block), usecols=(1, 2, 3), dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        return None  # ragged lines (colours on some, w on others): take the careful path


def _decimal(token: bytes) -> float:
    """``float`` of one OBJ number, without Python's digit separators: '1_000' is no number to the C and C++
    readers of other tools (numpy's text reader, Blender's), so it is none here either (ValueError)."""
    if b"_" in token:
        raise ValueError(token)
    return float(token)


def _compiled_vertex_block(block: bytes, rows: int | None = None) -> np.ndarray | None:
    """``solvers.decimal_kernel_jit.parse_vertex_lines`` over ``block``, the numbers outside its fast path
    converted by ``float``; None when the kernel is not built here, a line is not a plain one, or (given ``rows``)
    the block does not have that many lines."""
    from solvers import take_kernel
    module = take_kernel.built()
    if module is None or not block:
        return None
    chars = np.frombuffer(block, np.uint8)
    rows = block.count(b"\n") + (block[-1:] != b"\n") if rows is None else rows
    out = np.empty((rows, 3))
    slow = np.empty((3 * rows, 3), np.int64)       # room for every number (pages touched only where written)
    n_slow = np.zeros(1, np.int64)
    if module.parse_vertex_lines(chars, out, slow, n_slow) != rows:
        return None
    flat = out.reshape(-1)
    for index, start, end in slow[:n_slow[0]].tolist():
        try:
            flat[index] = _decimal(block[start:end])
        except ValueError:
            return None
    return out


def _parse_vertices(path: Path, data: bytes, span: tuple[int, int] | None | bool = False) -> np.ndarray:
    """The (V, 3) vertices; ``span``: the file's ``_vertex_span`` when the caller has it."""
    span = _vertex_span(data) if span is False else span
    block = None if span is None else data[span[0]:span[1]]
    if block is None and _V_NEXT.search(data) is None and data[:2] not in (b"v ", b"v\t"):
        raise RigInputError(f"{path}: has no vertex ('v') records.")
    verts = None if block is None else _parse_vertex_block(block)
    if verts is None:
        rows = []
        for i, line in enumerate(_V_LINE.findall(data)):
            parts = line.split()
            if len(parts) < 3:
                raise RigInputError(f"{path}: vertex record {i + 1} has fewer than 3 coordinates "
                                    "(the file may be truncated).")
            try:
                rows.append([_decimal(parts[0]), _decimal(parts[1]), _decimal(parts[2])])
            except ValueError:
                raise RigInputError(f"{path}: vertex record {i + 1} is not a number: "
                                    f"{line[:40].decode(errors='replace')!r}.") from None
        verts = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    bad = ~np.isfinite(verts).all(axis=1)
    if bad.any():
        raise RigInputError(f"{path}: vertex {int(np.argmax(bad))} has a NaN or infinite coordinate.")
    bad = (np.abs(verts) > MAX_COORDINATE).any(axis=1)   # named here, in this file, not later by the rig's folder
    if bad.any():
        raise RigInputError(f"{path}: vertex {int(np.argmax(bad))} has a coordinate beyond ±{MAX_COORDINATE:g}; "
                            "the file is damaged.")
    return verts


def _parse_faces(path: Path, data: bytes, n_vertices: int, records: list[bytes] | None = None,
                 columns: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(counts, 0-based vertex indices) of the face records; ``columns``: their corners' numbers as
    ``_uniform_columns`` parsed them, when the caller has them (the vertex index is the first)."""
    records = _F_LINE.findall(data) if records is None else records
    if not records:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    counts = None
    if columns is not None:
        counts = np.fromiter((len(r.split()) for r in records), dtype=np.int32, count=len(records))
        idx = columns[:, 0]
    if counts is None or len(idx) != int(counts.sum()):
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
    table = _table_run(data, key)
    if table is None:
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


def _table_run(data: bytes, key: bytes) -> np.ndarray | None:
    """The numbers of the file's ``key`` records ('vt', 'vn') when they are one run of lines each written
    ``key`` + one space + numbers: the rows ``_parse_table`` parses, without a regular expression over the
    file. None otherwise (``_parse_table`` finds the records one by one)."""
    span = _vertex_span(data, key)
    if span is None:
        return None
    block = data[span[0]:span[1]]
    lines = block.count(b"\n") + (not block.endswith(b"\n"))
    if block.count(key + b" ") != lines:   # each line starts 'key ', and the key appears nowhere else
        return None
    try:
        return np.loadtxt(io.BytesIO(block.replace(key + b" ", b"")), dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        return None


def _uniform_columns(tokens: list[bytes]) -> np.ndarray | None:
    """(n, k + 1) int64: the numbers of face corners all written alike, ``v``, ``v/vt``, ``v//vn`` (vt 0) or
    ``v/vt/vn``, parsed at once; None when the corners are written differently or a number is missing or bad
    (the callers' careful paths then find and name the problem)."""
    n = len(tokens)
    if not n:
        return None
    text = b" ".join(tokens)
    k = tokens[0].count(b"/")
    if k not in (0, 1, 2) or text.count(b"/") != n * k:
        return None
    if k:
        # token i lies between spaces i-1 and i; with n·k slashes in all, each has k when slashes k·i and
        # k·i + k − 1 both lie inside it
        chars = np.frombuffer(text, np.uint8)
        bounds = np.concatenate(([-1], np.flatnonzero(chars == ord(" ")), [len(text)]))
        slashes = np.flatnonzero(chars == ord("/"))
        if len(bounds) != n + 1 or not ((slashes[::k] > bounds[:-1]).all() and (slashes[k - 1::k] < bounds[1:]).all()):
            return None
        text = text.replace(b"//", b"/0/")
        if text.endswith(b"/") or b"/ " in text:
            return None
    try:
        return _whole_numbers(text.replace(b"/", b" ") if k else text, n * (k + 1)).reshape(n, k + 1)
    except ValueError:
        return None


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


def _corner_columns(path: Path, tokens: list[bytes], columns: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The vt and vn numbers (0 = none) of face corners written ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``;
    ``columns``: ``_uniform_columns(tokens)`` when the caller has it."""
    n = len(tokens)
    cols = _uniform_columns(tokens) if columns is None else columns
    if cols is not None and cols.shape[1] > 1:  # every corner written alike: one parse of all the numbers
        return cols[:, 1], (cols[:, 2] if cols.shape[1] == 3 else np.zeros(n, np.int64))
    try:
        parts = [t.split(b"/") for t in tokens]
        return tuple(np.array([int(p[j]) if len(p) > j and p[j] else 0 for p in parts], dtype=np.int64)
                     for j in (1, 2))
    except ValueError:
        raise RigInputError(f"{path}: a face record has a texture or normal index that is not a whole number.") from None


_RECORD_KEYS = (b"g", b"o", b"s", b"usemtl", b"mtllib")


def _records(data: bytes) -> list[tuple[int, str]]:
    """(byte offset, line) of the g/o/s/usemtl/mtllib lines, in file order (the lines whose first letter is one of
    theirs, found in one pass over the line starts)."""
    chars = np.frombuffer(data, np.uint8)
    starts = np.flatnonzero(chars[:-1] == 10) + 1
    first = chars[starts]
    maybe = starts[(first == ord("g")) | (first == ord("o")) | (first == ord("s")) | (first == ord("u"))
                   | (first == ord("m"))].tolist()
    if data[:1] in (b"g", b"o", b"s", b"u", b"m"):
        maybe.insert(0, 0)
    found = []
    for start in maybe:
        for key in _RECORD_KEYS:
            if data.startswith(key, start) and \
                    data[start + len(key):start + len(key) + 1] in (b" ", b"\t", b"\r", b"\n", b""):
                end = data.find(b"\n", start)
                found.append((start, data[start:end if end >= 0 else len(data)].decode("utf-8").rstrip()))
                break
    return found


def _faces_before(data: bytes, offsets: list[int]) -> list[int]:
    """How many face records ('f ' or 'f\\t' lines) come before each offset (a line start)."""
    chars = np.frombuffer(data, np.uint8)
    nl = np.flatnonzero((chars[:-2] == 10) & (chars[1:-1] == ord("f")) & ((chars[2:] == 32) | (chars[2:] == 9)))
    lead = 1 if data.startswith(b"f ") else 0
    return [int(np.searchsorted(nl, pos - 1)) + (lead if pos > 0 else 0) for pos in offsets]


def _parse_corners(path: Path, data: bytes, n_corners: int, faces: list[bytes], tokens: list[bytes] | None = None,
                   columns: np.ndarray | None = None) -> CornerAttributes | None:
    """The file's vt/vn lists, each face corner's vt/vn index and the group records, without touching v/f;
    ``tokens`` and ``columns``: the face corners and ``_uniform_columns(tokens)`` when the caller has them."""
    uvs = _parse_table(path, data, _VT_LINE, "texture coordinate ('vt')", (2, 3))
    normals = _parse_table(path, data, _VN_LINE, "normal ('vn')", (3, 3))
    records = _records(data)
    notes = []
    if uvs is not None and not np.isfinite(uvs).all():   # the geometry still loads; the texture cannot
        notes.append(f"{path}: its texture coordinates ('vt') hold NaN or infinite values; they are left out.")
        uvs = None
    if normals is not None and not np.isfinite(normals).all():   # nor written back on export: shading is computed
        notes.append(f"{path}: its normals ('vn') hold NaN or infinite values; they are left out.")
        normals = None
    if uvs is None and normals is None and not records and not notes:
        return None
    corner_uv = corner_normal = None
    tokens = b" ".join(faces).split() if tokens is None else tokens
    if len(tokens) == n_corners and (uvs is not None or normals is not None):
        vt, vn = _corner_columns(path, tokens, columns)
        if uvs is not None:
            corner_uv = _corner_index(path, vt, len(uvs), "texture coordinate")
        if normals is not None:
            corner_normal = _corner_index(path, vn, len(normals), "normal")
    at = _faces_before(data, [pos for pos, _ in records])   # the face number of each record
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
    span = _vertex_span(data)
    verts = _parse_vertices(path, data, span)
    faces = _F_LINE.findall(data)
    tokens = b" ".join(faces).split()
    columns = _uniform_columns(tokens)
    counts, idx = _parse_faces(path, data, len(verts), faces, columns)
    return ObjMesh(verts, counts, idx, _face_section(data),
                   _parse_corners(path, data, idx.size, faces, tokens, columns), vertex_tail=_vertex_tail(data, span),
                   path=str(path))


def _vertex_tail(data: bytes, span: tuple[int, int] | None) -> bytes | None:
    """The bytes after the file's one run of 'v' lines (``span``), when no face record comes before that run."""
    if span is None or data[span[1] - 1:span[1]] != b"\n" or _F_LINE.search(data, 0, span[0]) is not None:
        return None
    return data[span[1]:]


def _target_vertices(data: bytes, neutral: ObjMesh) -> np.ndarray | None:
    """A target's (V, 3) vertices when the file is the neutral's but for its header and its run of 'v' lines
    (every line of the run a 'v ' record, the neutral's vertex count): then its faces, vt/vn and groups are
    the neutral's byte for byte and need no parse. None when that is not so (the caller's full checks)."""
    tail = neutral.vertex_tail
    if tail is None or not data.endswith(tail):
        return None
    end = len(data) - len(tail)
    m = _V_NEXT.search(data, 0, end)
    start = 0 if data[:2] in (b"v ", b"v\t") else (m.start() + 1 if m else -1)
    if start < 0 or _F_LINE.search(data, 0, start) is not None:
        return None
    block = data[start:end]
    n = len(neutral.vertices)
    verts = _compiled_vertex_block(block, rows=n)      # checks that the block is n plain 'v x y z' lines itself
    if verts is not None:
        return verts if _plain_lengths(verts) else None
    # every line of the run is one 'v ' record, and there are V of them
    chars = np.frombuffer(block, np.uint8)
    ends = np.flatnonzero(chars == 10)
    if n == 0 or len(ends) != n or ends[-1] != len(block) - 1 or not block.startswith(b"v "):
        return None
    starts = ends[:-1] + 1
    if not ((chars[starts] == ord("v")) & (chars[starts + 1] == ord(" "))).all():
        return None
    verts = _parse_vertex_block(block)
    if verts is None or len(verts) != n or not _plain_lengths(verts):
        return None
    return verts


def _plain_lengths(verts: np.ndarray) -> bool:
    """Every coordinate finite and within ±MAX_COORDINATE (else ``_parse_vertices`` names the vertex)."""
    extent = np.abs(verts).max(initial=0.0)
    return bool(np.isfinite(extent) and extent <= MAX_COORDINATE)


def _first_difference(counts: np.ndarray, idx: np.ndarray, neutral: ObjMesh) -> str:
    """Which face of a target first differs from the neutral's: 'face N differs first' (1-based)."""
    n = min(counts.size, neutral.face_counts.size)
    differ = counts[:n] != neutral.face_counts[:n]
    k = int(np.argmax(differ)) if differ.any() else n
    starts = np.concatenate(([0], np.cumsum(counts[:k], dtype=np.int64)))
    if k:   # the corners of the faces before k are in the same places in both
        same = idx[:starts[-1]] == neutral.face_indices[:starts[-1]]
        if not same.all():
            k = int(np.searchsorted(starts, int(np.argmin(same)), side="right")) - 1
    return f"face {k + 1} differs first"


def read_obj_target(path: str | Path, neutral: ObjMesh) -> np.ndarray:
    """Read a blendshape target OBJ and check it matches the neutral (vertex count and face list).

    Returns its (V, 3) vertices. Face records identical to the neutral's as bytes skip the face parse.
    """
    path = Path(path)
    data = _read_bytes(path)
    verts = _target_vertices(data, neutral)
    if verts is not None:
        return verts
    verts = _parse_vertices(path, data)
    if len(verts) != len(neutral.vertices):
        raise RigInputError(f"{path}: has {len(verts)} vertices but the neutral has "
                            f"{len(neutral.vertices)}; every shape must have the neutral's vertices in order.")
    if not _same_face_section(data, neutral.face_section):
        counts, idx = _parse_faces(path, data, len(verts))
        if counts.size == 0:
            pass  # points-only targets are fine: faces come from the neutral
        elif not (np.array_equal(counts, neutral.face_counts) and np.array_equal(idx, neutral.face_indices)):
            # both named: a damaged neutral makes every target differ, and the first target is no more to blame
            first = _first_difference(counts, idx, neutral)
            raise RigInputError(f"{path}: its face list differs from the neutral's, {Path(neutral.path).name or '?'} "
                                f"({counts.size} faces vs {neutral.face_counts.size}; {first}); "
                                "one of the two files is damaged.")
    return verts


def write_obj(path: str | Path, vertices: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
              *, header: str = "", corners: CornerAttributes | None = None, normals: bool = True) -> None:
    """Write vertices and polygons in the given order (1-based indices), atomically (``obj_bytes``)."""
    from .atomic import atomic_write
    atomic_write(path, obj_bytes(vertices, face_counts, face_indices, header=header, corners=corners,
                                 normals=normals))


def obj_bytes(vertices: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray, *, header: str = "",
              corners: CornerAttributes | None = None, normals: bool = True) -> bytes:
    """An OBJ file of vertices and polygons in the given order (1-based indices).

    With ``corners`` (a source OBJ's, ``Rig.corners``) its ``vt``/``vn`` lists, each corner's ``v/vt/vn``
    and the group, material and smoothing records are written back where they were (``normals=False``
    leaves the normals out, e.g. for a posed surface they no longer fit).
    """
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
    return out.getvalue().encode("utf-8")
