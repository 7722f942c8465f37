"""Markers, motion damping, regional drag solves, keyframes, weights CSV and PC2 caches on the ICT rig."""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp

from model.errors import RigInputError
from model.keyframes import Keyframe, Timeline
from model.markers import Marker, MarkerSet, markers_from_json, markers_to_json, read_marker_json, write_marker_json
from model.pc2 import MAGIC, read_pc2, read_pc2_header, write_pc2
from model.pose import PoseEvaluator
from model.weights_csv import read_weights_csv, write_weights_csv
from solvers.damping import damp_displacement, damping_gains, point_mobility
from solvers.regional_solve import RegionalSolver


@pytest.fixture(scope="module")
def landmarks(ict_dir):
    """68 facial landmark vertices of ICT (iBUG order): 30 nose tip, 48/54 mouth corners, 19/24 brows, 8 chin."""
    return json.loads((ict_dir / "vertex_indices.json").read_text())["idx_to_landmark_verts"]


@pytest.fixture(scope="module")
def level(ict_rig):
    """Level 2 of the automatic segmentation of ICT (10 regions)."""
    from model.segmentation import segment_rig
    seg = segment_rig(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, ict_rig.deltas)
    return seg.levels[2]


# --- markers ----------------------------------------------------------------------------------------
def test_marker_sampling_on_vertices_and_face_points(ict_rig):
    tris = ict_rig.triangles()
    ms = MarkerSet.for_rig(ict_rig, [Marker("A", vertex=1225), Marker("B", face=100, bary=(0.2, 0.3, 0.5))])
    X = ict_rig.neutral + ict_rig.deltas[ict_rig.shape_index("jawOpen")]
    P = ms.positions(X)
    np.testing.assert_allclose(P[0], X[1225])
    np.testing.assert_allclose(P[1], 0.2 * X[tris[100, 0]] + 0.3 * X[tris[100, 1]] + 0.5 * X[tris[100, 2]])
    A = ms.delta_rows(ict_rig.deltas)
    assert A.shape == (6, ict_rig.n_shapes)
    k = ict_rig.shape_index("jawOpen")
    np.testing.assert_allclose(A[:, k], (P - ms.positions(ict_rig.neutral)).reshape(-1), atol=1e-12)


def test_duplicate_markers_are_rejected(ict_rig):
    tri = ict_rig.triangles()[50]
    with pytest.raises(RigInputError, match="same surface point"):
        MarkerSet.for_rig(ict_rig, [Marker("A", vertex=10), Marker("B", vertex=10)])
    with pytest.raises(RigInputError, match="same surface point"):  # a face point sitting on a corner vertex
        MarkerSet.for_rig(ict_rig, [Marker("A", vertex=int(tri[1])), Marker("B", face=50, bary=(0, 1, 0))])
    with pytest.raises(RigInputError, match="duplicate marker names"):
        MarkerSet.for_rig(ict_rig, [Marker("A", vertex=10), Marker("A", vertex=11)])


def test_background_markers_are_allowed_but_reported(ict_rig):
    mob = point_mobility(ict_rig.deltas)
    still = int(np.flatnonzero(mob == 0)[0])
    ms = MarkerSet.for_rig(ict_rig, [Marker("face", vertex=1225), Marker("skull", vertex=still)])
    assert ms.background == ["skull"]
    assert ms.warnings and "skull" in ms.warnings[0]


def test_marker_json_round_trip_and_agreement_with_the_take_reader(ict_rig, tmp_path):
    from model.marker_map import load_marker_map
    ms = MarkerSet.for_rig(ict_rig, [Marker("M00", vertex=1225), Marker("M01", face=2001, bary=(0.1, 0.6, 0.3)),
                                     Marker("M02", face=7, bary=(0.5, 0.25, 0.25))])
    path = tmp_path / "map.json"
    write_marker_json(path, ms, ict_rig)
    back = read_marker_json(path, ict_rig)
    assert back.names == ms.names
    assert abs(back.S - ms.S).max() < 1e-12
    # model.marker_map reads the same file for takes: it must land every marker on the same point.
    other = load_marker_map(path).binding(ict_rig)
    assert abs(other - ms.S).max() < 1e-12
    d = ms.to_dict()
    assert MarkerSet.from_dict(json.loads(json.dumps(d)), ict_rig).names == ms.names


