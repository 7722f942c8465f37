"""glTF 2.0 / GLB morph targets as a Rig (DESIGN.md, Readers), and a small writer.

Reads the mesh the user means: the one named by ``mesh`` (``--mesh NAME``), else the mesh with the most
morph targets and then the most vertices (a Ready Player Me avatar opens its head, not an eyeball). All its
primitives with POSITION are concatenated in primitive order (vertex order kept, no welding), triangle
indices as faces, each morph target's POSITION as a shape delta (zero on primitives without targets).
Target names come from ``mesh.extras.targetNames`` (else ``target_0``, ...). The mesh's default weights, when not
all 0, become the preset ``DEFAULT_POSE`` (and the pose a file opens in: ``app.loading``). TEXCOORD_0, when every
primitive has it, becomes the rig's UVs (one per vertex, ``Rig.corners``; v flipped to OBJ's upward v).

The node hierarchy's world matrix of the first node (in scene order) that instances the mesh is applied (for a
skinned mesh, its joints' bind placement instead, as glTF 2.0 §3.7.3 says: see ``_world_matrix``):
``M p`` to positions and its linear part (no translation) to morph deltas, which is exact because a
morph target moves the mesh before the node transform does; a mirroring transform flips the winding so
faces keep facing out. Buffers may be embedded (base64 data URIs), external files inside the glTF's folder,
or the GLB BIN chunk; interleaved buffer views (byteStride), normalised and plain integer components
(``KHR_mesh_quantization``) and sparse accessors are read. Extensions that only concern materials,
textures, lights or metadata (webp, basisu, ...) never block the geometry; meshopt- and Draco-compressed
geometry is refused in one sentence. Every offset, length, stride and count is checked against the
buffers before reading. Coordinates are labelled ``units`` (glTF's own convention is metres).
"""
from __future__ import annotations

import base64
import re
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from .errors import RigInputError, repeated, shown
from .input_files import read_input_bytes, regular_file
from .json_file import parse_json_text
from .pages import memory_shortfall, small_pages_for
from .presets import fitting_presets
from .rig import MAX_WEIGHT, CornerAttributes, Rig

from .export_gltf import CHUNK_BIN as _CHUNK_BIN, CHUNK_JSON as _CHUNK_JSON, GLB_MAGIC as _GLB_MAGIC
_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NORMALISE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_SUPPORTED_REQUIRED = {"KHR_mesh_quantization", "EXT_mesh_gpu_instancing"}
# Extensions that change only how the surface looks, never its geometry: a reader of shapes ignores them.
_LOOKS_ONLY = ("KHR_texture_", "EXT_texture_", "KHR_materials_", "KHR_lights_", "KHR_xmp", "EXT_lights_",
               "MSFT_texture_", "KHR_animation_pointer")
