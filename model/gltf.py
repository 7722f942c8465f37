"""glTF 2.0 / GLB morph targets as a Rig (DESIGN.md, Readers), and a small writer.

Reads the first mesh that has morph targets (else the first mesh): all its primitives with POSITION,
concatenated in primitive order (vertex order kept, no welding), triangle indices as faces, each morph
target's POSITION as a shape delta. Target names come from ``mesh.extras.targetNames`` (else
``target_0``, ...). Buffers may be embedded (base64 data URIs), external files, or the GLB BIN chunk;
interleaved buffer views (byteStride), normalised integer components and sparse accessors are handled.
Node transforms are not applied: coordinates are taken as they are in the mesh, labelled ``units``
(glTF's own convention is metres).
"""
from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from .atomic import atomic_write
from .errors import RigInputError
from .rig import Rig

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NORMALISE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_SUPPORTED_REQUIRED = {"KHR_mesh_quantization"}


class _Doc:
    """A parsed glTF document with its buffers, for reading accessors."""

    def __init__(self, path: Path, gltf: dict, bin_chunk: bytes | None) -> None:
        self.path, self.gltf, self.bin_chunk = path, gltf, bin_chunk
        self._buffers: dict[int, bytes] = {}

    def fail(self, problem: str) -> RigInputError:
        return RigInputError(f"{self.path}: {problem}")

    def buffer(self, i: int) -> bytes:
        if i in self._buffers:
            return self._buffers[i]
        bufs = self.gltf.get("buffers", [])
        if not 0 <= i < len(bufs):
            raise self.fail(f"refers to buffer {i}, which does not exist.")
        b = bufs[i]
        uri = b.get("uri")
        if uri is None:
            if self.bin_chunk is None:
                raise self.fail(f"buffer {i} has no uri and the file has no binary chunk.")
            data = self.bin_chunk
        elif uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if ";base64" not in head:
                raise self.fail(f"buffer {i} has a data URI that is not base64.")
            try:
                data = base64.b64decode(payload, validate=True)
            except (ValueError, TypeError):
                raise self.fail(f"buffer {i} has invalid base64 data.") from None
        else:
            ext = self.path.parent / unquote(uri)
            if not ext.is_file():
                raise self.fail(f"its buffer file '{uri}' was not found beside it.")
            data = ext.read_bytes()
        need = int(b.get("byteLength", len(data)))
        if len(data) < need:
            raise self.fail(f"buffer {i} is truncated ({len(data)} of {need} bytes).")
        self._buffers[i] = data
        return data

    def _read_view(self, view_index: int, offset: int, ctype: int, ncomp: int, count: int) -> np.ndarray:
        views = self.gltf.get("bufferViews", [])
        if not 0 <= view_index < len(views):
            raise self.fail(f"refers to buffer view {view_index}, which does not exist.")
        view = views[view_index]
        data = self.buffer(int(view.get("buffer", 0)))
        dtype = np.dtype(_COMPONENT[ctype]).newbyteorder("<")
        elem = dtype.itemsize * ncomp
        stride = int(view.get("byteStride", 0)) or elem
        start = int(view.get("byteOffset", 0)) + offset
        view_end = int(view.get("byteOffset", 0)) + int(view.get("byteLength", 0))
        end = start + (stride * (count - 1) + elem if count else 0)
        if end > view_end or view_end > len(data):
            raise self.fail(f"an accessor reads past the end of buffer view {view_index} (truncated file?).")
        if stride == elem:
            arr = np.frombuffer(data, dtype=dtype, count=count * ncomp, offset=start).reshape(count, ncomp)
        else:
            arr = np.lib.stride_tricks.as_strided(
                np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start).view(np.uint8),
                shape=(count, elem), strides=(stride, 1)).copy().view(dtype).reshape(count, ncomp)
        return arr

    def accessor(self, index: int) -> np.ndarray:
        """(count, ncomp) float64 (or int64 for index data) values of an accessor, sparse applied."""
        accs = self.gltf.get("accessors", [])
        if not isinstance(index, int) or not 0 <= index < len(accs):
            raise self.fail(f"refers to accessor {index}, which does not exist.")
        a = accs[index]
        ctype, typ, count = a.get("componentType"), a.get("type"), int(a.get("count", -1))
        if ctype not in _COMPONENT:
            raise self.fail(f"accessor {index} has an unsupported component type {ctype}.")
        if typ not in _NCOMP or count < 0:
            raise self.fail(f"accessor {index} has an invalid type or count.")
        ncomp = _NCOMP[typ]
        if "bufferView" in a:
            arr = self._read_view(int(a["bufferView"]), int(a.get("byteOffset", 0)), ctype, ncomp, count)
        else:
            arr = np.zeros((count, ncomp), dtype=_COMPONENT[ctype])
        if ctype == 5126:
            out = arr.astype(np.float64)
        elif a.get("normalized"):
            out = np.maximum(arr.astype(np.float64) / _NORMALISE[ctype], -1.0)
        else:
            out = arr.astype(np.int64) if typ == "SCALAR" else arr.astype(np.float64)
        sparse = a.get("sparse")
        if sparse:
            n = int(sparse.get("count", 0))
            si, sv = sparse.get("indices", {}), sparse.get("values", {})
            ictype = si.get("componentType")
            if ictype not in (5121, 5123, 5125):
                raise self.fail(f"accessor {index} has sparse indices of unsupported type {ictype}.")
            idx = self._read_view(int(si["bufferView"]), int(si.get("byteOffset", 0)), ictype, 1, n)[:, 0]
            vals = self._read_view(int(sv["bufferView"]), int(sv.get("byteOffset", 0)), ctype, ncomp, n)
            if n and idx.max() >= count:
                raise self.fail(f"accessor {index} has a sparse index beyond its count.")
            out = out.copy()
            if ctype != 5126 and a.get("normalized"):
                vals = np.maximum(vals.astype(np.float64) / _NORMALISE[ctype], -1.0)
            out[idx.astype(np.int64)] = vals
        return out