def test_marker_json_bad_input_names_the_problem(ict_rig, tmp_path):
    with pytest.raises(RigInputError, match="vertex 99999.*26719"):
        markers_from_json({"markers": {"M00": 99999}}, ict_rig)
    with pytest.raises(RigInputError, match="face"):
        markers_from_json({"markers": {"M00": {"face": 10 ** 7, "bary": [1, 0, 0]}}}, ict_rig)
    with pytest.raises(RigInputError, match="sum to 1"):
        markers_from_json({"markers": {"M00": {"face": 3, "bary": [0.5, 0.1, 0.1]}}}, ict_rig)
    with pytest.raises(RigInputError, match="mm"):
        markers_from_json({"rig_units": "mm", "markers": {"M00": 3}}, ict_rig)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(RigInputError, match="bad.json"):
        read_marker_json(bad, ict_rig)
    assert markers_to_json(MarkerSet.for_rig(ict_rig, [Marker("X", vertex=3)]), ict_rig)["markers"] == {"X": 3}


# --- damping ----------------------------------------------------------------------------------------
def test_damping_moves_the_nose_tip_less_than_a_mouth_corner(ict_rig, landmarks):
    gains = damping_gains(point_mobility(ict_rig.deltas))
    nose, mouth = landmarks[30], landmarks[48]
    mouse = np.array([0.5, 0.0, 0.0])
    at_nose = np.linalg.norm(damp_displacement(mouse, gains, vertex=nose))
    at_mouth = np.linalg.norm(damp_displacement(mouse, gains, vertex=mouth))
    assert at_nose < 0.5 * at_mouth
    assert 0.05 <= gains.min() and gains.max() <= 1.5
    moving = gains[point_mobility(ict_rig.deltas) > 0]
    assert 0.9 < np.median(moving) < 1.1  # a typical face point follows the mouse


# --- regional drag solve ----------------------------------------------------------------------------
def _drag_setup(rig, landmarks, level):
    names = ["nose", "mouthL", "mouthR", "browL", "browR", "chin"]
    verts = [landmarks[i] for i in (30, 48, 54, 19, 24, 8)]
    ms = MarkerSet.for_rig(rig, [Marker(n, vertex=int(v)) for n, v in zip(names, verts)])
    solver = RegionalSolver([r.vertices for r in level.regions], ms.S, ms.delta_rows(rig.deltas),
                            deltas=rig.deltas)
    return ms, solver


def test_dragging_a_mouth_corner_moves_it_and_keeps_the_others_pinned(ict_rig, landmarks, level):
    rig = ict_rig
    ms, solver = _drag_setup(rig, landmarks, level)
    ev = PoseEvaluator(rig, dtype=np.float64)
    R = level.n_regions
    W = np.zeros((R + 1, rig.n_shapes))
    X0 = ev.evaluate_regional(W, level.blend)
    current = ms.positions(X0)
    targets = current.copy()
    mouth = ms.index("mouthL")
    targets[mouth] += np.array([0.6, 0.5, 0.0])  # pull the corner out and up (a smile), cm
    b = (targets - ms.positions(rig.neutral)).reshape(-1)
    W1 = solver.solve(b, W)
    X1 = ev.evaluate_regional(W1, level.blend)
    moved = ms.positions(X1)
    before = np.linalg.norm(targets[mouth] - current[mouth])
    after = np.linalg.norm(targets[mouth] - moved[mouth])
    assert after < 0.3 * before  # the corner follows the drag
    others = [i for i in range(len(ms)) if i != mouth]
    assert np.linalg.norm(moved[others] - current[others], axis=1).max() < 0.1  # pinned markers stay (< 1 mm)
    assert W1.min() >= 0 and W1.max() <= 1
    untouched = [r for r in range(R) if r not in solver.active_regions]
    np.testing.assert_array_equal(W1[untouched], W[untouched])
    np.testing.assert_array_equal(W1[R], W[R])  # the background keeps the global weights


