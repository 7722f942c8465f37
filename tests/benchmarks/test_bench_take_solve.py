"""Take solve speed and accuracy on the real ICT Live Link take (358 frames, 60 markers).

Target (issue "Motion capture: solve takes onto the rig"): ≥ 500 frames/s for the solve including the
residual coefficients, and dense RMS < 0.22 mm against truth_dense_face.npz. Figures go into
``benchmark.extra_info`` (see ``--benchmark-json``) and are printed with ``-s``.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from model.marker_map import load_marker_map
from model.pose import PoseEvaluator
from model.take_c3d import read_c3d
from solvers.take_solve import TakeSolver


@pytest.fixture(scope="module")
def setup(ict_rig, take_dir):
    take = read_c3d(take_dir / "take.c3d")
    mm = load_marker_map(take_dir / "marker_map.json")
    labels, cols = mm.match(take)
    return mm.binding(ict_rig, labels), take.positions[:, cols], np.load(take_dir / "truth_dense_face.npz")


def dense_rms_mm(sol, truth) -> float:
    moving, pos = truth["moving"], truth["positions"].astype(np.float64)
    errs = [np.sqrt(np.mean(np.sum((sol.dense(int(f))[: pos.shape[1]][moving] - pos[i][moving]) ** 2, axis=1)))
            for i, f in enumerate(truth["frames"])]
    return float(np.mean(errs)) * 10.0


def test_bench_take_solve(benchmark, ict_rig, setup):
    B, X, truth = setup
    solver = TakeSolver(ict_rig.neutral, ict_rig.deltas, B,
                        surface=PoseEvaluator(ict_rig, dtype=np.float64).evaluate)  # everything rig/marker-set dependent, once
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=5, iterations=1)
    err = dense_rms_mm(sol, truth)
    fps = X.shape[0] / benchmark.stats.stats.min
    benchmark.extra_info.update(frames=X.shape[0], dense_rms_mm=err, frames_per_second_best=fps,
                                marker_rmse_cm=float(np.nanmean(sol.marker_rmse)))
    print(f"\ntake solve: {X.shape[0]} frames, best {benchmark.stats.stats.min:.3f} s = {fps:.0f} fps, "
          f"dense RMS {err:.4f} mm")
    assert err < 0.22


def test_bench_take_solve_with_correctives(benchmark, ict_rig, setup):
    """The same take on ICT with four correctives (Smith's brow pair and three other top pairs of the finder,
    each taking back 20% of the pair's summed motion where both act): Gauss–Newton weight steps."""
    from model.correctives import Corrective, set_correctives, solver_correctives
    from solvers.correctives import driver_region
    B, X, truth = setup
    rig = ict_rig.copy()
    pairs = [["browInnerUp_L", "browInnerUp_R"], ["mouthFunnel", "mouthPucker"], ["eyeLookUp_L", "eyeWide_L"],
             ["cheekRaiser_L", "cheekSquint_L"]]
    cs = []
    for drivers in pairs:
        d = rig.deltas[[rig.shape_index(n) for n in drivers]]
        cs.append(Corrective(drivers=drivers, delta=-0.2 * driver_region(d)[:, None] * d.sum(axis=0)))
    set_correctives(rig, cs)
    solver = TakeSolver(rig.neutral, rig.deltas, B, correctives=solver_correctives(rig),
                        surface=PoseEvaluator(rig, dtype=np.float64).evaluate)
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=3, iterations=1)
    fps = X.shape[0] / benchmark.stats.stats.min
    err = dense_rms_mm(sol, truth)
    benchmark.extra_info.update(frames_per_second_best=fps, dense_rms_mm=err)
    print(f"\ntake solve with 4 correctives: best {benchmark.stats.stats.min:.3f} s = {fps:.0f} fps, "
          f"dense RMS {err:.4f} mm")
    assert err < 0.22


def test_bench_take_dense_all_frames(benchmark, ict_rig, setup):
    B, X, _ = setup
    sol = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, surface=PoseEvaluator(ict_rig, dtype=np.float64).evaluate
                     ).solve(X, unit_factor=0.1)

    def all_frames():
        n = 0
        for x in sol.iter_dense():
            n += x.shape[0]
        return n

    assert benchmark.pedantic(all_frames, rounds=2, iterations=1) == X.shape[0] * ict_rig.n_vertices


@pytest.mark.parametrize("residual", ["none", "joshi", "gaussian", "multiquadric"])
def test_bench_take_solve_residual_kernels(benchmark, ict_rig, setup, residual):
    """Accuracy of each residual kernel with the solver's defaults otherwise (scale/λ per kernel below)."""
    B, X, truth = setup
    opts = {"joshi": dict(rbf_scale=3.0, rbf_lambda=0.3), "multiquadric": dict(rbf_lambda=0.01)}.get(residual, {})
    solver = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, residual=residual,
                        surface=PoseEvaluator(ict_rig, dtype=np.float64).evaluate, **opts)
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=1, iterations=1)
    err = dense_rms_mm(sol, truth)
    benchmark.extra_info.update(residual=residual, dense_rms_mm=err)
    print(f"\nresidual {residual}: dense RMS {err:.4f} mm")


def test_bench_take_solve_regional(benchmark, ict_rig, setup):
    """Per-region solve (two overlapping face halves, upper/lower) vs the global solve."""
    B, X, truth = setup
    y = ict_rig.neutral[:, 1]
    upper, lower = np.flatnonzero(y > 0.0), np.flatnonzero(y <= 1.0)
    blend = np.zeros((ict_rig.n_vertices, 3))
    blend[upper, 0] = 1.0
    blend[lower, 1] = 1.0
    both = np.intersect1d(upper, lower)
    blend[both, 0] = blend[both, 1] = 0.5
    ev = PoseEvaluator(ict_rig, dtype=np.float64)
    solver = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, regions=[upper, lower], blend=sp.csr_matrix(blend),
                        surface=lambda W: ev.evaluate_regional(W, blend))
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=1, iterations=1)
    err = dense_rms_mm(sol, truth)
    benchmark.extra_info.update(dense_rms_mm=err)
    print(f"\nregional (2 regions): dense RMS {err:.4f} mm")
