"""Left/right symmetry of a face mesh across x = 0: the vertex mirror map, how far the mesh is from
symmetric, and mirror images of per-vertex fields and of regional poses. Pure numpy / scipy.

The mirror map is the nearest neutral vertex to each reflected vertex (scipy cKDTree), the usual way of
Maya's and Blender's position-based symmetry when the topology is not known to be symmetric.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .mesh import extent

REFLECT_X = np.array([-1.0, 1.0, 1.0])  # M = diag(−1, 1, 1), the reflection across x = 0


class MirrorLookup:
    """``mirror_map`` of one mesh for any of its vertices: ``lookup(vertices)`` is ``mirror_map(neutral)[vertices]``
    (and the distances), built once per mesh.

    A vertex whose reflection is exactly the position of one vertex, and of no other, has that vertex as its
    nearest (at distance 0): those are found by hashing the positions (most of a symmetric mesh). The others
    (no exact image, or an image shared by several vertices) go to the k-d tree, built on first need."""

    _MIX = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9], dtype=np.uint64)

    def __init__(self, neutral):
        self.points = np.asarray(neutral, dtype=np.float64)
        self._tree = None
        h = self._hash(self.points)
        self._order = np.argsort(h)
        self._sorted = h[self._order]

    @classmethod
    def _hash(cls, p: np.ndarray) -> np.ndarray:
        bits = np.ascontiguousarray(p + 0.0).view(np.uint64)  # + 0.0: -0.0 and 0.0 hash alike
        return bits[:, 0] * cls._MIX[0] + bits[:, 1] * cls._MIX[1] + bits[:, 2] * cls._MIX[2]

    @property
    def tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = cKDTree(self.points)
        return self._tree

    def __call__(self, vertices=None) -> tuple[np.ndarray, np.ndarray]:
        """(distance, index) of the nearest vertex to the reflection of each of ``vertices`` (all if None)."""
        p = self.points if vertices is None else self.points[np.asarray(vertices, dtype=np.int64)]
        q = p * REFLECT_X
        n = self._sorted.size
        dist, idx = np.zeros(q.shape[0]), np.zeros(q.shape[0], dtype=np.int64)
        if n == 0 or q.shape[0] == 0:
            return dist, idx
        h = self._hash(q)
        pos = np.searchsorted(self._sorted, h)
        at = np.minimum(pos, n - 1)
        nxt = np.minimum(pos + 1, n - 1)
        cand = self._order[at]
        exact = (self._sorted[at] == h) & ((self._sorted[nxt] != h) | (pos + 1 >= n))
        c = self.points[cand]
        exact &= (c[:, 0] == q[:, 0]) & (c[:, 1] == q[:, 1]) & (c[:, 2] == q[:, 2])
        idx[exact] = cand[exact]
        rest = np.flatnonzero(~exact)
        if rest.size:
            d, i = self.tree.query(q[rest])
            dist[rest], idx[rest] = d, i
        return dist, idx


def mirror_map(neutral, tolerance: float | None = None) -> np.ndarray:
    """(V,) index of each vertex's mirror image across x = 0: the nearest neutral vertex to (−x, y, z).

    With ``tolerance``, vertices whose reflection is farther than that from any vertex map to themselves.
    """
    dist, idx = MirrorLookup(neutral)()
    if tolerance is not None:
        idx[dist > tolerance] = np.flatnonzero(dist > tolerance)
    return idx


def mirror_error(neutral, mirror) -> np.ndarray:
    """(V,) distance from each vertex to the reflection of its mirror vertex, ‖M p(m(v)) − p(v)‖: 0 on an
    exactly symmetric mesh, large where the mesh has no mirror image."""
    p = np.asarray(neutral, dtype=np.float64)
    return np.linalg.norm(p[np.asarray(mirror, dtype=np.int64)] * REFLECT_X - p, axis=1)


def unmatched_vertices(neutral, mirror, field, tolerance_fraction: float = 0.005) -> tuple[int, int, float]:
    """How many of the vertices a displacement field (V, 3) moves (above 1/1000 of its peak) have no mirror
    vertex within ``tolerance_fraction`` of the mesh's size: (unmatched, moved, tolerance)."""
    p = np.asarray(neutral, dtype=np.float64)
    n = np.linalg.norm(np.asarray(field, dtype=np.float64), axis=1)
    moved = n > 1e-3 * n.max() if n.max() > 0 else n > 0
    tol = tolerance_fraction * extent(p)
    return int((moved & (mirror_error(p, mirror) > tol)).sum()), int(moved.sum()), tol


def mirror_delta(delta, mirror) -> np.ndarray:
    """(V, 3) the other side's version of a corrective: e'(v) = M e(m(v)), M = diag(−1, 1, 1), the reflection
    across x = 0, with m the vertex mirror map (``mirror_map``); the mirror of a shape, as
    Maya's Mirror Target and Blender's Mirror Shape Key make it."""
    e = np.asarray(delta, dtype=np.float64)[np.asarray(mirror, dtype=np.int64)]
    e[:, 0] *= -1.0
    return e


def mirrored_region_weights(region_weights, blend, mirror, shape_mirror) -> np.ndarray:
    """(R, K) per-region weights of the mirror image of a regional pose, on the same regions.

    The pose's per-vertex weights are w(v) = Σ_r φ_r(v) W_r (Joshi §4, ``blend`` φ (V, R)); its mirror image has
    w'(v) = P w(m(v)), P swapping each shape with its mirror shape (``shape_mirror``, (K,) indices) and m the
    vertex mirror map. When the regions are mirror images of each other this is again a regional pose (the
    regions trade places); otherwise the least-squares one closest to it, (ΦᵀΦ) W' = Φᵀ w', clipped to [0, 1].
    """
    B = sp.csr_matrix(blend, dtype=np.float64)
    W = np.asarray(region_weights, dtype=np.float64)
    target = (B @ W)[np.asarray(mirror, dtype=np.int64)][:, np.asarray(shape_mirror, dtype=np.int64)]  # w'(v)
    gram = (B.T @ B).toarray()
    W_new = np.linalg.lstsq(gram, B.T @ target, rcond=None)[0]
    return np.clip(W_new, 0.0, 1.0)