_GEOMETRY_CODECS = {
    "EXT_meshopt_compression": "meshopt-compressed geometry (EXT_meshopt_compression), which this reader "
                               "does not decode; re-export it without meshopt compression (gltfpack without -c)",
    "KHR_meshopt_compression": "meshopt-compressed geometry (KHR_meshopt_compression), which this reader "
                               "does not decode; re-export it without meshopt compression (gltfpack without -c)",
    "KHR_draco_mesh_compression": "Draco-compressed geometry (KHR_draco_mesh_compression), an unsupported glTF "
                                  "extension; re-export it without Draco compression",
}


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
            data = self._external(i, uri)
        need = _int(b.get("byteLength", len(data)), -1)
        if need < 0:
            raise self.fail(f"buffer {i} has an invalid byteLength {b.get('byteLength')!r}.")
        if len(data) < need:
            raise self.fail(f"buffer {i} is truncated ({len(data)} of {need} bytes).")
        self._buffers[i] = data
        return data

    def _external(self, i: int, uri: str) -> bytes:
        """The bytes of an external buffer file, only from inside the glTF's own folder."""
        name = unquote(uri)
        folder = self.path.parent.resolve()
        target = (folder / name).resolve()
        if ("://" in uri or name.startswith(("/", "\\")) or Path(name).is_absolute() or ":" in name.split("/")[0]
                or ".." in Path(name.replace("\\", "/")).parts or not target.is_relative_to(folder)):
            raise self.fail(f"buffer {i} points outside the glTF's folder ('{uri}'); only files beside it are read.")
        if not target.is_file():
            raise self.fail(f"its buffer file '{uri}' was not found beside it.")
        try:
            return target.read_bytes()
        except OSError as e:
            raise self.fail(f"its buffer file '{uri}' cannot be read ({e.strerror or e}).") from None

    def _read_view(self, view_index: int, offset: int, ctype: int, ncomp: int, count: int) -> np.ndarray:
        views = self.gltf.get("bufferViews", [])
        if not 0 <= view_index < len(views):
            raise self.fail(f"refers to buffer view {view_index}, which does not exist.")
        view = views[view_index]
        codec = next((e for e in (view.get("extensions") or {}) if e in _GEOMETRY_CODECS), None)
        if codec:
            raise self.fail(f"holds {_GEOMETRY_CODECS[codec]}.")
        data = self.buffer(_int(view.get("buffer", 0)))
        dtype = np.dtype(_COMPONENT[ctype]).newbyteorder("<")
        elem = dtype.itemsize * ncomp
        stride = _int(view.get("byteStride", 0), -1)
        if stride < 0 or (stride and stride < elem):
            raise self.fail(f"buffer view {view_index} has byteStride {view.get('byteStride')!r}, "
                            f"less than the {elem}-byte elements it holds.")
        stride = stride or elem
        view_start, view_len = _int(view.get("byteOffset", 0), -1), _int(view.get("byteLength", -1), -1)
        if view_start < 0 or view_len < 0 or offset < 0:
            raise self.fail(f"buffer view {view_index} has a negative or missing byteOffset/byteLength.")
        view_end = view_start + view_len
        if view_end > len(data):
            raise self.fail(f"buffer view {view_index} ends at byte {view_end}, past the end of its "
                            f"{len(data)}-byte buffer (truncated file?).")
        start = view_start + offset
        end = start + (stride * (count - 1) + elem if count else 0)
        if end > view_end:
            raise self.fail(f"an accessor reads past the end of buffer view {view_index} (truncated file?).")
        if stride == elem:
            arr = np.frombuffer(data, dtype=dtype, count=count * ncomp, offset=start).reshape(count, ncomp)
        else:
            arr = np.lib.stride_tricks.as_strided(
                np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start).view(np.uint8),
                shape=(count, elem), strides=(stride, 1)).copy().view(dtype).reshape(count, ncomp)
        return arr

    def accessor_entry(self, index: int) -> dict:
        """The JSON of accessor ``index`` (RigInputError when there is none)."""
        accs = self.gltf.get("accessors", [])
        if not isinstance(index, int) or not 0 <= index < len(accs):
            raise self.fail(f"refers to accessor {index}, which does not exist.")
        return accs[index]

    def accessor(self, index: int) -> np.ndarray:
        """(count, ncomp) float64 (or int64 for index data) values of an accessor, sparse applied."""
        a = self.accessor_entry(index)
        ctype, typ, count = a.get("componentType"), a.get("type"), _int(a.get("count", -1), -1)
        if ctype not in _COMPONENT:
            raise self.fail(f"accessor {index} has an unsupported component type {ctype}.")
        if typ not in _NCOMP or count < 0:
            raise self.fail(f"accessor {index} has an invalid type or count.")
        ncomp = _NCOMP[typ]
        if "bufferView" in a:
            arr = self._read_view(_int(a["bufferView"], -1), _int(a.get("byteOffset", 0), -1), ctype, ncomp, count)
        else:   # zeros (sparse values go on top): no more of them than the file's buffers hold bytes
            held = sum(len(self.buffer(i)) for i in range(len(self.gltf.get("buffers", []))))
            if count * ncomp > held:
                raise self.fail(f"accessor {index} declares {count} values without a buffer view, more than the "
                                f"{held} bytes its buffers hold; the file is damaged.")
            arr = np.zeros((count, ncomp), dtype=_COMPONENT[ctype])
        if ctype == 5126:
            out = arr.astype(np.float64)
        elif a.get("normalized"):
            out = np.maximum(arr.astype(np.float64) / _NORMALISE[ctype], -1.0)
        else:
            out = arr.astype(np.int64) if typ == "SCALAR" else arr.astype(np.float64)
        sparse = a.get("sparse")
        if sparse:
            n = _int(sparse.get("count", -1), -1)
            if not 0 <= n <= count:
                raise self.fail(f"accessor {index} has a sparse count {sparse.get('count')!r} outside 0..{count}.")
            si, sv = sparse.get("indices", {}), sparse.get("values", {})
            ictype = si.get("componentType")
            if ictype not in (5121, 5123, 5125):
                raise self.fail(f"accessor {index} has sparse indices of unsupported type {ictype}.")
            idx = self._read_view(_int(si.get("bufferView"), -1), _int(si.get("byteOffset", 0), -1), ictype, 1, n)[:, 0]
            vals = self._read_view(_int(sv.get("bufferView"), -1), _int(sv.get("byteOffset", 0), -1), ctype, ncomp, n)
            if n and idx.max() >= count:
                raise self.fail(f"accessor {index} has a sparse index beyond its count.")
            out = out.copy()
            if ctype != 5126 and a.get("normalized"):
                vals = np.maximum(vals.astype(np.float64) / _NORMALISE[ctype], -1.0)
            out[idx.astype(np.int64)] = vals
        return out


