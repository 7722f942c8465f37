"""Left/right symmetry on ICT FaceKit: the mirror map, and the mirror image of a regional pose."""
from __future__ import annotations

import numpy as np
import pytest

from model.pose import PoseEvaluator
from model.segmentation import SegmentationSettings, segment_rig
from model.sides import mirror_indices
from solvers.symmetry import REFLECT_X, mirror_error, mirror_map, mirrored_region_weights


@pytest.fixture(scope="module")
def ict_level(ict_rig):
    seg = segment_rig(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, ict_rig.deltas,
                      SegmentationSettings(t=0.75))
    return seg.levels[len(seg.levels) // 2]


def test_mirror_map_of_ict_is_an_involution_on_the_face(ict_rig):
    m = mirror_map(ict_rig.neutral)
    face = np.arange(9409)
    assert mirror_error(ict_rig.neutral, m)[face].max() < 0.01           # cm
    assert (m[m[face]] == face).mean() > 0.99                            # mirroring twice comes back


def test_mirrored_regional_pose_on_ict(ict_rig, ict_level):
    """A regional pose's mirror image on the same regions: exact for a pose that is the same in every region;
    for arbitrary per-region weights the nearest regional pose, a few per cent of the motion off."""
    blend, K = ict_level.blend, ict_rig.n_shapes
    R = blend.shape[1]
    m, P = mirror_map(ict_rig.neutral), mirror_indices(ict_rig.shape_names)
    ev = PoseEvaluator(ict_rig, dtype=np.float64)
    rng = np.random.default_rng(0)
    w = np.zeros(K)
    w[[ict_rig.shape_index(n) for n in ("browInnerUp_L", "mouthSmile_R", "eyeBlink_L")]] = (0.8, 0.6, 1.0)
    same = np.tile(w, (R, 1))
    np.testing.assert_allclose(mirrored_region_weights(same, blend, m, P), np.tile(w[P], (R, 1)), atol=1e-9)
    W = rng.uniform(0.0, 0.5, (R, K))
    W2 = mirrored_region_weights(W, blend, m, P)
    assert W2.shape == W.shape and W2.min() >= 0 and W2.max() <= 1
    x, x2 = ev.evaluate_regional(W, blend), ev.evaluate_regional(W2, blend)
    face = np.arange(9409)
    err = np.linalg.norm(x2[face] - (x[m] * REFLECT_X)[face], axis=1)
    motion = np.linalg.norm(x[face] - ict_rig.neutral[face], axis=1)
    rel = np.sqrt((err ** 2).mean()) / np.sqrt((motion ** 2).mean())
    print(f"\nICT, {R} regions, random weights: mirror image off by {100 * rel:.1f} % RMS of the motion")
    assert rel < 0.1


def test_mirror_lookup_is_the_kd_tree_answer(ict_rig):
    """The hashed lookup of exact mirror images gives the k-d tree's nearest vertex and distance, for every
    vertex and for a subset, on ICT (123 positions shared by two vertices: those go to the tree)."""
    from scipy.spatial import cKDTree
    from solvers.symmetry import MirrorLookup
    p = ict_rig.neutral
    dist, idx = cKDTree(p).query(p * REFLECT_X)
    lookup = MirrorLookup(p)
    d_all, i_all = lookup()
    assert np.array_equal(i_all, idx) and np.array_equal(d_all, dist)
    some = np.random.default_rng(0).choice(p.shape[0], 5000, replace=False)
    d_some, i_some = lookup(some)
    assert np.array_equal(i_some, idx[some]) and np.array_equal(d_some, dist[some])
    assert np.array_equal(mirror_map(p), idx)
