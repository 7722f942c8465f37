"""Polygon-mesh helpers shared by the solvers (no model objects: counts and flat indices)."""
from __future__ import annotations

import numpy as np


def fan_triangulate(face_counts: np.ndarray, face_indices: np.ndarray) -> np.ndarray:
    """(T, 3) triangles of polygons given as counts + flat indices (fan from each first vertex)."""
    counts = np.asarray(face_counts, dtype=np.int64)
    idx = np.asarray(face_indices)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    ntri = np.maximum(counts - 2, 0)
    face_of_tri = np.repeat(np.arange(counts.size), ntri)
    k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)  # triangle number in face
    s = starts[face_of_tri]
    return np.stack([idx[s], idx[s + k + 1], idx[s + k + 2]], axis=1).astype(np.int32)