def _int(value, bad: int = -1) -> int:
    """A glTF integer property, or ``bad`` when it is not a whole number (checked by the caller)."""
    return value if isinstance(value, int) and not isinstance(value, bool) else bad


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


# What this reader uses of a glTF document and the JSON type each must have (glTF 2.0 §5): anything else there
# is refused in one sentence before it is used, never met as a Python error half-way through reading.
DEFAULT_POSE = "glTF default pose"   # the preset holding a mesh's default morph weights

_ARRAY_FIELDS = ("accessors", "bufferViews", "buffers", "meshes", "nodes", "scenes", "skins")
_FIELD_TYPES = {
    "accessors": {"bufferView": _is_int, "byteOffset": _is_int, "componentType": _is_int, "count": _is_int,
                  "type": lambda v: isinstance(v, str), "normalized": lambda v: isinstance(v, bool),
                  "sparse": lambda v: isinstance(v, dict)},
    "bufferViews": {"buffer": _is_int, "byteOffset": _is_int, "byteLength": _is_int, "byteStride": _is_int},
    "buffers": {"byteLength": _is_int, "uri": lambda v: isinstance(v, str)},
    "meshes": {"primitives": lambda v: isinstance(v, list) and all(isinstance(p, dict) for p in v),
               "extras": lambda v: isinstance(v, dict), "name": lambda v: isinstance(v, str)},
    "nodes": {"mesh": _is_int, "skin": _is_int,
              "children": lambda v: isinstance(v, list) and all(_is_int(c) for c in v),
              "matrix": lambda v: isinstance(v, list) and len(v) == 16 and all(_is_num(c) for c in v),
              "translation": lambda v: isinstance(v, list) and len(v) == 3 and all(_is_num(c) for c in v),
              "rotation": lambda v: isinstance(v, list) and len(v) == 4 and all(_is_num(c) for c in v),
              "scale": lambda v: isinstance(v, list) and len(v) == 3 and all(_is_num(c) for c in v)},
    "scenes": {"nodes": lambda v: isinstance(v, list) and all(_is_int(c) for c in v)},
    "skins": {"joints": lambda v: isinstance(v, list) and len(v) > 0 and all(_is_int(c) for c in v),
              "inverseBindMatrices": _is_int},
}


def _index_map(v) -> bool:
    return isinstance(v, dict) and all(isinstance(k, str) and _is_int(i) for k, i in v.items())


_PRIMITIVE_TYPES = {"attributes": _index_map, "indices": _is_int, "mode": _is_int,
                    "targets": lambda v: isinstance(v, list) and all(_index_map(t) for t in v),
                    "extras": lambda v: isinstance(v, dict)}


