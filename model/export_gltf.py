"""glTF 2.0 writer (``.glb`` binary or ``.gltf`` with the buffer embedded), numpy + json, Qt-free.

One mesh, one node, one primitive: POSITION (float32, with min/max), NORMAL (the area-weighted vertex normals
the viewport shades with, ``solvers.normals``), TEXCOORD_0 when the rig has one UV per vertex (an OBJ rig with UV
seams exports without: splitting its vertices would break the vertex order), fan-triangulated uint32 indices,
one material, and one morph target per blend shape of ``model.export.ExportContent`` (the rig's shapes, then its
correctives: POSITION offsets and the NORMAL offsets of the surface at that target's weight 1, each a sparse
accessor of the vertices it moves where that is smaller), named in
``mesh.extras.targetNames`` (the de facto convention of Blender, three.js, Babylon.js and Unreal).
Without NORMAL a client must shade the mesh flat (glTF 2.0, 3.7.2.1: Blender 3.4 imported every one of ICT's
52,220 faces flat); without a material it uses glTF's default, fully metallic, which looks dark in a viewer
without an environment. The material is dielectric and double-sided (the eyelashes and the mouth bag are open
sheets), its colour the part's with most faces where the file gave it one, else a light grey.
The rig's parts (its faces by material, ``model.parts``) are not split into primitives: Blender's importer gives
each primitive its own copy of the vertices it uses, which renumbers the vertices and doubles them at a seam
between parts (ICT FaceKit: 362 between the face and the back of the head), and vertex order is what caches and
marker maps rely on; the USD and OBJ exports carry the parts and their colours.
The current pose is the mesh's default ``weights``; an animation is one LINEAR sampler on the node's
``weights`` path with one key per frame, so every frame plays exactly the weights (and corrective
activations) the application computed. Written atomically (model.atomic).
"""
from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from solvers.mesh import bounds
from solvers.normals import VertexNormals

from .atomic import atomic_write_with
from .errors import RigInputError

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
FLOAT, UNSIGNED_INT = 5126, 5125


def _pad4(b: bytes, fill: bytes = b"\x00") -> bytes:
    return b + fill * (-len(b) % 4)


class _Buffer:
    """Accumulates 4-byte aligned buffer views and their accessors."""

    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.views: list[dict] = []
        self.accessors: list[dict] = []
        self.length = 0

    def view(self, arr: np.ndarray, target: int | None = None) -> int:
        """A buffer view of ``arr``'s bytes; its index."""
        data = np.ascontiguousarray(arr).tobytes()
        view = {"buffer": 0, "byteOffset": self.length, "byteLength": len(data)}
        if target:
            view["target"] = target
        self.views.append(view)
        padded = _pad4(data)
        self.blobs.append(padded)
        self.length += len(padded)
        return len(self.views) - 1

    def add(self, arr: np.ndarray, accessor: dict, target: int | None = None) -> int:
        accessor["bufferView"] = self.view(arr, target)
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def floats(self, arr: np.ndarray, typ: str, *, bounds: bool, target: int | None = None) -> int:
        a = np.asarray(arr, dtype="<f4")
        n = {"SCALAR": 1, "VEC3": 3}[typ]
        a2 = a.reshape(-1, n)
        acc = {"componentType": FLOAT, "count": int(a2.shape[0]), "type": typ}
        if bounds:  # glTF requires min/max of POSITION, morph target POSITION and animation inputs
            acc["min"], acc["max"] = _min_max(a2)
        return self.add(a2, acc, target)

    def offsets(self, arr: np.ndarray, *, bounds: bool) -> int:
        """A morph target's (V, 3) offsets: a sparse accessor (glTF 2.0, 3.6.2.3: zeros, then the rows that are
        not zero at their indices) where that is the smaller, as a shape that moves part of the face is (ICT's
        move 44% of its vertices on average); dense otherwise. ``bounds``: min and max (of all V rows)."""
        a = np.asarray(arr, dtype="<f4").reshape(-1, 3)
        rows = np.flatnonzero((a[:, 0] != 0) | (a[:, 1] != 0) | (a[:, 2] != 0)).astype("<u4")  # rows that move
        if 16 * rows.size >= 12 * len(a):                 # an index and a value each against a value each
            return self.floats(a, "VEC3", bounds=bounds, target=ARRAY_BUFFER)
        acc = {"componentType": FLOAT, "count": int(len(a)), "type": "VEC3"}
        if bounds:
            acc["min"], acc["max"] = _min_max(a)
        if rows.size:                                      # none: no buffer view, all zeros
            acc["sparse"] = {"count": int(rows.size),
                             "indices": {"bufferView": self.view(rows), "componentType": UNSIGNED_INT},
                             "values": {"bufferView": self.view(a[rows])}}
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def blob(self) -> bytes:
        return b"".join(self.blobs)


def _min_max(a: np.ndarray) -> tuple[list, list]:
    """An accessor's "min" and "max" of its (n, k) values, a column at a time (``solvers.mesh.bounds``: numpy's
    reduction of a (V, 3) array along its first axis is ~20x slower; two per morph target of a studio rig)."""
    if not a.size:
        return [0.0] * a.shape[1], [0.0] * a.shape[1]
    lo, hi = bounds(a)
    return lo.astype(float).tolist(), hi.astype(float).tolist()


DEFAULT_COLOR = (0.8, 0.8, 0.8)      # a part without a colour from its file


