"""An independent reading of glTF files (pygltflib for the JSON and buffers, numpy for the accessors,
scipy for the node rotations), to check model/gltf.py and model/export_gltf.py against."""
from __future__ import annotations

import base64

import numpy as np
import pytest

_NP = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_NORM = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}


def reference_accessors(path):
    """(the pygltflib document, values(accessor index) -> (count, width) float64 with sparse and normalisation)."""
    pygltflib = pytest.importorskip("pygltflib")
    g = pygltflib.GLTF2().load(str(path))

    cache: dict[int, bytes] = {}

    def buffer_bytes(i):
        if i not in cache:
            b = g.buffers[i]
            # pygltflib decodes only application/octet-stream data URIs; SimpleMorph's is application/gltf-buffer
            cache[i] = g.binary_blob() if b.uri is None else base64.b64decode(b.uri.split(",", 1)[1])
        return cache[i]

    def view_values(view_index, offset, ctype, width, count):
        v = g.bufferViews[view_index]
        dt = np.dtype(_NP[ctype])
        stride = v.byteStride or dt.itemsize * width
        raw = np.frombuffer(buffer_bytes(v.buffer), np.uint8)[(v.byteOffset or 0) + offset:]
        rows = np.lib.stride_tricks.sliding_window_view(raw, dt.itemsize * width)[::stride][:count]
        assert rows.shape[0] == count, "an accessor reads past its buffer"
        return np.ascontiguousarray(rows).view(dt).astype(np.float64).reshape(count, width)

    def values(i):
        a = g.accessors[i]
        w = _WIDTH[a.type]
        out = (view_values(a.bufferView, a.byteOffset or 0, a.componentType, w, a.count)
               if a.bufferView is not None else np.zeros((a.count, w)))
        if a.sparse is not None:
            s = a.sparse
            idx = view_values(s.indices.bufferView, s.indices.byteOffset or 0, s.indices.componentType, 1, s.count)
            val = view_values(s.values.bufferView, s.values.byteOffset or 0, a.componentType, w, s.count)
            out[idx[:, 0].astype(int)] = val
        if a.normalized:
            out = np.maximum(out / _NORM[a.componentType], -1.0)
        return out

    return g, values


def reference_animation(path):
    """(times (F,), weights (F, targets)) of the first animation's weights channel."""
    g, values = reference_accessors(path)
    sampler = g.animations[0].samplers[g.animations[0].channels[0].sampler]
    assert g.animations[0].channels[0].target.path == "weights" and sampler.interpolation == "LINEAR"
    times = values(sampler.input)[:, 0]
    return times, values(sampler.output)[:, 0].reshape(times.size, -1)


def reference_mesh(path):
    """Vertices, triangles, target names and deltas of the mesh with the most targets, read with pygltflib,
    plain numpy and scipy's rotations, with its node's world transform (parents first) applied."""
    from scipy.spatial.transform import Rotation
    g, values = reference_accessors(path)

    def local(n):
        if n.matrix is not None and any(n.matrix):
            return np.array(n.matrix, dtype=np.float64).reshape(4, 4).T
        m = np.eye(4)
        r = Rotation.from_quat(n.rotation or [0, 0, 0, 1]).as_matrix()
        m[:3, :3] = r @ np.diag(n.scale or [1, 1, 1])
        m[:3, 3] = n.translation or [0, 0, 0]
        return m

    mi = max(range(len(g.meshes)), key=lambda i: (max(len(p.targets or []) for p in g.meshes[i].primitives),
                                                  sum(g.accessors[p.attributes.POSITION].count
                                                      for p in g.meshes[i].primitives), -i))
    mesh = g.meshes[mi]
    parents = {c: i for i, n in enumerate(g.nodes) for c in (n.children or [])}
    node = next(i for i, n in enumerate(g.nodes) if n.mesh == mi)
    world = np.eye(4)
    while node is not None:
        world = local(g.nodes[node]) @ world
        node = parents.get(node)
    K = max(len(p.targets or []) for p in mesh.primitives)
    pos, deltas, tris, off = [], [], [], 0
    for p in mesh.primitives:
        x = values(p.attributes.POSITION)
        pos.append(x)
        deltas.append(np.stack([values(t["POSITION"]) for t in p.targets]) if p.targets else np.zeros((K,) + x.shape))
        tris.append(values(p.indices)[:, 0].astype(int).reshape(-1, 3) + off)
        off += len(x)
    names = (mesh.extras or {}).get("targetNames") or [f"target_{k}" for k in range(K)]
    A = world[:3, :3]
    tris = np.concatenate(tris)
    if np.linalg.det(A) < 0:
        tris = tris[:, [0, 2, 1]]
    return (np.concatenate(pos) @ A.T + world[:3, 3], tris, list(names), np.concatenate(deltas, axis=1) @ A.T)

