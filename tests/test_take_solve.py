"""The take solve (ALGORITHMS.md §4, §5, §7) on the real ICT Live Link take, plus the RBF residual."""
from __future__ import annotations

import csv

import numpy as np
import pytest
import scipy.sparse as sp

from model.marker_map import load_marker_map
from model.take_c3d import read_c3d
from solvers.rbf import RBFResidual, phantom_points
from solvers.take_solve import SolveCancelled, TakeSolver, solve_take


@pytest.fixture(scope="module")
def take_setup(ict_rig, take_dir):
    take = read_c3d(take_dir / "take.c3d")
    mm = load_marker_map(take_dir / "marker_map.json")
    labels, cols = mm.match(take)
    truth = np.load(take_dir / "truth_dense_face.npz")
    return take, mm, mm.binding(ict_rig, labels), take.positions[:, cols], truth


@pytest.fixture(scope="module")
def solution(ict_rig, take_setup):
    take, mm, _, _, _ = take_setup
    return solve_take(ict_rig, take, mm)


def dense_rms_mm(sol, truth) -> float:
    """The data README's measure: RMS over `moving` of the distance to `positions`, averaged over frames."""
    moving, pos = truth["moving"], truth["positions"].astype(np.float64)
    errs = []
    for i, f in enumerate(truth["frames"]):
        x = sol.dense(int(f))[: pos.shape[1]]
        errs.append(np.sqrt(np.mean(np.sum((x[moving] - pos[i][moving]) ** 2, axis=1))))
    return float(np.mean(errs)) * 10.0  # cm -> mm


def test_dense_accuracy_below_target(solution, take_setup):
    err = dense_rms_mm(solution, take_setup[4])
    assert err < 0.22, f"dense RMS {err:.4f} mm"


def test_residual_improves_on_the_rig_fit(ict_rig, take_setup, solution):
    _, _, B, X, truth = take_setup
    plain = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, residual="none").solve(X, unit_factor=0.1)
    assert plain.coefficients is None
    assert dense_rms_mm(solution, truth) < dense_rms_mm(plain, truth)
    assert np.allclose(plain.weights, solution.weights)  # the residual does not change the weights


def test_solution_shapes_units_and_head(solution, take_setup, ict_rig):
    take, _, B, X, _ = take_setup
    F, K = take.n_frames, ict_rig.n_shapes
    assert solution.weights.shape == (F, K) and solution.head.shape == (F, 4, 4)
    assert (solution.weights >= 0).all() and (solution.weights <= 1).all()
    # marker RMSE in rig units (cm): optical noise is ~0.3 mm, so around 0.05 cm
    assert 0.02 < np.nanmean(solution.marker_rmse) < 0.1
    assert solution.dense(0).shape == (ict_rig.n_vertices, 3)
    # the head maps the stabilised fit back onto the take (take units, mm): within a few noise levels
    f = 200
    fit = B @ solution.dense(f)
    back = fit @ solution.head[f][:3, :3].T + solution.head[f][:3, 3]
    ok = np.isfinite(X[f]).all(axis=1)
    assert np.sqrt(np.mean(np.sum((back[ok] - X[f][ok]) ** 2, axis=1))) < 1.0  # mm


def test_gaps_are_dropped_per_frame(solution, take_setup):
    take = take_setup[0]
    miss = take.missing
    gap_frames = np.flatnonzero(miss.any(axis=1))
    assert gap_frames.size > 0
    f = int(gap_frames[0])
    assert np.isnan(solution.misfit[f][miss[f]]).all()
    assert np.isfinite(solution.misfit[f][~miss[f]]).all()
    assert np.isfinite(solution.weights).all() and np.isfinite(solution.marker_rmse).all()
    assert np.isfinite(solution.dense(f)).all()
    # coefficients of a missing marker are zero for that frame
    assert np.all(solution.coefficients[f][: take.n_markers][miss[f]] == 0)


def test_weights_track_truth(solution, take_dir, ict_rig):
    with open(take_dir / "truth_weights.csv") as fh:
        rows = list(csv.reader(fh))
    names = rows[0][1:]
    truth = np.array([[float(v) for v in r[1:]] for r in rows[1:]])
    solved = solution.weights[:, [ict_rig.shape_index(n) for n in names]]
    active = [j for j in range(len(names)) if truth[:, j].std() > 0.1]  # the shapes the take really uses
    assert len(active) >= 20
    for j in active:
        corr = np.corrcoef(solved[:, j], truth[:, j])[0, 1]
        assert corr > 0.85, (names[j], corr)
    assert np.median([np.corrcoef(solved[:, j], truth[:, j])[0, 1] for j in active]) > 0.97
    assert np.sqrt(np.mean((solved - truth) ** 2)) < 0.08


def test_progress_and_cancel(ict_rig, take_setup):
    _, _, B, X, _ = take_setup
    solver = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, residual="none", two_pass=False)
    seen = []
    solver.solve(X[:40], unit_factor=0.1, progress=lambda d, t, what: seen.append((d, t)))
    assert seen and seen[-1][0] == seen[-1][1]
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 10

    with pytest.raises(SolveCancelled):
        solver.solve(X, unit_factor=0.1, cancel=cancel)


def test_regional_solve_blends_regions(ict_rig, take_setup):
    _, _, B, X, _ = take_setup
    V = ict_rig.n_vertices
    upper = np.flatnonzero(ict_rig.neutral[:, 1] > 0.0)
    lower = np.flatnonzero(ict_rig.neutral[:, 1] <= 1.0)
    blend = np.zeros((V, 3))
    blend[upper, 0] = 1.0
    blend[lower, 1] = 1.0
    blend[np.intersect1d(upper, lower), :2] = 0.5
    solver = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, regions=[upper, lower], blend=sp.csr_matrix(blend))
    sol = solver.solve(X[:60], unit_factor=0.1)
    assert sol.region_weights.shape == (60, 3, ict_rig.n_shapes)
    assert np.allclose(sol.region_weights[:, 2], sol.weights)  # background row = the global solve
    assert not np.allclose(sol.region_weights[:, 0], sol.region_weights[:, 1])
    assert np.isfinite(sol.dense(45)).all()


def test_rbf_interpolates_and_phantoms_hold(ict_rig):
    rng = np.random.default_rng(0)
    centres = ict_rig.neutral[rng.choice(6000, 20, replace=False)]
    ph_idx = phantom_points(ict_rig.neutral[:9409], centres, 2.0, 12)
    phantoms = ict_rig.neutral[ph_idx]
    assert len(ph_idx) == 12
    res = rng.normal(size=(20, 3)) * 0.05
    for kernel in ("joshi", "gaussian", "multiquadric"):
        rbf = RBFResidual(centres, phantoms, np.vstack([centres, phantoms]), kernel=kernel, scale=1.5, lam=0.0)
        C = rbf.coefficients(res)
        out = rbf.evaluate(C)
        assert np.allclose(out[:20], res, atol=1e-8) and np.allclose(out[20:], 0, atol=1e-8)
    # a missing marker is dropped and gets a zero coefficient; its factorisation is cached
    rbf = RBFResidual(centres, phantoms, centres, kernel="gaussian", scale=1.5, lam=0.01)
    gap = res.copy()
    gap[3] = np.nan
    C = rbf.coefficients(gap)
    assert np.all(C[3] == 0) and len(rbf._cache) == 1
    rbf.coefficients(gap)
    assert len(rbf._cache) == 1
    batch = rbf.coefficients_batch(np.stack([gap, gap * 2]))
    assert np.allclose(batch[0], C) and np.allclose(batch[1], 2 * C)
