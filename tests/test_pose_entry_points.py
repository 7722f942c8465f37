"""One pose evaluation: a rig with correctives (one of them muted) posed regionally and globally through every
entry point -- the document (viewport and exports), a take's PC2 export, a take solve's dense frames and the
command line's export -- gives the arrays of ``model.pose.PoseEvaluator``, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from model.correctives import Corrective, set_correctives
from model.marker_map import MarkerMap
from model.pc2 import read_pc2
from model.pose import PoseEvaluator
from model.project import Project, save_project
from model.take_exports import export_pc2
from model.take_workspace import TakeWorkspace, regional_solve_options, solve_take
from model.takes import MarkerTake, WeightTake
from tests.cli_runner import run_cli

PAIRS = [["browInnerUp_L", "browInnerUp_R"], ["eyeBlink_L", "eyeWide_L"]]


@pytest.fixture(scope="module")
def posed(sample_rig):
    """The sample rig with two correctives (the second muted), a segmentation level, and a regional pose in
    which both correctives fire."""
    from model.segmentation import SegmentationSettings, segment_rig
    rig = sample_rig.copy()
    cs = []
    for i, drivers in enumerate(PAIRS):
        d = rig.deltas[[rig.shape_index(n) for n in drivers]].sum(axis=0)
        cs.append(Corrective(drivers=drivers, delta=(0.3 + 0.2 * i) * np.roll(d, 1, axis=1), muted=i == 1))
    set_correctives(rig, cs)
    seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, SegmentationSettings(t=0.75))
    level = 1
    blend = seg.levels[level].blend
    rng = np.random.default_rng(7)
    W = rng.uniform(0.0, 0.3, (blend.shape[1], rig.n_shapes))
    W[:, [rig.shape_index(n) for p in PAIRS for n in p]] = rng.uniform(0.5, 1.0, (blend.shape[1], 4))
    return rig, seg, level, blend, W


def test_the_evaluator_applies_live_correctives_and_leaves_muted_and_excluded_ones_out(posed):
    rig, _, _, blend, W = posed
    ev = PoseEvaluator(rig, dtype=np.float64)
    w = W[-1]
    a = ev.activations(w)
    assert (a > 0.2).all()                       # both correctives fire at this pose
    live, muted = rig.correctives
    by_hand = rig.neutral + np.einsum("k,kvc->vc", w, rig.deltas) + a[0] * live.delta
    np.testing.assert_allclose(ev.evaluate(w), by_hand, atol=1e-12)
    np.testing.assert_allclose(ev.evaluate(w, include_muted=True), by_hand + a[1] * muted.delta, atol=1e-12)
    np.testing.assert_allclose(ev.evaluate(w, exclude=[live.name]), by_hand - a[0] * live.delta, atol=1e-12)
    np.testing.assert_allclose(ev.evaluate(w, exclude=[0]), by_hand - a[0] * live.delta, atol=1e-12)
    # regional: per-vertex blended weights activate the correctives; without any live corrective the per-region
    # gemv path gives the same surface as the per-vertex one
    per_vertex = np.asarray(sp.csr_matrix(blend) @ W)
    from model.correctives import corrective_activations_per_vertex
    av = corrective_activations_per_vertex(rig.correctives, rig.shape_names, per_vertex)
    regional = rig.neutral + np.einsum("vk,kvc->vc", per_vertex, rig.deltas)
    np.testing.assert_allclose(ev.evaluate_regional(W, blend), regional + av[:, :1] * live.delta, atol=1e-12)
    np.testing.assert_allclose(ev.evaluate_regional(W, blend, exclude=[live.name]), regional, atol=1e-12)
    assert np.abs(av[:, :1] * live.delta).max() > 0.05     # cm: leaving it out is visible


def test_every_entry_point_gives_the_evaluators_arrays(qtbot, posed, tmp_path):
    from app.document import Document, PoseState
    rig, seg, level, blend, W = posed
    ev32, ev64 = PoseEvaluator(rig), PoseEvaluator(rig, dtype=np.float64)

    # the document: the viewport's float32 surface and the float64 one of exports, regional and global
    doc = Document()
    doc.set_project(Project(rig=rig, weights=np.zeros(rig.n_shapes)), None)
    state = PoseState(W[-1].copy(), W.copy(), blend, level)
    doc.set_pose_state(state)
    assert np.array_equal(doc.posed_surface(), ev32.evaluate_regional(W, blend))
    assert np.array_equal(doc.evaluate_state(state, dtype=np.float64), ev64.evaluate_regional(W, blend))
    doc.set_weights(W[-1])
    assert np.array_equal(doc.posed_surface(), ev32.evaluate(W[-1]))
    assert np.array_equal(doc.evaluate_state(doc.pose_state(), dtype=np.float64), ev64.evaluate(W[-1]))
    # a rig edit (muting the live corrective) bumps the version: both evaluators follow, none is stale
    before = doc.evaluate_state(doc.pose_state(), dtype=np.float64)
    rig_muted = rig.copy()
    rig_muted.correctives[0].muted = True
    doc.project.rig = rig_muted
    doc.rig_edited()
    after = doc.evaluate_state(doc.pose_state(), dtype=np.float64)
    assert np.array_equal(after, PoseEvaluator(rig_muted, dtype=np.float64).evaluate(W[-1]))
    assert np.abs(after - before).max() > 0.05

    # a take's PC2 export: a weight take posed by the rig, written as float32 by the evaluator's batched
    # evaluation (all frames as one float32 matrix product), which is its per-frame pose to float32 rounding
    F = 4
    frames_w = np.stack([W[r] for r in range(F)])
    ws = TakeWorkspace(rig)
    ws.take = WeightTake(weights=frames_w, names=list(rig.shape_names), rate=30.0)
    export_pc2(ws, tmp_path / "take.pc2")
    data, _, _ = read_pc2(tmp_path / "take.pc2")
    assert np.array_equal(data, PoseEvaluator(rig, dtype=np.float64).evaluate_many(frames_w))
    per_frame = np.stack([ev64.evaluate(w) for w in frames_w])
    assert np.abs(data - per_frame).max() < 4e-7 * max(1.0, float(np.abs(per_frame).max()))

    # a take solve's dense frames (per region, no residual): the evaluator at the solved region weights
    vertices = np.flatnonzero(np.abs(rig.deltas).max(axis=(0, 2)) > 0)[::40]
    labels = [f"M{i:03d}" for i in range(vertices.size)]
    mm = MarkerMap(markers=dict(zip(labels, vertices.tolist())), rig_units="cm")
    truth = np.stack([ev64.evaluate(w) for w in frames_w])
    take = MarkerTake(positions=truth[:, vertices], labels=labels, rate=30.0, units="cm")
    sol = solve_take(rig, take, mm, calibration_frames=0, head_motion=False, residual="none", two_pass=False,
                     **regional_solve_options(seg, level))
    assert sol.region_weights is not None and sol.solver.C == 1
    for f in range(F):
        assert np.array_equal(sol.dense(f), ev64.evaluate_regional(sol.region_weights[f], blend))

    # the command line's export of the project: the evaluator's surface, to the OBJ's six decimals
    from model.obj_io import read_obj
    save_project(Project(rig=rig), tmp_path / "rig.bsproj")
    w = W[-1]
    text = ",".join(f"{n}={v!r}" for n, v in zip(rig.shape_names, w.tolist()))
    run_cli("export", tmp_path / "rig.bsproj", "--weights", text, "-o", tmp_path / "pose.obj")
    written = read_obj(tmp_path / "pose.obj").vertices
    expected = np.array([[float(f"{x:.6f}") for x in row] for row in ev64.evaluate(w).tolist()])
    assert np.array_equal(written, expected)


def test_inbetweens_mute_and_ranges_reach_every_entry_point(qtbot, sample_rig, tmp_path):
    """The Shapes list's settings (issue 18) change the posed mesh everywhere: the document (viewport), a take's
    PC2 export and the command line's OBJ export all give the evaluator's piecewise in-between surface, with the
    muted shape left out and the ranged shape clamped."""
    from app.document import Document
    from model.obj_io import read_obj
    from model.rig import Inbetween
    rig = sample_rig.copy()
    k = rig.shape_index("jawOpen")
    d = rig.deltas[k]
    D = 0.5 * d + 0.2 * np.roll(d, 1, axis=1)
    rig.inbetweens = {"jawOpen": [Inbetween(0.5, D)]}
    rig.muted = ["mouthSmile_L"]
    rig.ranges = {"mouthFunnel": (0.0, 0.5)}
    rig.validate()
    f = rig.shape_index("mouthFunnel")
    w = np.zeros(rig.n_shapes)
    w[[k, rig.shape_index("mouthSmile_L"), f]] = [0.25, 1.0, 0.9]
    by_hand = rig.neutral + 0.5 * D + 0.5 * rig.deltas[f]      # jaw at 0.25 on its curve, smile muted, funnel clamped
    ev64 = PoseEvaluator(rig, dtype=np.float64)
    np.testing.assert_allclose(ev64.evaluate(w), by_hand, atol=1e-12)

    doc = Document()
    doc.set_project(Project(rig=rig, weights=w), None)
    assert np.array_equal(doc.posed_surface(), PoseEvaluator(rig).evaluate(w))
    assert np.array_equal(doc.evaluate_state(doc.pose_state(), dtype=np.float64), ev64.evaluate(w))

    frames_w = np.stack([w * s for s in (0.5, 1.0, 1.5)])
    ws = TakeWorkspace(rig)
    ws.take = WeightTake(weights=frames_w, names=list(rig.shape_names), rate=30.0)
    export_pc2(ws, tmp_path / "take.pc2")
    data, _, _ = read_pc2(tmp_path / "take.pc2")
    per_frame = np.stack([ev64.evaluate(x) for x in frames_w])
    assert np.abs(data - per_frame).max() < 4e-7 * max(1.0, float(np.abs(per_frame).max()))

    save_project(Project(rig=rig), tmp_path / "rig.bsproj")
    text = ",".join(f"{n}={v!r}" for n, v in zip(rig.shape_names, w.tolist()) if v)
    run_cli("export", tmp_path / "rig.bsproj", "--weights", text, "-o", tmp_path / "pose.obj")
    written = read_obj(tmp_path / "pose.obj").vertices
    expected = np.array([[float(f"{x:.6f}") for x in row] for row in by_hand.tolist()])
    np.testing.assert_allclose(written, expected, atol=1.5e-6)
    assert np.abs(written - (rig.neutral + 0.25 * d + rig.deltas[rig.shape_index("mouthSmile_L")]
                             + 0.9 * rig.deltas[f])).max() > 0.05   # the plain linear pose is far from it


def test_a_float64_evaluator_reads_the_rigs_own_deltas_in_place_and_poses_as_the_gathered_matrix_does(ict_rig):
    """A float64 evaluator of a rig without in-betweens or correctives (ICT) holds no copy of the rig's deltas
    (a batch worker's, the solves' and the exports'); its global, many-frame and regional poses are those of the
    evaluator made over the moving vertices only (the float32 display evaluator's layout, here in float64), and
    a rig with a corrective gets its own matrix."""
    import tracemalloc
    rig = ict_rig
    tracemalloc.start()
    try:
        ev = PoseEvaluator(rig, dtype=np.float64)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert np.shares_memory(ev._D, rig.deltas) and peak < 0.2 * rig.deltas.nbytes, peak
    gathered = PoseEvaluator(rig, dtype=np.float32)          # the moving vertices' matrix, made the usual way
    gathered._D = np.take(rig.deltas.reshape(rig.n_shapes, -1), gathered._cols, axis=1)   # ...in float64
    gathered.dtype, gathered._neutral = np.float64, rig.neutral.reshape(-1).astype(np.float64)
    assert gathered.moving_vertices.size < rig.n_vertices    # ICT's back of the head moves in no shape
    rng = np.random.default_rng(3)
    for w in (rng.uniform(0, 1, rig.n_shapes), np.eye(rig.n_shapes)[rig.shape_index("jawOpen")]):
        np.testing.assert_allclose(ev.evaluate(w), gathered.evaluate(w), rtol=0, atol=1e-12)
    W = rng.uniform(0, 1, (5, rig.n_shapes))
    np.testing.assert_allclose(ev.evaluate_many(W, dtype=np.float64), gathered.evaluate_many(W, dtype=np.float64),
                               rtol=0, atol=1e-12)
    labels = (rig.neutral[:, 0] > 0).astype(int)              # two regions: left and right of the face
    blend = sp.csr_matrix((np.ones(rig.n_vertices), (np.arange(rig.n_vertices), labels)), shape=(rig.n_vertices, 2))
    R = rng.uniform(0, 1, (2, rig.n_shapes))
    regional = ev.pose(R, blend)
    np.testing.assert_allclose(regional, gathered.pose(R, blend), rtol=0, atol=1e-12)
    left = labels == 0
    np.testing.assert_allclose(regional[left], ev.evaluate(R[0])[left], rtol=0, atol=1e-12)
    assert not np.allclose(regional[~left], ev.evaluate(R[0])[~left])
    with_corrective = rig.copy()
    set_correctives(with_corrective, [Corrective(drivers=["jawOpen", "mouthClose"],
                                                 delta=np.full((rig.n_vertices, 3), 0.1))])
    own = PoseEvaluator(with_corrective, dtype=np.float64)
    assert not np.shares_memory(own._D, with_corrective.deltas) and own._D.shape[0] == rig.n_shapes + 1


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_the_gathered_matrix_is_the_same_on_any_number_of_threads(ict_rig, threads):
    """The display evaluator's float32 matrix of the moving vertices' columns (a studio rig's rows are gathered on
    the machine's cores): ``full[:, cols]`` cast, row for row, however the rows are shared out."""
    from model.pose import _gathered_columns, _moving_vertices
    full = ict_rig.deltas.reshape(ict_rig.n_shapes, -1)
    moving = _moving_vertices(full, ict_rig.n_vertices)
    cols = (moving[:, None] * 3 + np.arange(3)).reshape(-1)
    for dtype in (np.float32, np.float64):
        got = _gathered_columns(full, cols, dtype, threads=threads)
        assert got.dtype == dtype and np.array_equal(got, full[:, cols].astype(dtype))
    assert np.array_equal(PoseEvaluator(ict_rig)._D, _gathered_columns(full, cols, np.float32, threads=threads))


def test_a_regional_pose_of_a_few_shapes_is_joshis_blend_of_each_regions_pose(ict_rig):
    """Regions keyed with a few shapes each (what marker-keyed playback evaluates every frame, where only those
    shapes' rows are read), and regions with every shape live, against Joshi §4 written out densely in float64:
    x(v) = b0(v) + Σ_r φ_r(v) Σ_k W_rk d_k(v)."""
    rig = ict_rig
    rng = np.random.default_rng(11)
    V, K = rig.n_vertices, rig.n_shapes
    phi = rng.uniform(0.0, 1.0, (V, 4))
    phi[rng.uniform(size=(V, 4)) < 0.5] = 0.0              # regions that cover part of the face
    phi[phi.sum(axis=1) == 0, 0] = 1.0
    phi /= phi.sum(axis=1, keepdims=True)
    blend = sp.csr_matrix(phi)
    W = np.zeros((4, K))
    keyed = (["jawOpen", "mouthSmile_L"], ["browInnerUp_L"], ["eyeBlink_L", "eyeBlink_R", "jawOpen"])
    for r, names in enumerate(keyed):
        W[r, [rig.shape_index(n) for n in names]] = rng.uniform(0.2, 1.0, len(names))
    W[3] = rng.uniform(0.0, 0.5, K)                         # every shape live in the last region
    deltas = np.asarray(rig.deltas, dtype=np.float64)
    expected = rig.neutral + np.einsum("vr,rk,kvc->vc", phi, W, deltas)
    np.testing.assert_allclose(PoseEvaluator(rig, dtype=np.float64).evaluate_regional(W, blend), expected,
                               rtol=0, atol=1e-10)
    np.testing.assert_allclose(PoseEvaluator(rig).evaluate_regional(W, blend), expected, rtol=0, atol=2e-5)
    # the set-up made ahead on another thread (a marker drag's level while Marker Mode waits for a press), then
    # adopted by the display evaluator, poses the same, bit for bit
    ev = PoseEvaluator(rig)
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(1) as pool:
        parts = pool.submit(ev.blend_parts, blend).result()
    ev.adopt_blend_parts(blend, parts)
    assert ev._blend_entry(blend).parts is parts
    assert np.array_equal(ev.evaluate_regional(W, blend), PoseEvaluator(rig).evaluate_regional(W, blend))