def _check_structure(path: Path, gltf: dict) -> None:
    """Raise RigInputError naming the first property of the wrong JSON type among those this reader uses."""
    def bad(where: str) -> RigInputError:
        return RigInputError(f"{path}: {where} has a value of the wrong type; the file is damaged.")
    for key in ("asset", "extras"):
        if key in gltf and not isinstance(gltf[key], dict):
            raise bad(f"'{key}'")
    for key in ("extensionsRequired", "extensionsUsed"):
        if key in gltf and not (isinstance(gltf[key], list) and all(isinstance(e, str) for e in gltf[key])):
            raise bad(f"'{key}'")
    if "scene" in gltf and not _is_int(gltf["scene"]):
        raise bad("'scene'")
    for key in _ARRAY_FIELDS:
        items = gltf.get(key, [])
        if not isinstance(items, list) or not all(isinstance(it, dict) for it in items):
            raise bad(f"'{key}'")
        checks = _FIELD_TYPES[key]
        for i, it in enumerate(items):
            for field, ok in checks.items():
                if field in it and not ok(it[field]):
                    raise bad(f"{key}[{i}].{field}")
            if key == "meshes":
                for j, prim in enumerate(it.get("primitives", [])):
                    for field, ok in _PRIMITIVE_TYPES.items():
                        if field in prim and not ok(prim[field]):
                            raise bad(f"meshes[{i}].primitives[{j}].{field}")
                names = it.get("extras", {}).get("targetNames")
                if names is not None and not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
                    raise bad(f"meshes[{i}].extras.targetNames")


def _parse(path: Path) -> _Doc:
    raw = read_input_bytes(path)
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
        text = json_bytes.decode("utf-8")
    except UnicodeDecodeError:
        text = ""
    if not text.lstrip().startswith("{"):
        raise RigInputError(f"{path}: is neither valid glTF JSON nor a GLB file.")
    gltf = parse_json_text(text, str(path))
    if not isinstance(gltf, dict):
        raise RigInputError(f"{path}: is not a glTF document (the JSON is not an object).")
    _check_structure(path, gltf)
    version = str(gltf.get("asset", {}).get("version", ""))
    if not version.startswith("2"):
        raise RigInputError(f"{path}: glTF version '{version}' is not supported (glTF 2.0 only).")
    required = set(gltf.get("extensionsRequired") or [])
    codec = next((e for e in sorted(required) if e in _GEOMETRY_CODECS), None)
    if codec:
        raise RigInputError(f"{path}: holds {_GEOMETRY_CODECS[codec]}.")
    unsupported = {e for e in required - _SUPPORTED_REQUIRED if not e.startswith(_LOOKS_ONLY)}
    if unsupported:
        raise RigInputError(f"{path}: needs the unsupported glTF extension(s) {', '.join(sorted(unsupported))}.")
    return _Doc(path, gltf, bin_chunk)


def _primitive_triangles(doc: _Doc, prim: dict, n: int) -> np.ndarray:
    mode = int(prim.get("mode", 4))
    if "indices" in prim:   # whole numbers, one each (glTF 2.0 §3.7.2.1): a float or normalised one is no vertex
        acc = doc.accessor_entry(prim["indices"])
        if acc.get("componentType") == 5126 or acc.get("normalized") or acc.get("type") != "SCALAR":
            raise doc.fail(f"the indices of a primitive (accessor {prim['indices']}) are not whole numbers, "
                           "one per corner.")
        if "bufferView" not in acc:   # all zero: every triangle on vertex 0
            raise doc.fail(f"the indices of a primitive (accessor {prim['indices']}) have no buffer view holding them.")
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


def _mesh_sizes(doc: _Doc, mesh: dict) -> tuple[int, int]:
    """(morph targets, vertices) of a mesh, from the accessor counts (nothing decoded)."""
    accs = doc.gltf.get("accessors", [])
    prims = [p for p in mesh.get("primitives", []) if "POSITION" in (p.get("attributes") or {})]
    n_targets = max((len(p.get("targets") or []) for p in prims), default=0)
    n_vertices = 0
    for p in prims:
        i = p["attributes"]["POSITION"]
        if isinstance(i, int) and 0 <= i < len(accs):
            n_vertices += max(_int(accs[i].get("count", 0), 0), 0)
    return n_targets, n_vertices


def _mesh_label(mesh: dict, index: int) -> str:
    return mesh.get("name") or f"mesh_{index}"


def gltf_meshes(path: str | Path) -> list[dict]:
    """The meshes of a glTF file as ``{"name", "targets", "vertices"}`` (for ``info`` and a mesh choice)."""
    doc = _parse(Path(path))
    return [dict(zip(("name", "targets", "vertices"), (_mesh_label(m, i),) + _mesh_sizes(doc, m)))
            for i, m in enumerate(doc.gltf.get("meshes", []))]