def test_unreachable_drag_stays_within_bounds(ict_rig, landmarks, level):
    ms, solver = _drag_setup(ict_rig, landmarks, level)
    W = np.full((level.n_regions + 1, ict_rig.n_shapes), 0.1)
    b = (ms.positions(ict_rig.neutral) * 0 + 50.0).reshape(-1)  # 50 cm away: far beyond any shape
    W1 = solver.solve(b, W)
    assert np.isfinite(W1).all() and W1.min() >= 0.0 and W1.max() <= 1.0
    assert (W1 != W).any()


# --- keyframes ----------------------------------------------------------------------------------------
def test_timeline_interpolates_and_stays_within_bounds():
    K = 4
    tl = Timeline(interpolation="smooth")
    tl.set_key(0.0, np.zeros(K))
    tl.set_key(1.0, np.array([1.0, 0.5, 0.0, 1.0]))
    tl.set_key(1.5, np.array([0.0, 0.5, 1.0, 1.0]))
    np.testing.assert_allclose(tl.evaluate(1.0), [1.0, 0.5, 0.0, 1.0])  # passes through keys
    np.testing.assert_allclose(tl.evaluate(0.5, "linear"), [0.5, 0.25, 0.0, 0.5])
    ts = np.linspace(-1, 3, 401)
    vals = np.array([tl.evaluate(t) for t in ts])
    assert vals.min() >= 0.0 and vals.max() <= 1.0  # Catmull-Rom overshoot is clipped
    np.testing.assert_allclose(vals[0], 0.0)
    np.testing.assert_allclose(vals[-1], [0.0, 0.5, 1.0, 1.0])
    smooth_diff = np.abs(np.diff(vals[:, 1])).max()
    assert smooth_diff < 0.02  # no jumps
    tl.set_key(1.0, np.full(K, 0.2))  # replace
    assert len(tl) == 3
    tl.remove_key(1.5)
    assert len(tl) == 2
    back = Timeline.from_dict(json.loads(json.dumps(tl.to_dict())))
    np.testing.assert_allclose(back.evaluate(0.7), tl.evaluate(0.7))
    with pytest.raises(RigInputError):
        tl.set_key(2.0, np.zeros((3, K)))


def _nearest_in_triangle(p):
    """The point of {w ≥ 0, w0 + w1 ≤ 1} nearest to the 2-vector p: p itself, or the nearest point of an edge."""
    if p.min() >= 0 and p.sum() <= 1:
        return p
    best = None
    for a, b in (((0, 0), (1, 0)), ((0, 0), (0, 1)), ((1, 0), (0, 1))):
        a, b = np.array(a, float), np.array(b, float)
        q = a + np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1) * (b - a)
        best = q if best is None or np.linalg.norm(p - q) < np.linalg.norm(p - best) else best
    return best


def test_convex_timeline_passes_through_its_keys_and_projects_between_them():
    P = np.array([[[0.6, 0.4], [0.0, 0.0]], [[0.9, 0.1], [1.0, 0.0]], [[0.0, 1.0], [0.0, 1.0]]])  # 2 regions, 2 shapes
    tl = Timeline([Keyframe(t, P[t]) for t in range(3)], mode="convex")
    for t in range(3):                        # every key is convex (w ≥ 0, Σ w ≤ 1 per region): shown as keyed
        np.testing.assert_allclose(tl.evaluate(float(t)), P[t], atol=1e-12)
        np.testing.assert_allclose(tl.evaluate(float(t), "linear"), P[t], atol=1e-12)
    # Catmull–Rom with finite-difference tangents at unit spacing, written out here
    m = [P[1] - P[0], (P[2] - P[0]) / 2, P[2] - P[1]]
    projected = 0
    for t in np.linspace(0, 2, 81):
        i = min(int(t), 1)
        s = t - i
        lerp = (1 - s) * P[i] + s * P[i + 1]   # convex combinations of convex keys: nothing to project
        np.testing.assert_allclose(tl.evaluate(t, "linear"), lerp, atol=1e-12)
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        raw = h00 * P[i] + h10 * m[i] + h01 * P[i + 1] + h11 * m[i + 1]
        want = np.array([_nearest_in_triangle(r) for r in raw])
        projected += int(np.abs(want - raw).max() > 1e-6)
        np.testing.assert_allclose(tl.evaluate(t), want, atol=1e-9)   # the nearest convex pose to the curve
    assert projected > 10    # the smooth curve leaves the set between these keys (78 of these 81 times)


