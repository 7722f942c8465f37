"""Smooth-shading vertex normals of a polygon mesh whose points move but whose faces do not.

The area-weighted vertex normal (the standard smooth-shading normal, e.g. Max 1999, "Weights for computing
vertex normals from facet normals"): n_v = normalize(sum over triangles t at v of (e1_t x e2_t)), the cross
product of a triangle's edges being its normal times twice its area. Polygons are fanned into triangles once;
the sum onto corners is one precomputed sparse (V, T) incidence product per axis, ~1 ms on ICT FaceKit; where
the compiled kernels are built (``solvers.take_kernel``), one pass over the triangles does the same arithmetic in the
same order (``shape_kernels_jit.vertex_normals32``), ~0.3 ms.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .mesh import fan_triangulate

def _compiled():
    """The built kernel module (``solvers.take_kernel.built``: never builds it, never imports numba), or None."""
    from . import take_kernel
    return take_kernel.built()


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
        self._corners = [np.ascontiguousarray(self.tris[:, c], dtype=np.intp) for c in range(3)]
        self.n_points = n_points
        self._incidence: sp.csr_matrix | None = None

    @property
    def incidence(self) -> sp.csr_matrix:
        """(V, T) sparse corner incidence of the triangles, for ``numpy`` (where the compiled kernel is not built):
        made on first use (0.15 s at 422k vertices, which the compiled path never needs)."""
        if self._incidence is None:
            T = len(self.tris)
            self._incidence = sp.csr_matrix(
                (np.ones(3 * T, np.float32), (self.tris.ravel(), np.repeat(np.arange(T), 3))), shape=(self.n_points, T))
        return self._incidence

    def _face_normal_components(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y, z of e1 x e2 of each triangle, each (T,) float32. Coordinates gathered one axis at a time
        from contiguous copies (structure of arrays): about 3x faster than gathering (T, 3, 3) corners."""
        x, y, z = np.array(np.asarray(points, dtype=np.float32).T)   # (3, V) contiguous
        a, b, c = self._corners
        ax, ay, az = x[a], y[a], z[a]
        e1x, e1y, e1z = x[b] - ax, y[b] - ay, z[b] - az
        e2x, e2y, e2z = x[c] - ax, y[c] - ay, z[c] - az
        return e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x

    def face_normals(self, points: np.ndarray) -> np.ndarray:
        """(T, 3) float32 e1 x e2 of each triangle: its normal times twice its area (winding-signed)."""
        return np.stack(self._face_normal_components(points), axis=1)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        compiled = _compiled()
        if compiled is not None and points.shape == (self.n_points, 3):
            # one pass over the triangles in the compiled kernel, the same bits (~0.3 ms on ICT FaceKit, every
            # frame the viewport draws)
            out = np.empty((self.n_points, 3), dtype=np.float32)
            compiled.vertex_normals32(np.ascontiguousarray(points, dtype=np.float32), *self._corners, out)
            return out
        return self.numpy(points)

    def numpy(self, points: np.ndarray) -> np.ndarray:
        """``self(points)`` with numpy and scipy's sparse product (where the compiled kernel is not built)."""
        # per axis: the triangles' normals summed onto their corners, then normalised (~1 ms on ICT FaceKit)
        n = [self.incidence @ f for f in self._face_normal_components(points)]
        length = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        inv = np.divide(1.0, length, out=np.ones_like(length), where=length > 0)
        out = np.empty((self.n_points, 3), dtype=np.float32)
        for c in range(3):
            np.multiply(n[c], inv, out=out[:, c])
        return out

    def quantised(self, points: np.ndarray) -> np.ndarray:
        """The normals as int8 (unit length x 127): a quarter of the memory, for caching many frames."""
        return np.rint(self(points) * NORMAL_SCALE).astype(np.int8)


def dequantise(normals: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """int8 normals from ``VertexNormals.quantised`` back to float32 (near unit length), into ``out`` if given."""
    return np.multiply(normals, np.float32(1.0 / NORMAL_SCALE), out=out, dtype=np.float32)
