"""Smooth-shading vertex normals of a polygon mesh whose points move but whose faces do not.

The area-weighted vertex normal (the standard smooth-shading normal, e.g. Max 1999, "Weights for computing
vertex normals from facet normals"): n_v = normalize(sum over triangles t at v of (e1_t x e2_t)), the cross
product of a triangle's edges being its normal times twice its area. Polygons are fanned into triangles once;
the sum onto corners is one precomputed sparse (V, T) incidence product, ~2 ms on ICT FaceKit.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .mesh import fan_triangulate

NORMAL_SCALE = 127.0  # int8 quantisation of unit normals: 3 bytes a vertex, about half a degree of error


def vertex_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(V, 3) float64 unit area-weighted vertex normals of a triangle mesh, for one-off use (sculpting,
    nudging along the normal); zero for vertices in no triangle. ``VertexNormals`` is the same in float32 with
    the faces' incidence built once, for surfaces redrawn every frame."""
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    fn = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    corners = t.ravel()
    vn = np.stack([np.bincount(corners, weights=np.repeat(fn[:, c], 3), minlength=p.shape[0]) for c in range(3)],
                  axis=1)
    length = np.linalg.norm(vn, axis=1, keepdims=True)
    return np.divide(vn, length, out=np.zeros_like(vn), where=length > 0)


def compact_faces(face_indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(used, local): the sorted vertex indices the polygons use, and the polygons' corners renumbered
    into them (``used[local] == face_indices``). Drawing a part of a mesh then moves only its own points."""
    idx = np.asarray(face_indices, dtype=np.int64)
    used, local = np.unique(idx, return_inverse=True)
    return used, local.reshape(idx.shape)


class VertexNormals:
    """``normals(points)`` -> (V, 3) float32 unit vertex normals for the fixed faces given here
    (zero for vertices no face uses); ``normals.quantised(points)`` -> the same as int8 (x 127)."""

    def __init__(self, face_counts: np.ndarray, face_indices: np.ndarray, n_points: int) -> None:
        self.tris = fan_triangulate(face_counts, face_indices)
        self._flat = self.tris.ravel().astype(np.intp)
        T = len(self.tris)
        self.n_points = n_points
        self.incidence = sp.csr_matrix((np.ones(3 * T, np.float32), (self.tris.ravel(), np.repeat(np.arange(T), 3))),
                                       shape=(n_points, T))

    def face_normals(self, points: np.ndarray) -> np.ndarray:
        """(T, 3) float32 e1 x e2 of each triangle: its normal times twice its area (winding-signed)."""
        p = np.asarray(points, dtype=np.float32)
        corners = np.take(p, self._flat, axis=0).reshape(-1, 3, 3)  # (T, 3, 3): np.take is 5x fancy indexing
        e1 = corners[:, 1] - corners[:, 0]
        e2 = corners[:, 2] - corners[:, 0]
        fn = np.empty_like(e1)                      # the cross product, written out (np.cross is slower)
        fn[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
        fn[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
        fn[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        return fn

    def __call__(self, points: np.ndarray) -> np.ndarray:
        out = np.asarray(self.incidence @ self.face_normals(points), dtype=np.float32)
        length = np.linalg.norm(out, axis=1, keepdims=True)
        out /= np.where(length > 0, length, 1.0)
        return out

    def quantised(self, points: np.ndarray) -> np.ndarray:
        """The normals as int8 (unit length x 127): a quarter of the memory, for caching many frames."""
        return np.rint(self(points) * NORMAL_SCALE).astype(np.int8)


def dequantise(normals: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """int8 normals from ``VertexNormals.quantised`` back to float32 (near unit length), into ``out`` if given."""
    return np.multiply(normals, np.float32(1.0 / NORMAL_SCALE), out=out, dtype=np.float32)