# --- files --------------------------------------------------------------------------------------------
def test_per_shape_keys_are_curves_of_their_own():
    """A key of one shape (Maya's key on one attribute) moves that shape's curve only; keys of the whole pose
    evaluate as before; moving, removing and saving keep each shape's keys."""
    tl = Timeline(interpolation="linear")
    tl.set_key(0.0, [0.0, 0.0, 0.0])
    tl.set_key(2.0, [1.0, 1.0, 1.0])
    tl.set_shape_key(1.0, 1, 0.0)                   # shape 1 held at 0 at 1 s; the pose there is not a key of 0 and 2
    np.testing.assert_allclose(tl.evaluate(0.5), [0.25, 0.0, 0.25])
    np.testing.assert_allclose(tl.evaluate(1.0), [0.5, 0.0, 0.5])
    np.testing.assert_allclose(tl.evaluate(1.5), [0.75, 0.5, 0.75])
    assert [k.time for k in tl.shape_keys(1)] == [0.0, 1.0, 2.0] and [k.time for k in tl.shape_keys(0)] == [0.0, 2.0]
    tl.set_shape_key(1.0, 2, 0.9)                   # on the same key: now keys shapes 1 and 2, shape 1 unchanged
    np.testing.assert_allclose(tl.evaluate(1.0), [0.5, 0.0, 0.9])
    tl.move_shape_key(1, 1.0, 0.5, 0.4)             # shape 1's key to 0.5 s at 0.4; shape 2's stays at 1 s
    np.testing.assert_allclose(tl.evaluate(0.5)[1], 0.4)
    np.testing.assert_allclose(tl.evaluate(1.0)[2], 0.9)
    assert [k.time for k in tl.shape_keys(1)] == [0.0, 0.5, 2.0]
    back = Timeline.from_dict(json.loads(json.dumps(tl.to_dict())))
    for t in np.linspace(0, 2, 9):
        np.testing.assert_allclose(back.evaluate(t), tl.evaluate(t))
    tl.remove_shape_key(1.0, 2)                     # the key at 1 s keyed only shape 2: it goes
    assert [k.time for k in tl.keys] == [0.0, 0.5, 2.0]
    assert tl.next_key_time(0.5) == 2.0 and tl.next_key_time(0.5, -1) == 0.0 and tl.next_key_time(2.0) is None
    with pytest.raises(RigInputError):
        tl.remove_shape_key(0.5, 0)                 # 0.5 s does not key shape 0
    # a regional timeline: a shape's value is its largest over the regions; a move shifts every region
    rt = Timeline()
    rt.set_key(0.0, np.array([[0.2, 0.0], [0.6, 0.0]]))
    rt.move_shape_key(0, 0.0, 0.0, 0.8)
    np.testing.assert_allclose(rt.keys[0].weights[:, 0], [0.4, 0.8])
    with pytest.raises(RigInputError):
        Keyframe(0.0, [0.0, 1.0], keyed=[True])     # a mask of the wrong length


def test_weights_csv_round_trip_and_bad_files(tmp_path, ict_rig):
    W = np.random.default_rng(0).random((5, ict_rig.n_shapes))
    path = tmp_path / "w.csv"
    write_weights_csv(path, W, ict_rig.shape_names, rate=60.0)
    frames, times, names, W2 = read_weights_csv(path)
    assert names == ict_rig.shape_names
    np.testing.assert_array_equal(frames, np.arange(5))
    np.testing.assert_allclose(times, np.arange(5) / 60.0)
    np.testing.assert_array_equal(W2, W)
    assert path.read_text().splitlines()[0] == "frame,time," + ",".join(ict_rig.shape_names)
    (tmp_path / "bad.csv").write_text("frame,time,a\n0,0.0,zz\n")
    with pytest.raises(RigInputError, match="bad.csv"):
        read_weights_csv(tmp_path / "bad.csv")
    (tmp_path / "short.csv").write_text("frame,time,a,b\n0,0.0,1\n")
    with pytest.raises(RigInputError, match="row 2"):
        read_weights_csv(tmp_path / "short.csv")


