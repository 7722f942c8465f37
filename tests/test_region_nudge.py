"""The region nudge's smooth falloff over the overlap rings (solvers.region_nudge.ring_falloff; issue 18)."""
from __future__ import annotations

import numpy as np
import pytest

from model.errors import RigInputError
from solvers.laplacian import mesh_adjacency
from solvers.region_nudge import nudge_region, ring_falloff


def _strip(n=12, m=4):
    """A grid of n columns x m rows of quads; vertex (i, j) = j * n + i."""
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(m, dtype=float))
    pts = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(n * m)])
    quads = [[j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i] for j in range(m - 1) for i in range(n - 1)]
    return pts, np.full(len(quads), 4), np.array(quads).ravel()


def test_falloff_is_one_on_the_core_and_smoothly_down_the_rings():
    pts, fc, fi = _strip()
    n, m = 12, 4
    col = pts[:, 0].astype(int)
    core = np.flatnonzero(col <= 3)
    vertices = np.flatnonzero(col <= 6)          # three overlap rings: columns 4, 5, 6
    A = mesh_adjacency(len(pts), fc, fi)
    w = ring_falloff(A, core, vertices)
    by_col = {c: np.unique(np.round(w[col[vertices] == c], 12)) for c in range(7)}
    assert all(len(v) == 1 for v in by_col.values())              # one weight per ring
    ring = [by_col[c][0] for c in range(3, 7)]
    assert ring[0] == 1.0
    np.testing.assert_allclose(ring[1:], [0.84375, 0.5, 0.15625])   # smoothstep of 3/4, 1/2, 1/4
    # nudged: the region moves, the edge has no cliff (the step to the outside is the smallest one)
    moved = nudge_region(pts, vertices, 1.0, direction=np.array([0, 0, 1.0]), weights=w)[:, 2]
    steps = np.abs(np.diff([moved[col == c][0] for c in range(n)]))
    assert steps.max() < 0.4 and steps[6] < 0.2 and moved[col == 7].max() == 0.0


def test_a_region_without_rings_is_its_core_and_a_stray_core_is_refused():
    pts, fc, fi = _strip()
    A = mesh_adjacency(len(pts), fc, fi)
    core = np.arange(5)
    np.testing.assert_array_equal(ring_falloff(A, core, core), np.ones(5))
    with pytest.raises(RigInputError):
        ring_falloff(A, np.array([40]), core)
