"""solvers.ray_pick: the faces a pick ray can meet are among the faces it returns, checked against a ray-triangle
intersection of every face (Möller & Trumbore 1997) and the distance of the line to each face's vertices."""
from __future__ import annotations

import numpy as np

from solvers.mesh import cell_layout
from solvers.ray_pick import face_boxes, faces_near_ray


def _met(tris, o, d):
    """Which (T, 3, 3) triangles the line o + t·d meets (Möller–Trumbore, any t)."""
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - tris[:, 0]
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1)


def test_face_boxes_of_mixed_polygons():
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0], [0, 1, 3], [-1, 5, 1]], dtype=np.float32)
    counts, idx = np.array([3, 4]), np.array([0, 1, 2, 1, 2, 3, 4])
    lo, hi = face_boxes(pts, *cell_layout(counts, idx))
    np.testing.assert_array_equal(lo, [[0, 0, 0], [-1, 0, 0]])
    np.testing.assert_array_equal(hi, [[1, 2, 0], [1, 5, 3]])
    # faces of many sizes (one face each of 3 to 12 vertices), against each face's own min and max
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(60, 3))
    counts = np.arange(3, 13)
    idx = rng.integers(0, 60, counts.sum())
    offsets, connectivity = cell_layout(counts, idx)
    lo, hi = face_boxes(pts, offsets, connectivity)
    for f in range(len(counts)):
        own = pts[connectivity[offsets[f]:offsets[f + 1]]]
        np.testing.assert_array_equal(lo[f], own.min(axis=0))
        np.testing.assert_array_equal(hi[f], own.max(axis=0))


def test_every_face_the_ray_meets_is_returned_in_order():
    rng = np.random.default_rng(3)
    centres = rng.uniform(-10, 10, (4000, 1, 3))
    tris = centres + rng.normal(0, 0.4, (4000, 3, 3))
    pts = tris.reshape(-1, 3)
    offsets, connectivity = cell_layout(np.full(4000, 3), np.arange(12000))
    lo, hi = face_boxes(pts, offsets, connectivity)
    for _ in range(40):
        o = rng.uniform(-12, 12, 3)
        d = rng.normal(size=3)
        if _ % 4 == 0:
            d[rng.integers(3)] = 0.0          # parallel to a pair of slabs
        got = faces_near_ray(lo, hi, o, d, margin=0.0)
        assert np.all(np.diff(got) > 0)
        assert set(np.flatnonzero(_met(tris, o, d))) <= set(got)
        # with a margin: every face with a vertex within it of the line as well
        margin = 0.3
        u = d / np.linalg.norm(d)
        r = pts - o
        dist = np.linalg.norm(r - np.outer(r @ u, u), axis=1).reshape(-1, 3).min(axis=1)
        near = faces_near_ray(lo, hi, o, d, margin)
        assert set(np.flatnonzero(dist <= margin)) <= set(near) and set(got) <= set(near)
        assert len(near) < 1000                # and not everything