def test_weights_csv_is_what_the_csv_module_writes(tmp_path):
    """The weights CSV's rows are joined directly (fast) but must be exactly what Python's csv module writes for the
    same values: names quoted where they need it, every number the shortest repr that reads back to it, the frames
    and times given."""
    import csv
    import io
    rng = np.random.default_rng(3)
    W = rng.random((7, 4)) * [1.0, 1e-7, 1e5, -1.0]
    W[0] = [0.0, -0.0, 1 / 3, 5e-324]
    names = ["jaw", 'a,"quoted"', "b c", "é"]
    frames, times = np.array([3, 4, 5, 7, 8, 10, 11]), np.array([0.1, 0.2, 1 / 3, 0.5, 2.0, 1e-9, 7.0])
    path = tmp_path / "w.csv"
    write_weights_csv(path, W, names, times=times, frames=frames)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["frame", "time", *names])
    for f, t, row in zip(frames, times, W):
        w.writerow([int(f), repr(float(t)), *(repr(float(x)) for x in row)])
    assert path.read_bytes() == buf.getvalue().encode("utf-8")
    f2, t2, n2, W2 = read_weights_csv(path)
    assert n2 == names and np.array_equal(f2, frames) and np.array_equal(t2, times) and np.array_equal(W2, W)


def test_pc2_streaming_round_trip_header_and_atomicity(tmp_path, ict_rig):
    ev = PoseEvaluator(ict_rig)
    path = tmp_path / "take.pc2"
    k = ict_rig.shape_index("jawOpen")

    def frames():
        for f in range(4):
            w = np.zeros(ict_rig.n_shapes)
            w[k] = f / 3
            yield ev.evaluate(w).copy()

    assert write_pc2(path, frames(), start_frame=10.0, sample_rate=1.0) == 4
    raw = path.read_bytes()
    assert raw[:12] == MAGIC and len(raw) == 32 + 4 * ict_rig.n_vertices * 3 * 4
    h = read_pc2_header(path)
    assert h == {"n_points": ict_rig.n_vertices, "start_frame": 10.0, "sample_rate": 1.0, "n_samples": 4}
    data, start, rate = read_pc2(path)
    np.testing.assert_allclose(data[3], ict_rig.neutral + ict_rig.deltas[k], atol=1e-4)

    def broken():
        yield np.zeros((ict_rig.n_vertices, 3))
        raise RuntimeError("crash mid-take")

    with pytest.raises(RuntimeError):
        write_pc2(path, broken())
    assert path.read_bytes() == raw  # the previous cache is intact
    (tmp_path / "cut.pc2").write_bytes(raw[:1000])
    with pytest.raises(RigInputError, match="truncated"):
        read_pc2(tmp_path / "cut.pc2")


def test_regional_solve_at_the_finest_level_fits_markers_at_least_as_well_as_global(ict_rig):
    """Joshi §4: per-region weights have more freedom than one global vector, so on targets that are not in
    the rig's span (a smooth non-linear change on top of a known pose) they fit the markers at least as well."""
    from model.segmentation import segment_rig
    from solvers.weight_solve import WeightSolver
    rig = ict_rig
    seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas)
    fine = seg.levels[0]
    face = np.arange(9409)
    moving = face[np.linalg.norm(rig.deltas[:, face], axis=2).max(axis=0) > 1e-3]
    markers = moving[np.linspace(0, moving.size - 1, 50).astype(int)]
    ms = MarkerSet.for_rig(rig, [Marker(f"K{i}", vertex=int(v)) for i, v in enumerate(markers)])
    w_true = rig.weights_from_dict({"jawOpen": 0.5, "mouthSmile_L": 0.7, "browInnerUp_R": 0.6, "eyeBlink_L": 0.8})
    ev = PoseEvaluator(rig, dtype=np.float64)
    posed = ev.evaluate(w_true)
    bend = 0.05 * np.sin(rig.neutral[:, :1] / 2.0) * np.array([0.0, 1.0, 0.5])  # not in the span of the shapes
    targets = ms.positions(posed + bend)
    A = ms.delta_rows(rig.deltas)
    b = (targets - ms.positions(rig.neutral)).reshape(-1)
    w_global = WeightSolver(A, lam_sparsity=0.0, lam_reg=0.0).solve(b)
    global_fit = ms.positions(ev.evaluate(w_global))
    regional = RegionalSolver([r.vertices for r in fine.regions], ms.S, A, deltas=rig.deltas,
                              solve_background=True, lam_reg=1e-8)
    W = regional.solve(b, np.repeat(w_global[None], fine.n_regions + 1, axis=0))
    regional_fit = ms.positions(ev.evaluate_regional(W, fine.blend))
    rms = lambda fit: float(np.sqrt(np.mean(np.sum((fit - targets) ** 2, axis=1))))
    assert W.min() >= 0 and W.max() <= 1
    print(f"marker RMS: regional {rms(regional_fit):.5f} cm, global {rms(global_fit):.5f} cm")
    assert rms(regional_fit) <= rms(global_fit) + 1e-9, (rms(regional_fit), rms(global_fit))


