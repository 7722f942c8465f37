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
    offsets = np.asarray(offsets, dtype=np.int64)
    starts = offsets[:-1]
    ids = np.asarray(connectivity, dtype=np.int64)
    lo = np.empty((starts.size, 3))
    hi = np.empty((starts.size, 3))
    counts = np.diff(offsets)
    sizes = np.unique(counts)
    # faces of a few sizes (triangles and quads): their i-th vertices compared a size at a time, half the time of
    # reduceat (4.6 ms on ICT)
    groups = [(np.flatnonzero(counts == n), int(n)) for n in sizes] if len(sizes) <= 8 else None
    for k in range(3):          # column by column (``solvers.mesh.bounds``)
        c = p[:, k][ids]
        if groups is None:
            lo[:, k] = np.minimum.reduceat(c, starts)
            hi[:, k] = np.maximum.reduceat(c, starts)
            continue
        for faces, n in groups:
            first = starts[faces]
            low = high = c[first]
            for i in range(1, n):
                low, high = np.minimum(low, c[first + i]), np.maximum(high, c[first + i])
            lo[faces, k], hi[faces, k] = low, high
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
