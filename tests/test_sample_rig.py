"""The bundled sample face rig: size, orientation, named shapes doing what their names say, symmetry,
locality, overlaps, presets, OBJ round trip and a clean connected mesh."""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from model.readers import load_rig
from resources.sample_rig import build_sample_rig, sample_geometry, write_sample

REQUIRED = [
    "eyeBlink_L", "eyeBlink_R", "eyeWide_L", "eyeWide_R", "eyeSquint_L", "eyeSquint_R",
    "browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R", "browDown_L", "browDown_R",
    "mouthSmile_L", "mouthSmile_R", "mouthFrown_L", "mouthFrown_R", "mouthStretch_L", "mouthStretch_R",
    "jawOpen", "mouthPucker", "mouthFunnel", "mouthClose", "cheekPuff_L", "cheekPuff_R",
    "cheekSquint_L", "cheekSquint_R", "noseSneer_L", "noseSneer_R", "mouthLeft", "mouthRight",
    "mouthUpperUp_L", "mouthUpperUp_R", "mouthLowerDown_L", "mouthLowerDown_R",
]
MOVE = 1e-4  # cm: a vertex "moves" in a shape when its displacement exceeds this


def delta(rig, name):
    return rig.deltas[rig.shape_index(name)]


def moved(rig, name):
    return np.linalg.norm(delta(rig, name), axis=1) > MOVE


@pytest.fixture(scope="module")
def mirror(sample_rig):
    """mirror[v] = the vertex at v's position reflected across x = 0."""
    p = sample_rig.neutral
    dist, idx = cKDTree(p).query(p * [-1.0, 1.0, 1.0])
    assert dist.max() < 1e-6, "the neutral is not mirror-symmetric"
    return idx


def test_size_units_and_names(sample_rig):
    rig = sample_rig
    assert rig.units == "cm" and rig.name == "sample"
    assert rig.n_vertices >= 5000
    assert set(REQUIRED) <= set(rig.shape_names)
    assert rig.n_shapes >= 24
    lo, hi = rig.neutral.min(axis=0), rig.neutral.max(axis=0)
    assert 18.0 <= hi[1] - lo[1] <= 22.0          # face height
    assert 12.0 <= hi[0] - lo[0] <= 16.0          # width
    assert np.abs(0.5 * (lo + hi)).max() < 1.0    # centred near the origin
    counts = np.bincount(rig.face_counts)
    assert counts[4] > 0.9 * rig.n_faces          # mostly quads


def test_build_is_cached_but_returns_independent_copies():
    a = build_sample_rig()
    a.deltas[:] = 0.0
    a.neutral[:] = 0.0
    b = build_sample_rig()
    assert np.abs(b.deltas).max() > 1.0 and np.abs(b.neutral).max() > 1.0


def test_orientation_matches_ict(sample_rig, ict_rig):
    """Y up, looking down +Z, and _L on the same side of x as ICT FaceKit's _L."""
    for rig in (sample_rig, ict_rig):
        skin = rig.neutral[: min(rig.n_vertices, 9409)]
        tip = skin[np.argmax(skin[:, 2])]                     # the nose tip is the front-most point
        assert abs(tip[0]) < 0.05
        jaw = delta(rig, "jawOpen")
        chin = np.argmax(np.linalg.norm(jaw, axis=1))
        assert jaw[chin, 1] < 0 and rig.neutral[chin, 1] < tip[1]   # the chin is below and moves down
    ict_side = np.sign(ict_rig.neutral[moved(ict_rig, "browInnerUp_L"), 0].mean())
    our_side = np.sign(sample_rig.neutral[moved(sample_rig, "browInnerUp_L"), 0].mean())
    assert ict_side == our_side == 1.0


def test_left_right_pairs_are_mirror_images(sample_rig, mirror):
    names = [n for n in sample_rig.shape_names if n.endswith("_L")]
    assert len(names) >= 12
    for name in names:
        left, right = delta(sample_rig, name), delta(sample_rig, name[:-2] + "_R")
        mirrored = right[mirror] * [-1.0, 1.0, 1.0]
        np.testing.assert_allclose(left, mirrored, atol=1e-9, err_msg=name)
        assert np.abs(left).max() > 0.2, name
    left, right = delta(sample_rig, "mouthLeft"), delta(sample_rig, "mouthRight")
    np.testing.assert_allclose(left, right[mirror] * [-1.0, 1.0, 1.0], atol=1e-9)


def test_every_shape_is_local_and_smooth(sample_rig):
    rig = sample_rig
    g = sample_geometry()
    e = rig.edges()
    rest = np.linalg.norm(rig.neutral[e[:, 0]] - rig.neutral[e[:, 1]], axis=1)
    for name, d in zip(rig.shape_names, rig.deltas):
        m = np.linalg.norm(d, axis=1) > MOVE
        assert m.any(), name
        assert not m[~g.skin].any(), f"{name} moves an eyeball"
        limit = 0.5 if name != "jawOpen" else 0.7
        assert m.sum() < limit * g.skin.sum(), f"{name} is not local"
        # No edge is crushed or torn at full weight.
        x = rig.neutral + d
        ratio = np.linalg.norm(x[e[:, 0]] - x[e[:, 1]], axis=1) / rest
        assert 0.2 < ratio.min() and ratio.max() < 6.0, name