def test_a_region_without_markers_follows_them_with_its_own_shapes_in_a_drag():
    """``RegionalSolver(unmarked="follow")``, as a drag solves: a region holding no marker is solved from every marker
    with its own shapes (against scipy's bounded least squares on ‖A w − b‖² + λ_r ‖w − w₀‖²); with "keep" it keeps
    its weights; a region with markers is solved from its own either way."""
    from scipy.optimize import lsq_linear
    rng = np.random.default_rng(3)
    M, K, V, lam = 4, 5, 8, 1e-2
    S = sp.csr_matrix((np.ones(M), (np.arange(M), np.arange(M))), shape=(M, V))   # markers on vertices 0-3
    regions = [np.arange(4), np.arange(4, 8)]                                       # the second holds none
    A = rng.normal(size=(3 * M, K))
    region_max = np.ones((2, K))
    region_max[1, 0] = 0.0                                                          # shape 0 does not move it
    b = 0.3 * rng.normal(size=3 * M)
    W = np.zeros((3, K))
    keep = RegionalSolver(regions, S, A, region_max=region_max, lam_reg=lam).solve(b, W)
    follow = RegionalSolver(regions, S, A, region_max=region_max, lam_reg=lam, unmarked="follow").solve(b, W)
    np.testing.assert_array_equal(keep[1], W[1])
    np.testing.assert_array_equal(follow[0], keep[0])
    sh = np.arange(1, K)
    ref = lsq_linear(np.vstack([A[:, sh], np.sqrt(lam) * np.eye(sh.size)]), np.concatenate([b, np.zeros(sh.size)]),
                     bounds=(0.0, 1.0), tol=1e-12).x
    np.testing.assert_allclose(follow[1, sh], ref, atol=1e-6)
    assert follow[1, 0] == 0.0 and np.abs(follow[1] - keep[1]).max() > 0.05


def test_a_dragged_marker_is_held_in_the_view_plane_its_depth_free():
    """``model.markers.in_view_plane``: the dragged marker's three rows (of the deltas, the targets, a corrective's
    displacements) projected by P = I − f fᵀ, every other marker's untouched, along either axis."""
    from model.markers import in_view_plane
    rng = np.random.default_rng(5)
    rows = rng.normal(size=(12, 6))                      # 4 markers, 6 shapes
    f = np.array([0.3, -0.2, -1.0])
    out = in_view_plane(rows, 2, f)
    u = f / np.linalg.norm(f)
    np.testing.assert_allclose(u @ out[6:9], 0.0, atol=1e-12)              # no depth left in marker 2's rows
    np.testing.assert_allclose(out[6:9], (np.eye(3) - np.outer(u, u)) @ rows[6:9], atol=1e-12)
    np.testing.assert_array_equal(np.delete(out, [6, 7, 8], axis=0), np.delete(rows, [6, 7, 8], axis=0))
    np.testing.assert_allclose(in_view_plane(rows.T, 2, f, axis=1), out.T, atol=1e-12)
    np.testing.assert_array_equal(in_view_plane(rows, 2, [0.0, 0.0, 1.0])[6:8], rows[6:8])   # x, y stay (front)
