"""Retargeting an actor who is not the rig (ALGORITHMS.md §12), on the shared takes: the actor take with its marker
map within the issue's accuracy, calibration from a chosen or found neutral, head motion from stable and head-band
markers, a mostly-missing marker left out, a take at 100 Hz, and one sentence for bad calibration input."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from model.errors import RigInputError
from model.marker_map import load_marker_map
from model.pose import PoseEvaluator
from model.take_c3d import read_c3d
from model.take_workspace import TakeWorkspace, solve_report, solve_take
from model.takes import MarkerTake
from tests.conftest import DATA, require_data

ACTOR_DIR = DATA / "mocap" / "actor_take"
PERF = slice(30, None)       # the performance frames (the first 30 are the neutral)


@pytest.fixture(scope="module")
def actor_dir():
    return require_data(ACTOR_DIR)


@pytest.fixture(scope="module")
def evaluator(ict_rig):
    return PoseEvaluator(ict_rig, dtype=np.float64)


def truth_weights(rig, path) -> np.ndarray:
    with open(path) as fh:
        rows = list(csv.reader(fh))
    T = np.array([[float(v) for v in r[1:]] for r in rows[1:]])
    W = np.zeros((T.shape[0], rig.n_shapes))
    W[:, [rig.shape_index(n) for n in rows[0][1:]]] = T
    return W


def posed_rms_mm(ev, W, T, moving, frames) -> float:
    """RMS (mm) over the moving face between the rig posed with W and with T, averaged over ``frames``."""
    e = [np.sqrt(np.mean(np.sum((ev.pose(W[f])[moving] - ev.pose(T[f])[moving]) ** 2, axis=1))) for f in frames]
    return float(np.mean(e)) * 10.0


@pytest.fixture(scope="module")
def actor(ict_rig, actor_dir, evaluator):
    take = read_c3d(actor_dir / "take.c3d")
    mm = load_marker_map(actor_dir / "marker_map.json")
    truth = np.load(actor_dir / "truth_dense_face.npz")
    T = truth_weights(ict_rig, actor_dir / "truth_weights.csv")
    frames = [int(f) for f in truth["frames"] if f >= 30]
    return take, mm, T, truth["moving"], frames


@pytest.fixture(scope="module")
def actor_solution(ict_rig, actor, evaluator):
    take, mm, *_ = actor
    return solve_take(ict_rig, take, mm, evaluator=evaluator)


def test_actor_take_with_its_map_meets_the_accuracy(ict_rig, actor, actor_solution, evaluator):
    _, _, T, moving, frames = actor
    sol = actor_solution
    w_rms = np.sqrt(np.mean((sol.weights[PERF] - T[PERF]) ** 2))
    posed = posed_rms_mm(evaluator, sol.weights, T, moving, frames)
    assert w_rms < 0.07, w_rms           # fitting absolute positions gave 0.23
    assert posed < 0.40, posed           # and 1.3 mm
    # the rig explains most of the markers' motion from the actor's neutral
    assert 0.8 < sol.motion_explained < 1.0
    assert sol.neutral_frames == (0, 29)
    from model.antagonists import pair_indices, rig_antagonists, strong_pairs
    assert strong_pairs(sol.weights, pair_indices(ict_rig, rig_antagonists(ict_rig))) == []


def test_without_the_map_automatic_mapping_finds_the_places(ict_rig, actor, evaluator):
    """Automatic mapping of the actor (similarity, the rig warped toward the markers, then each marker's vertex
    re-fitted from the take's motion), then the same solve: the issue's 0.09 weights RMS and 0.50 mm. Measured
    0.072 / 0.40 mm; the registration alone (no re-fit) gave 0.137 / 0.80 mm, its vertices 1.5 mm (mean) from the
    marker map's, and the places that explain the motion best are not all the map's own vertices (the actor's
    expressions are ICT's scaled by smooth per-shape fields)."""
    from model.antagonists import pair_indices, rig_antagonists, strong_pairs
    take, mm, T, moving, frames = actor
    ws = TakeWorkspace(ict_rig)
    ws.take = take
    ws.auto_map()
    d = np.array([np.linalg.norm(ict_rig.neutral[ws.marker_map.markers[lab]] - ict_rig.neutral[mm.markers[lab]])
                  for lab in take.labels])
    # cm: the re-fit searches 8 mm around the registered place (1.8 mm mean from the map's vertices, 8.2 mm at most)
    assert len(d) == 60 and d.max() < 1.0 and np.mean(d) < 0.25, (d.max(), d.mean())
    sol = ws.solve({"mode": "global"}, evaluator=evaluator)
    assert np.sqrt(np.mean((sol.weights[PERF] - T[PERF]) ** 2)) < 0.09
    assert posed_rms_mm(evaluator, sol.weights, T, moving, frames) < 0.50
    assert strong_pairs(sol.weights, pair_indices(ict_rig, rig_antagonists(ict_rig))) == []


def test_fitting_absolute_positions_reads_identity_as_expression(ict_rig, actor, evaluator):
    """The nearest wrong answer: the rig's own neutral fitted to the actor's markers (retarget 'none')."""
    take, mm, T, _, _ = actor
    sol = solve_take(ict_rig, take, mm, evaluator=evaluator, retarget="none", residual="none")
    assert np.sqrt(np.mean((sol.weights[PERF] - T[PERF]) ** 2)) > 0.15


def test_report_says_what_the_rig_explains_and_the_calibration(ict_rig, actor, actor_solution):
    take = actor[0]
    rep = solve_report(ict_rig, take, actor_solution, {"mode": "global"})
    assert rep["neutral_frames"] == [0, 29] and rep["markers_left_out"] == []
    assert rep["motion_explained"] == pytest.approx(actor_solution.motion_explained)
    assert set(rep["motion_explained_per_marker"]) == set(actor_solution.labels)
    assert rep["options"]["retarget"] == "scale"


def _moved_neutral(take: MarkerTake) -> MarkerTake:
    """The take with its neutral lead-in moved into the middle (frames 170–199): the first frames are not neutral."""
    X = take.positions
    return MarkerTake(np.concatenate([X[30:200], X[:30], X[200:]]), take.labels, take.rate, take.units, "moved.c3d")


def test_a_take_without_a_neutral_lead_in_finds_its_neutral(ict_rig, actor, evaluator):
    take, mm, T, moving, _ = actor
    moved = _moved_neutral(take)
    Tm = np.concatenate([T[30:200], T[:30], T[200:]])
    ws = TakeWorkspace(ict_rig)
    ws.take, ws.marker_map = moved, mm
    sol = ws.solve({"mode": "global", "neutral_frames": "auto"}, evaluator=evaluator)
    a, b = sol.neutral_frames
    assert 168 <= a and b <= 201, (a, b)
    rep = ws.report()
    assert rep["neutral_frames"] == [a, b] and "most neutral" in rep["neutral_frames_how"]
    perf = np.r_[0:170, 200:358]
    assert np.sqrt(np.mean((sol.weights[perf] - Tm[perf]) ** 2)) < 0.08
    # the first 30 frames taken as neutral (today's default) read the held expression as the neutral
    first = ws.solve({"mode": "global"}, evaluator=evaluator)
    assert np.sqrt(np.mean((first.weights[perf] - Tm[perf]) ** 2)) > 0.1


def _with_head_band(take: MarkerTake, sol, rng) -> MarkerTake:
    """Three head-band markers moving rigidly with the solved head, plus an extra marker missing in 80% of frames."""
    band_rig = np.array([[-6.0, 14.0, 2.0], [0.0, 16.0, 3.0], [6.0, 14.0, 2.0]])   # above the forehead, rig cm
    band = np.einsum("fij,mj->fmi", sol.head[:, :3, :3], band_rig) + sol.head[:, None, :3, 3]
    band += rng.normal(scale=0.3, size=band.shape)
    extra = take.positions[:, :1] + 5.0
    extra[rng.random(take.n_frames) < 0.8] = np.nan
    X = np.concatenate([take.positions, band, extra], axis=1)
    return MarkerTake(X, take.labels + ["root-L", "root-C", "root-R", "EXTRA"], take.rate, take.units, "band.c3d")


def test_head_band_markers_steady_the_head_and_a_mostly_missing_marker_is_left_out(ict_rig, actor, actor_solution,
                                                                                evaluator):
    take, mm, T, _, _ = actor
    banded = _with_head_band(take, actor_solution, np.random.default_rng(1))
    ws = TakeWorkspace(ict_rig)
    mapped = load_marker_map(ACTOR_DIR / "marker_map.json")
    mapped.markers["EXTRA"] = 100                                # mapped, but seen in a fifth of the frames
    ws.take, ws.marker_map = banded, mapped
    sol = ws.solve({"mode": "global", "stable": "root-*"}, evaluator=evaluator)
    rep = ws.report()
    assert rep["head_markers"] == ["root-L", "root-C", "root-R"]
    assert rep["markers_left_out"] == ["EXTRA"] and "missing" in rep["markers_left_out_why"]["EXTRA"]
    # three noisy band markers (0.3 mm) are all the head has here: a little looser than the face's own 0.067
    assert np.sqrt(np.mean((sol.weights[PERF] - T[PERF]) ** 2)) < 0.10
    # the head follows the band: the face's markers placed by either head agree to a millimetre or two (three
    # band markers with 0.3 mm noise, 10-20 cm from the chin, against the face's 60)
    rest = sol.solver.rest
    by_band = np.einsum("fij,mj->fmi", sol.head[:, :3, :3], rest) + sol.head[:, None, :3, 3]
    by_face = np.einsum("fij,mj->fmi", actor_solution.head[:, :3, :3], rest) + actor_solution.head[:, None, :3, 3]
    assert np.mean(np.linalg.norm(by_band - by_face, axis=2)) < 2.0          # mm


def test_a_take_at_100_hz(ict_rig, actor, evaluator):
    take, mm, T, _, _ = actor
    F = take.n_frames
    t_new = np.arange(0, (F - 1) / 60.0, 1 / 100.0)
    src = np.arange(F) / 60.0
    X = np.stack([[np.interp(t_new, src, take.positions[:, m, c]) for c in range(3)] for m in range(take.n_markers)])
    X = X.transpose(2, 0, 1)
    fast = MarkerTake(X, take.labels, 100.0, take.units, "take100.trc")
    Tn = np.stack([np.interp(t_new, src, T[:, k]) for k in range(T.shape[1])], axis=1)
    ws = TakeWorkspace(ict_rig)
    ws.take, ws.marker_map = fast, mm
    sol = ws.solve({"mode": "global", "neutral_frames": "0:45"}, evaluator=evaluator)
    assert sol.n_frames == len(t_new) and ws.report()["rate"] == 100.0 and ws.report()["neutral_frames"] == [0, 45]
    perf = t_new >= 0.5
    assert np.sqrt(np.mean((sol.weights[perf] - Tn[perf]) ** 2)) < 0.08


@pytest.mark.parametrize("settings, words", [
    ({"neutral_frames": "300:400"}, "outside the take"),
    ({"neutral_frames": "5"}, "not a frame range"),
    ({"stable": "head-*"}, "not in the take"),
    ({"stable": "M00,M01"}, "at least 3 stable markers"),
])
def test_bad_calibration_input_is_one_sentence(ict_rig, actor, settings, words):
    take, mm, *_ = actor
    ws = TakeWorkspace(ict_rig)
    ws.take, ws.marker_map = take, mm
    with pytest.raises(RigInputError) as err:
        ws.solve({"mode": "global", **settings})
    msg = str(err.value)
    assert words in msg and msg.count(". ") == 0 and msg.endswith("."), msg


def test_a_mouth_corner_drag_on_ict_leaves_no_antagonist_pair_both_on(ict_rig):
    """The issue's drag at level 3: one marker on the left mouth corner pulled 1.5 cm out and 1 cm up in six steps.
    Without the exclusion the regional solve leaves cheekPuff_L and mouthStretch_L both above 0.2; with the rig's
    antagonists, no pair, and the marker still reaches its target."""
    import scipy.sparse as sp
    from model.antagonists import pair_indices, rig_antagonists, strong_pairs
    from model.segmentation import SegmentationSettings, segment_rig
    from solvers.regional_solve import RegionalSolver, shape_region_max
    rig = ict_rig
    seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, SegmentationSettings())
    regions = [r.vertices for r in seg.levels[3].regions]
    corner = int(np.argmax(np.linalg.norm(rig.deltas[rig.shape_index("mouthSmile_L"), :9409], axis=1)))
    S = sp.csr_matrix(([1.0], ([0], [corner])), shape=(1, rig.n_vertices))
    A = np.stack([S @ rig.deltas[k] for k in range(rig.n_shapes)]).reshape(rig.n_shapes, -1).T
    pairs = pair_indices(rig, rig_antagonists(rig))
    region_max = shape_region_max(rig.deltas, regions)
    found = {}
    for name, ant in (("plain", None), ("antagonists", pairs)):
        solver = RegionalSolver(regions, S, A, region_max=region_max, solve_background=True, lam_reg=1e-3,
                                antagonists=ant)
        W = np.zeros((len(regions) + 1, rig.n_shapes))
        for step in range(1, 7):
            b = np.array([1.5, 1.0, 0.0]) * step / 6
            W = solver.solve(b, W)
        found[name] = (strong_pairs(W, pairs), np.linalg.norm(A @ W[-1] - b))
    assert found["plain"][0], "the drag no longer trades antagonists: the test lost its point"
    assert found["antagonists"][0] == [] and found["antagonists"][1] < 0.01



def test_a_chin_drag_with_the_lower_lip_pinned_holds_the_antagonist_that_costs_least(ict_rig, take_dir):
    """Eight markers of the take's map from chin to brow (every 6th by height), level 2, solved as a drag solves
    them; the chin marker dragged 5.4 mm down in eight moves, the others pinned. Following it needs jawOpen with
    mouthShrugLower (to hold the lower lip), an antagonist pair: the exclusion holds the member whose hold costs
    least, so the chin reaches its target (within 0.2 mm), the pins hold (0.05 mm) and no pair is left on.
    Holding the weaker member instead (the rule before) held jawOpen: the chin stopped 1.4 mm short and a pinned
    marker moved 1.6 mm, the face creased between the regions. The background row is solved from the markers on
    the background's vertices: from all of them, it also followed the chin and its pinned markers moved 0.2 mm."""
    from model.antagonists import pair_indices, rig_antagonists, strong_pairs
    from model.markers import Marker, MarkerSet
    from model.segmentation import SegmentationSettings, segment_rig
    from solvers.regional_solve import shape_region_max
    rig = ict_rig
    verts = list(load_marker_map(take_dir / "marker_map.json").markers.values())
    chosen = sorted(verts, key=lambda v: rig.neutral[v, 1])[::6][:8]
    ms = MarkerSet.for_rig(rig, [Marker(f"m{i}", vertex=int(v)) for i, v in enumerate(chosen)])
    level = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, SegmentationSettings()).levels[2]
    regions = [r.vertices for r in level.regions]
    pairs = pair_indices(rig, rig_antagonists(rig))
    solver = ms.drag_solver(rig, regions, shape_region_max(rig.deltas, regions), antagonists=pairs,
                            background=np.flatnonzero(level.blend.toarray()[:, -1] > 0))
    start = ms.positions(rig.neutral)
    chin = int(np.argmin(start[:, 1]))
    W = np.zeros((len(regions) + 1, rig.n_shapes))
    for step in range(1, 9):
        targets = start.copy()
        targets[chin, 1] -= 0.54 * step / 8
        W = solver.solve((targets - start).reshape(-1), W)
    moved = ms.positions(PoseEvaluator(rig, dtype=np.float64).pose(W, blend=level.blend)) - start
    assert np.linalg.norm(moved[chin] - (targets[chin] - start[chin])) < 0.02, moved[chin]
    assert np.linalg.norm(np.delete(moved, chin, axis=0), axis=1).max() < 0.005
    assert strong_pairs(W, pairs, 0.1) == []