def _choose_mesh(doc: _Doc, mesh: str | None) -> int:
    meshes = doc.gltf.get("meshes", [])
    if not meshes:
        raise doc.fail("has no meshes.")
    labels = [_mesh_label(m, i) for i, m in enumerate(meshes)]
    if mesh is not None:
        if mesh in labels:
            return labels.index(mesh)
        raise doc.fail(f"has no mesh named '{mesh}' (it has: {', '.join(labels)}).")
    sizes = [_mesh_sizes(doc, m) for m in meshes]
    return max(range(len(meshes)), key=lambda i: (sizes[i], -i))


def _quaternion_matrix(q) -> np.ndarray:
    x, y, z, w = (float(c) for c in q)
    n = x * x + y * y + z * z + w * w
    s = 2.0 / n if n > 0 else 0.0
    return np.array([[1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
                     [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
                     [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)]])


def node_matrix(node: dict) -> np.ndarray:
    """A node's local 4x4 matrix: ``matrix`` (column-major) or T * R * S."""
    if "matrix" in node:
        m = np.asarray(node["matrix"], dtype=np.float64)
        if m.size != 16:
            raise ValueError("a node matrix does not have 16 numbers")
        return m.reshape(4, 4).T
    out = np.eye(4)
    out[:3, :3] = _quaternion_matrix(node.get("rotation", (0, 0, 0, 1))) * np.asarray(node.get("scale", (1, 1, 1)),
                                                                                       dtype=np.float64)
    out[:3, 3] = np.asarray(node.get("translation", (0, 0, 0)), dtype=np.float64)
    return out


def _world_matrix(doc: _Doc, mesh_index: int) -> np.ndarray:
    """World matrix of the first node (depth first from the scene's roots) that instances the mesh, or for a skinned
    mesh (whose node transform is ignored, glTF 2.0 §3.7.3: only its joints place it) the joints' placements
    (``_skin_matrices``): one matrix when they agree (the file's bind pose), else (J, 4, 4) per joint."""
    nodes = doc.gltf.get("nodes", [])
    parent: dict[int, int] = {}
    for i, n in enumerate(nodes):
        for c in n.get("children", []) or []:
            if isinstance(c, int) and 0 <= c < len(nodes):
                parent.setdefault(c, i)
    scenes = doc.gltf.get("scenes", [])
    scene = doc.gltf.get("scene", 0)
    roots = list(scenes[scene].get("nodes", [])) if isinstance(scene, int) and 0 <= scene < len(scenes) else []
    roots += [i for i in range(len(nodes)) if i not in parent and i not in roots]
    order, stack, seen = [], list(reversed(roots)), set()
    while stack:
        i = stack.pop()
        if not isinstance(i, int) or not 0 <= i < len(nodes) or i in seen:
            continue
        seen.add(i)
        order.append(i)
        stack.extend(reversed(nodes[i].get("children", []) or []))
    hit = next((i for i in order if nodes[i].get("mesh") == mesh_index), None)

    def world(node: int | None) -> np.ndarray:
        M = np.eye(4)
        chain = set()
        while node is not None:
            if node in chain:
                raise doc.fail("its node hierarchy has a cycle.")
            chain.add(node)
            try:
                M = node_matrix(nodes[node]) @ M
            except (ValueError, TypeError):
                raise doc.fail(f"node {node} has an invalid transform.") from None
            node = parent.get(node)
        return M

    skin = nodes[hit].get("skin") if hit is not None else None
    M = world(hit) if skin is None else _skin_matrices(doc, skin, world)
    if not np.isfinite(M).all():
        raise doc.fail("a node transform has NaN or infinite values.")
    return M


def _skin_matrices(doc: _Doc, skin: int, world) -> np.ndarray:
    """How skin ``skin``'s joints place its mesh as the file poses them: each joint's world matrix times its inverse
    bind matrix, (4, 4) when they are all the same (the bind pose), else (J, 4, 4) for ``_skinned``."""
    nodes, skins = doc.gltf.get("nodes", []), doc.gltf.get("skins", [])
    if not 0 <= skin < len(skins):
        raise doc.fail(f"a node refers to skin {skin}, which does not exist.")
    joints = skins[skin].get("joints", [])
    if not joints or any(not 0 <= j < len(nodes) for j in joints):
        raise doc.fail(f"skin {skin} has no joints or a joint that is not a node.")
    if "inverseBindMatrices" in skins[skin]:
        ibm = doc.accessor(skins[skin]["inverseBindMatrices"])
        if ibm.shape[1] != 16 or ibm.shape[0] < len(joints):
            raise doc.fail(f"skin {skin}'s inverse bind matrices are not one 4x4 matrix per joint.")
        ibm = ibm[:len(joints)].reshape(-1, 4, 4).transpose(0, 2, 1)     # column-major, as node matrices
    else:
        ibm = np.broadcast_to(np.eye(4), (len(joints), 4, 4))
    placed = np.stack([world(j) @ b for j, b in zip(joints, ibm)])
    if not np.isfinite(placed).all():
        raise doc.fail(f"skin {skin} has NaN or infinite joint transforms.")
    size = max(1.0, float(np.abs(placed[0]).max()))
    return placed[0] if np.abs(placed - placed[0]).max() <= 1e-6 * size else placed


def _skinned(doc: _Doc, prims: list[dict], sizes: list[int], placed: np.ndarray) -> np.ndarray:
    """(V, 4, 4) per-vertex matrices of linear blend skinning: each vertex's JOINTS_n/WEIGHTS_n blend of the joints'
    placements ``placed`` (J, 4, 4), the weights normalised; a primitive without them stays as bound."""
    out = []
    for p, n in zip(prims, sizes):
        attrs = p.get("attributes") or {}
        sets = [(attrs[f"JOINTS_{i}"], attrs[f"WEIGHTS_{i}"]) for i in range(8)
                if f"JOINTS_{i}" in attrs and f"WEIGHTS_{i}" in attrs]
        if not sets:
            out.append(np.broadcast_to(np.eye(4), (n, 4, 4)))
            continue
        M, total = np.zeros((n, 4, 4)), np.zeros(n)
        for j_acc, w_acc in sets:
            J, W = doc.accessor(j_acc), doc.accessor(w_acc)
            if J.shape != (n, 4) or W.shape != (n, 4):
                raise doc.fail("a primitive's JOINTS/WEIGHTS are not four per vertex.")
            if not np.isfinite(W).all() or J.min() < 0 or J.max() >= len(placed) or (J != np.round(J)).any():
                raise doc.fail("a primitive's skin weights are not numbers or name a joint its skin does not have.")
            J = J.astype(np.int64)
            for c in range(4):
                M += W[:, c, None, None] * placed[J[:, c]]
            total += W.sum(axis=1)
        if not (total > 0).all():
            raise doc.fail("a vertex of its skinned mesh has no skin weight.")
        out.append(M / total[:, None, None])
    return np.concatenate(out)


def load_gltf(path: str | Path, units: str = "m", mesh: str | None = None) -> Rig:
    """Read a .gltf or .glb file's morph targets as a Rig (see the module docstring).

    ``mesh`` names the mesh to read (default: the most morph targets, then the most vertices).
    """
    path = regular_file(path)
    try:
        return _load(path, units, mesh)
    except RigInputError:
        raise
    except (TypeError, AttributeError, KeyError, IndexError, ValueError, OverflowError) as exc:
        # the structure check covers what this reader uses; this is the last line for what it missed
        raise RigInputError(f"{path}: the glTF is damaged ({type(exc).__name__}: {shown(exc, 80)}).") from None


def _load(path: Path, units: str, mesh: str | None) -> Rig:
    doc = _parse(path)
    mesh_index = _choose_mesh(doc, mesh)
    mesh = doc.gltf["meshes"][mesh_index]
    n_targets, n_vertices = _mesh_sizes(doc, mesh)
    with small_pages_for(n_targets * n_vertices * 24):   # a studio-scale rig's deltas (model.pages)
        return _load_mesh(doc, path, units, mesh_index, mesh)


def _load_mesh(doc: _Doc, path: Path, units: str, mesh_index: int, mesh: dict) -> Rig:
    label = _mesh_label(mesh, mesh_index)
    prims = [p for p in mesh.get("primitives", []) if "POSITION" in (p.get("attributes") or {})]
    if not prims:
        raise doc.fail(f"its mesh '{label}' has no primitive with vertex positions.")
    K = max(len(p.get("targets") or []) for p in prims)
    if any(len(p.get("targets") or []) not in (0, K) for p in prims):
        raise doc.fail(f"the primitives of its mesh '{label}' have different numbers of morph targets.")
    if K == 0:
        raise doc.fail(f"has no morph targets (blendshapes) on its mesh '{label}'.")
    positions = [doc.accessor(p["attributes"]["POSITION"]) for p in prims]   # each checked against its buffers
    if any(pos.shape[1] != 3 for pos in positions):
        raise doc.fail("a POSITION accessor is not VEC3.")
    vertices = sum(pos.shape[0] for pos in positions)
    short = memory_shortfall(3 * K * vertices * 24)    # the deltas as read, joined and transformed (float64)
    if short:
        raise doc.fail(f"its {K:,} morph targets on {vertices:,} vertices need {short}.")
    deltas, tris, offset = [], [], 0
    uvs: list | None = []
    for p, pos in zip(prims, positions):
        n = pos.shape[0]
        uvs = _texcoords(doc, p, n, uvs)
        d = np.zeros((K, n, 3))
        for k, t in enumerate(p.get("targets") or []):
            if "POSITION" in t:
                dk = doc.accessor(t["POSITION"])
                if dk.shape != (n, 3):
                    raise doc.fail(f"morph target {k} has {dk.shape[0]} vertices but its primitive has {n}.")
                d[k] = dk
        deltas.append(d)
        tris.append(_primitive_triangles(doc, p, n) + offset)
        offset += n
    M = _world_matrix(doc, mesh_index)
    with np.errstate(invalid="ignore", over="ignore"):   # a NaN or infinity in the file: the Rig refuses it below
        if M.ndim == 2:
            A = M[:3, :3]
            neutral = np.concatenate(positions) @ A.T + M[:3, 3]
            D = np.concatenate(deltas, axis=1) @ A.T
        else:   # a skin posed away from its bind pose: each vertex placed by its joints
            Mv = _skinned(doc, prims, [pos.shape[0] for pos in positions], M)
            A = np.median(Mv[:, :3, :3], axis=0)
            neutral = np.einsum("vij,vj->vi", Mv[:, :3, :3], np.concatenate(positions)) + Mv[:, :3, 3]
            D = np.einsum("vij,kvj->kvi", Mv[:, :3, :3], np.concatenate(deltas, axis=1))
    T = np.concatenate(tris).astype(np.int32)
    if np.linalg.det(A) < 0:  # a mirroring node: keep the faces facing out
        T = T[:, [0, 2, 1]]
    names = (mesh.get("extras") or {}).get("targetNames") or (prims[0].get("extras") or {}).get("targetNames")
    if names is None:
        names = [f"target_{k}" for k in range(K)]
    names = [str(n) for n in names]
    if len(names) != K:
        raise doc.fail(f"lists {len(names)} target names for {K} morph targets.")
    dup = repeated(names)
    if dup:
        raise doc.fail(f"has duplicate morph target names: {', '.join(dup)}.")
    rig = Rig(neutral=neutral, face_counts=np.full(T.shape[0], 3, np.int32), face_indices=T.reshape(-1),
              shape_names=names, deltas=D, units=units, name=mesh.get("name") or path.stem, source=str(path))
    if isinstance(uvs, list) and uvs:
        rig.corners = CornerAttributes(uvs=np.concatenate(uvs), corner_uv=rig.face_indices.copy())
    elif isinstance(uvs, str):
        rig.corners = CornerAttributes(notes=[f"{path}: {uvs}"])
    records, rig.materials = _material_parts(doc, prims, [len(t) for t in tris])
    if records:
        rig.corners = rig.corners or CornerAttributes()
        rig.corners.records = records
    rig.presets = fitting_presets(names)      # the emotion presets, where the targets have ARKit's names
    default = _default_weights(doc, mesh, K)
    if default is not None and default.any():
        rig.presets[DEFAULT_POSE] = {n: float(w) for n, w in zip(names, default) if w != 0}
    return rig


def _default_weights(doc: _Doc, mesh: dict, K: int) -> np.ndarray | None:
    """The mesh's default morph weights (glTF 2.0 §3.7.2.2: ``mesh.weights``, one per target, the pose a viewer
    shows without an animation: Blender's shape key values), None where it gives none."""
    if "weights" not in mesh:
        return None
    w = mesh["weights"]
    if not isinstance(w, list) or len(w) != K or not all(_is_num(v) for v in w) or \
            not np.isfinite(np.asarray(w, dtype=np.float64)).all():
        raise doc.fail(f"its mesh's default weights are not {K} numbers, one per morph target.")
    w = np.asarray(w, dtype=np.float64)
    if np.abs(w).max(initial=0.0) > MAX_WEIGHT:   # the pose it opens in (1e30: the surface posed 10^30 m away)
        raise doc.fail(f"its mesh's default weights reach {shown(float(np.abs(w).max()), 20)}, beyond the ±"
                       f"{MAX_WEIGHT:g} a weight may have.")
    return w


def _material_parts(doc: _Doc, prims: list[dict], n_tris: list[int]) -> tuple[list[tuple[int, str]], dict]:
    """(``usemtl`` records, one before each primitive's first face; {material: base colour}) when the primitives
    name more than one material or one with a colour (``model.parts``); ([], {}) otherwise. A material's colour
    is its ``baseColorFactor`` when no texture multiplies it."""
    materials = doc.gltf.get("materials") if isinstance(doc.gltf.get("materials"), list) else []
    names, colors, start = [], {}, 0
    records = []
    for p, n in zip(prims, n_tris):
        i = p.get("material")
        m = materials[i] if isinstance(i, int) and not isinstance(i, bool) and 0 <= i < len(materials) \
            and isinstance(materials[i], dict) else None
        label = str(m.get("name") or f"material_{i}") if m is not None else "default"
        name = re.sub(r"[\s\x00-\x1f\x7f]+", "_", label)[:100]      # one word on an OBJ's usemtl line
        pbr = (m or {}).get("pbrMetallicRoughness")
        pbr = pbr if isinstance(pbr, dict) else {}
        factor = pbr.get("baseColorFactor")
        if m is not None and "baseColorTexture" not in pbr and isinstance(factor, list) and len(factor) == 4 \
                and all(isinstance(c, (int, float)) and not isinstance(c, bool) and np.isfinite(c) for c in factor):
            colors[name] = tuple(float(min(1.0, max(0.0, c))) for c in factor[:3])
        if not records or records[-1][1] != f"usemtl {name}":
            records.append((start, f"usemtl {name}"))
        names.append(name)
        start += n
    if len(set(names)) < 2 and not colors:
        return [], {}
    return records, colors


def _texcoords(doc: _Doc, prim: dict, n: int, uvs: list | str | None) -> list | str | None:
    """Add a primitive's TEXCOORD_0 (n, 2) to ``uvs``: None once a primitive has none (the mesh has no UVs),
    a sentence once they cannot be used (the geometry loads without them)."""
    if not isinstance(uvs, list):
        return uvs
    index = (prim.get("attributes") or {}).get("TEXCOORD_0")
    if index is None:
        return ("some of its primitives have no texture coordinates (TEXCOORD_0); textures cannot be shown."
                if uvs else None)
    try:
        uv = doc.accessor(index)
    except RigInputError as exc:
        return f"its texture coordinates cannot be read ({shown(str(exc).split(': ', 1)[-1], 120)}); they are left out."
    if uv.shape != (n, 2):
        return f"a TEXCOORD_0 accessor holds {uv.shape[0]} {'VEC2' if uv.shape[1] == 2 else 'non-VEC2'} values for {n} vertices; the UVs are left out."
    if not np.isfinite(uv).all():
        return "its texture coordinates (TEXCOORD_0) hold NaN or infinite values; they are left out."
    uv[:, 1] = 1.0 - uv[:, 1]   # glTF's v runs down the image, OBJ's (the rig's) up
    return uvs + [uv]


# --- writer -------------------------------------------------------------------------------------
def write_gltf(rig: Rig, path: str | Path, units: str | None = None) -> None:
    """Write the rig as .gltf (buffer embedded as base64) or .glb, atomically, in ``units`` (default: as is).

    The rest pose and the shapes only (correctives become extra morph targets); ``model.export.export_rig``
    writes a pose and an animation too, in metres by default.
    """
    from .export import export_content
    from .export_gltf import write_gltf_content
    if Path(path).suffix.lower() not in (".gltf", ".glb"):
        raise RigInputError(f"{path}: write glTF to a .gltf or .glb file.")
    write_gltf_content(export_content(rig, units=units or rig.units), path)