def test_jaw_open_drops_chin_and_lower_lip_and_opens_mouth(sample_rig):
    g = sample_geometry()
    d = delta(sample_rig, "jawOpen")
    p = sample_rig.neutral
    mid_up = g.mouth.upper[len(g.mouth.upper) // 2]
    mid_lo = g.mouth.lower[len(g.mouth.lower) // 2]
    assert abs(p[mid_up, 0]) < 1e-9 and abs(p[mid_lo, 0]) < 1e-9
    gap0 = p[mid_up, 1] - p[mid_lo, 1]
    gap1 = (p[mid_up] + d[mid_up])[1] - (p[mid_lo] + d[mid_lo])[1]
    assert 0 < gap0 < 0.5 and gap1 > 2.0                    # lips parted slightly, then wide open
    assert np.linalg.norm(d[mid_up]) < 0.05                 # the upper lip stays
    chin = np.flatnonzero(g.skin & (np.abs(p[:, 0]) < 0.05) & (p[:, 1] < g.mouth_y - 2.5))
    chin = chin[np.argmax(p[chin, 2])]
    assert d[chin, 1] < -2.5 and d[chin, 2] < 0             # down and back about the jaw hinge
    forehead = g.skin & (p[:, 1] > g.eye_y + 1.0)
    assert np.abs(d[forehead]).max() < 1e-6


def test_eye_blink_closes_only_that_eyes_lids(sample_rig):
    g = sample_geometry()
    p = sample_rig.neutral
    for side, sign in (("L", 1.0), ("R", -1.0)):
        d = delta(sample_rig, f"eyeBlink_{side}")
        m = np.linalg.norm(d, axis=1) > MOVE
        assert (sign * p[m, 0] > 0).all()
        assert np.linalg.norm(p[m] - g.eye_centre[side], axis=1).max() < 3.5
        assert (d[m, 1] <= 1e-9).all()                      # everything that moves goes down
        upper = g.eyes[side].upper[1:-1]
        lower = g.eyes[side].lower[1:-1]
        assert (d[upper, 1] < 0).all()
        closed = np.linalg.norm(p[upper] + d[upper] - p[lower], axis=1)
        assert closed.max() < 0.05                          # the upper lid meets the lower lid
        opened = np.linalg.norm(p[upper] - p[lower], axis=1)
        assert opened.max() > 0.8


def test_eye_wide_and_squint_move_the_lids(sample_rig):
    g = sample_geometry()
    for side in ("L", "R"):
        up = g.eyes[side].upper[1:-1]
        lo = g.eyes[side].lower[1:-1]
        wide = delta(sample_rig, f"eyeWide_{side}")
        assert (wide[up, 1] > 0).all() and wide[up, 1].max() > 0.15
        squint = delta(sample_rig, f"eyeSquint_{side}")
        assert (squint[lo, 1] > 0).all() and squint[lo, 1].max() > 0.1


def test_brows_move_up_and_down_where_named(sample_rig):
    rig, g = sample_rig, sample_geometry()
    p = rig.neutral
    for shape, dy_sign in (("browInnerUp", 1), ("browOuterUp", 1), ("browDown", -1)):
        for side, sign in (("L", 1.0), ("R", -1.0)):
            d = delta(rig, f"{shape}_{side}")
            w = np.linalg.norm(d, axis=1)
            m = w > MOVE
            assert (dy_sign * d[m, 1] > 0).all(), f"{shape}_{side}"
            centre = (p * w[:, None]).sum(axis=0) / w.sum()
            assert centre[1] > g.eye_y + 1.0                # on the brow / forehead
            assert sign * centre[0] > 0                     # on its own side
            own = (w * (sign * p[:, 0] > -0.5)).sum() / w.sum()
            assert own > 0.9, f"{shape}_{side}"              # mostly its own side and the middle
    inner = np.linalg.norm(delta(rig, "browInnerUp_L"), axis=1)
    outer = np.linalg.norm(delta(rig, "browOuterUp_L"), axis=1)
    inner_x = (p[:, 0] * inner).sum() / inner.sum()
    outer_x = (p[:, 0] * outer).sum() / outer.sum()
    assert 0 < inner_x < outer_x
    # Inner brows lift the middle of the forehead, and very little of the far side.
    right_side = p[:, 0] < -3.0
    assert inner[right_side].max() < 0.05


def test_overlaps_where_muscles_overlap(sample_rig):
    rig, g = sample_rig, sample_geometry()
    p = rig.neutral

    def mag(name):
        return np.linalg.norm(delta(rig, name), axis=1)

    mid_forehead = g.skin & (np.abs(p[:, 0]) < 0.3) & (p[:, 1] > g.eye_y + 1.5)
    both = np.minimum(mag("browInnerUp_L"), mag("browInnerUp_R"))[mid_forehead]
    assert both.max() > 0.3 * mag("browInnerUp_L").max()
    for a, b in (("browInnerUp_L", "browOuterUp_L"), ("mouthSmile_L", "cheekSquint_L"),
                 ("eyeSquint_L", "cheekSquint_L"), ("noseSneer_L", "noseSneer_R"),
                 ("mouthUpperUp_L", "mouthUpperUp_R"), ("mouthLowerDown_L", "mouthLowerDown_R")):
        overlap = np.minimum(mag(a) / mag(a).max(), mag(b) / mag(b).max())
        assert overlap.max() > 0.1, (a, b)
    # ...but the two eyes never share a vertex.
    assert not (moved(rig, "eyeBlink_L") & moved(rig, "eyeBlink_R")).any()


def test_mouth_shapes_move_the_mouth_as_named(sample_rig):
    rig, g = sample_rig, sample_geometry()
    p = rig.neutral
    corner_l = g.mouth.upper[-1] if p[g.mouth.upper[-1], 0] > 0 else g.mouth.upper[0]
    smile = delta(rig, "mouthSmile_L")[corner_l]
    frown = delta(rig, "mouthFrown_L")[corner_l]
    stretch = delta(rig, "mouthStretch_L")[corner_l]
    assert smile[1] > 0.3 and smile[0] > 0.1
    assert frown[1] < -0.3
    assert stretch[0] > 0.3
    assert delta(rig, "mouthLeft")[corner_l, 0] > 0.3 and delta(rig, "mouthRight")[corner_l, 0] < -0.3
    mid_up = g.mouth.upper[len(g.mouth.upper) // 2]
    mid_lo = g.mouth.lower[len(g.mouth.lower) // 2]
    assert delta(rig, "mouthPucker")[mid_up, 2] > 0.5                  # lips push forward
    fun = delta(rig, "mouthFunnel")
    assert fun[mid_up, 1] > 0.1 and fun[mid_lo, 1] < -0.1               # lips part into an O
    close = delta(rig, "mouthClose")
    assert close[mid_lo, 1] > 0.5 and close[mid_up, 1] <= 0
    assert delta(rig, "mouthUpperUp_L")[mid_up, 1] > 0.1
    assert delta(rig, "mouthLowerDown_L")[mid_lo, 1] < -0.1
    for name in ("cheekPuff_L", "cheekSquint_L", "noseSneer_L"):
        w = np.linalg.norm(delta(rig, name), axis=1)
        centre = (p * w[:, None]).sum(axis=0) / w.sum()
        assert centre[0] > 0.5, name
        assert g.mouth_y - 1.0 < centre[1] < g.eye_y, name
    assert (delta(rig, "cheekPuff_L")[moved(rig, "cheekPuff_L"), 0] > 0).all()   # puffs outward


def test_presets_are_the_six_emotions_over_existing_shapes(sample_rig):
    assert set(sample_rig.presets) == {"happy", "sad", "angry", "surprised", "disgusted", "afraid"}
    for name, weights in sample_rig.presets.items():
        assert weights, name
        assert all(0.0 < w <= 1.0 for w in weights.values()), name
        sample_rig.weights_from_dict(weights)   # raises on an unknown shape name


def test_write_sample_round_trip(tmp_path):
    rig = build_sample_rig()
    folder = write_sample(tmp_path / "sample")
    assert (folder / "neutral.obj").exists()
    back = load_rig(folder)
    assert back.n_vertices == rig.n_vertices
    np.testing.assert_array_equal(back.face_counts, rig.face_counts)
    np.testing.assert_array_equal(back.face_indices, rig.face_indices)
    np.testing.assert_allclose(back.neutral, rig.neutral, atol=1e-6)
    assert sorted(back.shape_names) == sorted(rig.shape_names)
    for name in rig.shape_names:
        np.testing.assert_allclose(back.deltas[back.shape_index(name)], delta(rig, name), atol=2e-6)
    assert json.loads((folder / "presets.json").read_text()) == rig.presets


def test_mesh_is_clean_and_connected(sample_rig):
    rig, g = sample_rig, sample_geometry()
    p = rig.neutral
    tri = rig.triangles()
    area = 0.5 * np.linalg.norm(np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), axis=1)
    assert area.min() > 1e-4
    for poly in rig.polygons():
        assert len(set(poly.tolist())) == len(poly)
    e = rig.edges()
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(rig.n_vertices,) * 2)
    n, labels = connected_components(adj, directed=False)
    assert n == 3                                           # the skin and two eyeballs
    assert len(set(labels[g.skin])) == 1
    for side in ("L", "R"):
        assert len(set(labels[g.eyeball[side]])) == 1
        assert labels[g.eyeball[side][0]] != labels[0]
    # Consistent orientation: every directed edge is used by one polygon at most.
    starts = np.concatenate(([0], np.cumsum(rig.face_counts)[:-1]))
    nxt = np.arange(rig.face_indices.size) + 1
    nxt[starts + rig.face_counts - 1] = starts
    directed = rig.face_indices.astype(np.int64) * rig.n_vertices + rig.face_indices[nxt]
    assert len(np.unique(directed)) == len(directed)