def test_refit_points_moves_a_marker_to_the_point_that_explains_its_motion_unless_the_prior_says_no():
    """``refit_points``: three candidate vertices with different motions; the marker moved like vertex 2. It moves
    there from vertex 0, unless vertex 2 is many σ from where the registration put it and the gain is small."""
    from solvers.retarget import refit_points
    rng = np.random.default_rng(5)
    deltas = rng.normal(size=(4, 3, 3))                      # 4 shapes, 3 vertices
    W = rng.uniform(0, 1, (50, 4))
    motion = np.einsum("fk,kc->fc", W, deltas[:, 2])[:, None] + rng.normal(scale=0.01, size=(50, 1, 3))
    motion[::7] = np.nan                                      # missing samples are skipped
    cand = [np.array([0, 1, 2])]
    assert refit_points(motion, W, deltas, cand, [np.array([0.0, 1.0, 1.0])], lam=0.05).tolist() == [2]
    # a candidate a little worse (its motion 1 % off) wins when the better one is 10 σ away, loses without a prior
    near = deltas.copy()
    near[:, 0] = deltas[:, 2] * 1.01
    assert refit_points(motion, W, near, cand, [np.array([0.0, 1.0, 100.0])], lam=0.05).tolist() == [0]
    assert refit_points(motion, W, near, cand, [np.array([0.0, 1.0, 100.0])], lam=0.0).tolist() == [2]