def _unit_normals(normals, points: np.ndarray) -> np.ndarray:
    """(V, 3) unit vertex normals of ``points`` (``VertexNormals``), +z where no face gives one (a vertex no face
    uses, or only degenerate ones): glTF requires every NORMAL to be of unit length."""
    n = np.asarray(normals(np.asarray(points, dtype=np.float32)), dtype=np.float32)
    n[~(np.abs(n).sum(axis=1) > 0)] = (0.0, 0.0, 1.0)
    return n


def _material(parts) -> dict:
    """The primitive's one material (module docstring): the colour of the part with most faces, if it has one."""
    name, color = "surface", DEFAULT_COLOR
    if parts is not None and parts.names:
        counts = np.bincount(parts.face_part[parts.face_part >= 0], minlength=len(parts.names))
        k = int(np.argmax(counts))
        name = parts.names[k]
        if not np.isnan(parts.colors[k]).any():
            color = tuple(float(c) for c in parts.colors[k])
    return {"name": name, "doubleSided": True,
            "pbrMetallicRoughness": {"baseColorFactor": [*map(float, color), 1.0], "metallicFactor": 0.0,
                                     "roughnessFactor": 0.5}}


def gltf_document(content) -> tuple[dict, "_Buffer"]:
    """The glTF JSON document and its one binary buffer (its views' bytes in order: ``_Buffer.blobs``) for an
    ``ExportContent``."""
    from .rig import fan_triangulate
    buf = _Buffer()
    i_pos = buf.floats(content.neutral, "VEC3", bounds=True, target=ARRAY_BUFFER)
    tris = fan_triangulate(content.face_counts, content.face_indices).astype("<u4").reshape(-1)
    i_idx = buf.add(tris, {"componentType": UNSIGNED_INT, "count": int(tris.size), "type": "SCALAR"},
                    ELEMENT_ARRAY_BUFFER)
    normals = VertexNormals(content.face_counts, content.face_indices, len(content.neutral))
    rest = _unit_normals(normals, content.neutral)
    i_nrm = buf.floats(rest, "VEC3", bounds=False, target=ARRAY_BUFFER)
    targets = [{"POSITION": buf.offsets(d, bounds=True),
                "NORMAL": buf.offsets(_unit_normals(normals, content.neutral + d) - rest, bounds=False)}
               for d in content.deltas]
    primitive = {"attributes": {"POSITION": i_pos, "NORMAL": i_nrm}, "indices": i_idx, "mode": 4, "material": 0}
    if content.uvs is not None:   # TEXCOORD_0: glTF's v runs down the image (the rig's, as OBJ's, up)
        uv = np.asarray(content.uvs, dtype=np.float64)
        primitive["attributes"]["TEXCOORD_0"] = buf.add(
            np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1).astype("<f4"),
            {"componentType": FLOAT, "count": int(uv.shape[0]), "type": "VEC2"}, ARRAY_BUFFER)
    if targets:
        primitive["targets"] = targets
    mesh = {"name": content.name, "primitives": [primitive]}
    if targets:
        mesh["weights"] = [float(w) for w in np.asarray(content.pose, dtype=np.float32)]
        mesh["extras"] = {"targetNames": list(content.names)}
    gltf: dict = {
        "asset": {"version": "2.0", "generator": "Blendshape Studio"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": content.name}],
        "meshes": [mesh],
        "materials": [_material(content.parts)],
    }
    if content.times is not None and targets:
        i_in = buf.floats(content.times, "SCALAR", bounds=True)
        i_out = buf.floats(content.frames.reshape(-1), "SCALAR", bounds=False)
        gltf["animations"] = [{"name": "weights",
                               "samplers": [{"input": i_in, "output": i_out, "interpolation": "LINEAR"}],
                               "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}]
    gltf.update({"accessors": buf.accessors, "bufferViews": buf.views, "buffers": [{"byteLength": buf.length}]})
    gltf["extras"] = {"units": content.units, "up": content.up}
    return gltf, buf


def write_gltf_content(content, path: str | Path) -> None:
    """Write an ``ExportContent`` as ``.glb`` or ``.gltf`` (buffer embedded as base64), atomically; a ``.glb``'s
    buffer views are written one after the other, never joined into one more copy of the file in memory (0.64 GB
    for a 422k-vertex, 228-shape rig, three such copies before)."""
    chunks = gltf_chunks(content, path)
    atomic_write_with(path, lambda f: [f.write(chunk) for chunk in chunks])


def gltf_bytes(content, path: str | Path) -> bytes:
    """The ``.glb`` or ``.gltf`` file (by ``path``'s extension) of an ``ExportContent``, for writers of file sets."""
    return b"".join(gltf_chunks(content, path))


def gltf_chunks(content, path: str | Path) -> list[bytes]:
    """The ``.glb`` or ``.gltf`` file (by ``path``'s extension) of an ``ExportContent`` as the byte strings that make
    it, in order."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".gltf", ".glb"):
        raise RigInputError(f"{path}: write glTF to a .gltf or .glb file.")
    gltf, buf = gltf_document(content)
    if suffix == ".gltf":
        gltf["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(buf.blob()).decode(
            "ascii")
        return [json.dumps(gltf).encode("utf-8")]
    js = _pad4(json.dumps(gltf).encode("utf-8"), b" ")
    body_length = 8 + len(js) + 8 + buf.length
    return [struct.pack("<4sII", GLB_MAGIC, 2, 12 + body_length), struct.pack("<II", len(js), CHUNK_JSON), js,
            struct.pack("<II", buf.length, CHUNK_BIN), *buf.blobs]
