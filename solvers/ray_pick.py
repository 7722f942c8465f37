"""Which faces a pick ray can meet, so that a picker intersects only those (``widgets.picking``): each face's
bounding box (once per pose), and the boxes the ray's line passes within a margin of (the slab test, Kay & Kajiya
1986). A face the ray meets within a distance d of it (VTK's pick tolerance) has its box within d of the line, so
with a margin of at least d the faces returned are all the faces the ray can meet, in their order. Pure numpy.
"""
from __future__ import annotations

import numpy as np


def face_boxes(points: np.ndarray, offsets: np.ndarray, connectivity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (F, 3) float64: the bounding box of each face of a cell array (``offsets`` (F + 1,),
    ``connectivity``: VTK's layout, ``solvers.mesh.cell_layout``) over (V, 3) ``points``. Faces have ≥ 1 vertex."""
    p = np.asarray(points)
    starts = np.asarray(offsets, dtype=np.int64)[:-1]
    ids = np.asarray(connectivity, dtype=np.int64)
    lo = np.empty((starts.size, 3))
    hi = np.empty((starts.size, 3))
    for k in range(3):          # column by column (``solvers.mesh.bounds``)
        c = p[:, k][ids]
        lo[:, k] = np.minimum.reduceat(c, starts)
        hi[:, k] = np.maximum.reduceat(c, starts)
    return lo, hi


def faces_near_ray(lo: np.ndarray, hi: np.ndarray, origin, direction, margin: float) -> np.ndarray:
    """Ascending indices of the boxes (``face_boxes``) that the line origin + t·direction (any t) passes through
    when each is grown by ``margin`` on every side."""
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    enter = np.full(len(lo), -np.inf)
    leave = np.full(len(lo), np.inf)
    for k in range(3):
        a, b = lo[:, k] - margin - o[k], hi[:, k] + margin - o[k]
        if d[k] == 0.0:         # parallel to the slab: inside it everywhere or nowhere
            out = (a > 0.0) | (b < 0.0)
            enter[out], leave[out] = np.inf, -np.inf
            continue
        t0, t1 = a / d[k], b / d[k]
        np.maximum(enter, np.minimum(t0, t1), out=enter)
        np.minimum(leave, np.maximum(t0, t1), out=leave)
    return np.flatnonzero(enter <= leave)