def _parse(path: Path) -> _Doc:
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise RigInputError(f"{path}: cannot be read ({e.strerror or e}).") from None
    if not raw:
        raise RigInputError(f"{path}: the file is empty.")
    bin_chunk = None
    if raw[:4] == _GLB_MAGIC:
        if len(raw) < 20:
            raise RigInputError(f"{path}: the GLB file is truncated (no header).")
        _magic, version, length = struct.unpack_from("<4sII", raw, 0)
        if version != 2:
            raise RigInputError(f"{path}: GLB version {version} is not supported (glTF 2.0 only).")
        if length > len(raw):
            raise RigInputError(f"{path}: the GLB file is truncated ({len(raw)} of {length} bytes).")
        pos, json_bytes = 12, None
        while pos + 8 <= length:
            clen, ctype = struct.unpack_from("<II", raw, pos)
            chunk = raw[pos + 8:pos + 8 + clen]
            if len(chunk) < clen:
                raise RigInputError(f"{path}: the GLB file is truncated inside a chunk.")
            if ctype == _CHUNK_JSON and json_bytes is None:
                json_bytes = chunk
            elif ctype == _CHUNK_BIN and bin_chunk is None:
                bin_chunk = chunk
            pos += 8 + clen
        if json_bytes is None:
            raise RigInputError(f"{path}: the GLB file has no JSON chunk.")
    else:
        json_bytes = raw
    try:
        gltf = json.loads(json_bytes.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise RigInputError(f"{path}: is neither valid glTF JSON nor a GLB file.") from None
    if not isinstance(gltf, dict):
        raise RigInputError(f"{path}: is not a glTF document (the JSON is not an object).")
    version = str(gltf.get("asset", {}).get("version", ""))
    if not version.startswith("2"):
        raise RigInputError(f"{path}: glTF version '{version}' is not supported (glTF 2.0 only).")
    unsupported = set(gltf.get("extensionsRequired", [])) - _SUPPORTED_REQUIRED
    if unsupported:
        raise RigInputError(f"{path}: needs the unsupported glTF extension(s) {', '.join(sorted(unsupported))}.")
    return _Doc(path, gltf, bin_chunk)


def _primitive_triangles(doc: _Doc, prim: dict, n: int) -> np.ndarray:
    mode = int(prim.get("mode", 4))
    idx = doc.accessor(prim["indices"])[:, 0] if "indices" in prim else np.arange(n, dtype=np.int64)
    if mode == 4:
        if idx.size % 3:
            raise doc.fail("a triangle primitive has an index count that is not a multiple of 3.")
        tris = idx.reshape(-1, 3)
    elif mode == 5:  # strip
        k = np.arange(max(idx.size - 2, 0))
        tris = np.stack([idx[k], idx[k + 1 + (k % 2)], idx[k + 2 - (k % 2)]], axis=1)
    elif mode == 6:  # fan
        k = np.arange(1, max(idx.size - 1, 1))
        tris = np.stack([np.full(k.size, idx[0]), idx[k], idx[k + 1]], axis=1) if idx.size >= 3 else np.zeros((0, 3), np.int64)
    else:
        raise doc.fail(f"a primitive has mode {mode} (points or lines); only triangles can be read.")
    if tris.size and (tris.min() < 0 or tris.max() >= n):
        raise doc.fail("a primitive has an index beyond its vertex count.")
    return tris.astype(np.int64)


def load_gltf(path: str | Path, units: str = "m") -> Rig:
    """Read a .gltf or .glb file's morph targets as a Rig (see the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise RigInputError(f"{path}: does not exist.")
    doc = _parse(path)
    meshes = doc.gltf.get("meshes", [])
    if not meshes:
        raise doc.fail("has no meshes.")
    with_targets = [m for m in meshes if any(p.get("targets") for p in m.get("primitives", []))]
    mesh = with_targets[0] if with_targets else meshes[0]
    prims = [p for p in mesh.get("primitives", []) if "POSITION" in p.get("attributes", {})]
    if not prims:
        raise doc.fail("its first mesh has no primitive with vertex positions.")
    n_targets = {len(p.get("targets", [])) for p in prims}
    if len(n_targets) > 1:
        raise doc.fail("the primitives of its mesh have different numbers of morph targets.")
    K = n_targets.pop()
    if K == 0:
        raise doc.fail("has no morph targets (blendshapes) on its first mesh.")
    positions, deltas, tris, offset = [], [], [], 0
    for p in prims:
        pos = doc.accessor(p["attributes"]["POSITION"])
        if pos.shape[1] != 3:
            raise doc.fail("a POSITION accessor is not VEC3.")
        n = pos.shape[0]
        d = np.zeros((K, n, 3))
        for k, t in enumerate(p["targets"]):
            if "POSITION" in t:
                dk = doc.accessor(t["POSITION"])
                if dk.shape != (n, 3):
                    raise doc.fail(f"morph target {k} has {dk.shape[0]} vertices but its primitive has {n}.")
                d[k] = dk
        positions.append(pos)
        deltas.append(d)
        tris.append(_primitive_triangles(doc, p, n) + offset)
        offset += n
    neutral = np.concatenate(positions)
    D = np.concatenate(deltas, axis=1)
    T = np.concatenate(tris).astype(np.int32)
    if not np.isfinite(neutral).all() or not np.isfinite(D).all():
        raise doc.fail("has NaN or infinite coordinates.")
    names = (mesh.get("extras") or {}).get("targetNames") or (prims[0].get("extras") or {}).get("targetNames")
    if names is None:
        names = [f"target_{k}" for k in range(K)]
    names = [str(n) for n in names]
    if len(names) != K:
        raise doc.fail(f"lists {len(names)} target names for {K} morph targets.")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise doc.fail(f"has duplicate morph target names: {', '.join(dup)}.")
    return Rig(neutral=neutral, face_counts=np.full(T.shape[0], 3, np.int32), face_indices=T.reshape(-1),
               shape_names=names, deltas=D, units=units, name=mesh.get("name") or path.stem, source=str(path))


# --- writer -------------------------------------------------------------------------------------
def _pad4(b: bytes, fill: bytes = b"\x00") -> bytes:
    return b + fill * (-len(b) % 4)


def _document(rig: Rig, scale: float) -> tuple[dict, bytes]:
    pos = (rig.neutral * scale).astype("<f4")
    deltas = (rig.deltas * scale).astype("<f4")
    tris = rig.triangles().astype("<u4")
    blobs, views, accessors = [], [], []
    offset = 0

    def add(arr: np.ndarray, target: int | None, acc: dict) -> int:
        nonlocal offset
        data = _pad4(arr.tobytes())
        view = {"buffer": 0, "byteOffset": offset, "byteLength": arr.nbytes}
        if target:
            view["target"] = target
        views.append(view)
        blobs.append(data)
        offset += len(data)
        acc["bufferView"] = len(views) - 1
        accessors.append(acc)
        return len(accessors) - 1

    def vec3(arr: np.ndarray) -> int:
        return add(arr, 34962, {"componentType": 5126, "count": int(arr.shape[0]), "type": "VEC3",
                                "min": arr.min(axis=0).astype(float).tolist() if arr.size else [0, 0, 0],
                                "max": arr.max(axis=0).astype(float).tolist() if arr.size else [0, 0, 0]})

    i_pos = vec3(pos)
    i_idx = add(tris.reshape(-1), 34963, {"componentType": 5125, "count": int(tris.size), "type": "SCALAR"})
    targets = [{"POSITION": vec3(d)} for d in deltas]
    mesh = {"name": rig.name, "primitives": [{"attributes": {"POSITION": i_pos}, "indices": i_idx, "mode": 4,
                                               "targets": targets}],
            "weights": [0.0] * rig.n_shapes, "extras": {"targetNames": list(rig.shape_names)}}
    gltf = {"asset": {"version": "2.0", "generator": "Blendshape Studio"},
            "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": rig.name}],
            "meshes": [mesh], "accessors": accessors, "bufferViews": views,
            "buffers": [{"byteLength": offset}]}
    return gltf, b"".join(blobs)


def write_gltf(rig: Rig, path: str | Path, units: str | None = None) -> None:
    """Write the rig as .gltf (one JSON file, buffer embedded as base64) or .glb (binary), atomically.

    The polygons are fan-triangulated; positions and deltas are stored as float32. With ``units`` the
    coordinates are converted from ``rig.units`` (e.g. ``units='m'`` for other glTF tools); by default they
    are written as they are.
    """
    from .rig import unit_scale
    path = Path(path)
    scale = 1.0 if units is None else unit_scale(rig.units, units)
    gltf, blob = _document(rig, scale)
    suffix = path.suffix.lower()
    if suffix == ".gltf":
        gltf["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")
        atomic_write(path, json.dumps(gltf).encode("utf-8"))
    elif suffix == ".glb":
        js = _pad4(json.dumps(gltf).encode("utf-8"), b" ")
        body = (struct.pack("<II", len(js), _CHUNK_JSON) + js + struct.pack("<II", len(blob), _CHUNK_BIN) + blob)
        atomic_write(path, struct.pack("<4sII", _GLB_MAGIC, 2, 12 + len(body)) + body)
    else:
        raise RigInputError(f"{path}: write glTF to a .gltf or .glb file.")
