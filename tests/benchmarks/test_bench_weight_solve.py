"""Speed of the weight solves on ICT: one drag step over a segmentation level, global solves cold and warm."""
from __future__ import annotations

import numpy as np
import pytest

from model.markers import Marker, MarkerSet
from model.pose import evaluate
from solvers.regional_solve import RegionalSolver
from solvers.weight_solve import WeightSolver


@pytest.fixture(scope="module")
def drag_problem(ict_rig):
    from model.segmentation import segment_rig
    rig = ict_rig
    level = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas).levels[1]
    # One marker at the centre of each of the 6 largest regions of level 1 (20 regions), so 6 regions solve.
    big = sorted(level.regions, key=lambda r: -r.core.size)[:6]
    verts = []
    for reg in big:
        P = rig.neutral[reg.core]
        verts.append(int(reg.core[np.argmin(np.linalg.norm(P - P.mean(axis=0), axis=1))]))
    ms = MarkerSet.for_rig(rig, [Marker(f"M{i}", vertex=int(v)) for i, v in enumerate(verts)])
    solver = RegionalSolver([r.vertices for r in level.regions], ms.S, ms.delta_rows(rig.deltas), deltas=rig.deltas)
    assert len(solver.active_regions) == 6
    W = np.zeros((level.n_regions + 1, rig.n_shapes))
    targets = ms.positions(rig.neutral)
    targets[1] += [0.6, 0.5, 0.0]
    b = (targets - ms.positions(rig.neutral)).reshape(-1)
    return solver, b, W, level


def test_bench_drag_solve_one_level(benchmark, drag_problem):
    """One mouse move: 6 markers in 6 regions of level 1 of the ICT segmentation (20 regions), the solver of
    the press reused (warm)."""
    solver, b, W, level = drag_problem
    out = benchmark(solver.solve, b, W)
    assert out.shape == W.shape and out.min() >= 0 and out.max() <= 1
    print(f"drag solve: {level.n_regions} regions, {len(solver.active_regions)} with markers, "
          f"shapes per region {[len(solver.shapes[r]) for r in solver.active_regions]}")


@pytest.fixture(scope="module")
def global_problem(ict_rig):
    rig = ict_rig
    rng = np.random.default_rng(0)
    moving = np.flatnonzero(np.abs(rig.deltas[:, :9409]).max(axis=(0, 2)) > 1e-6)
    verts = rng.choice(moving, 60, replace=False)
    ms = MarkerSet.for_rig(rig, [Marker(f"M{i:02d}", vertex=int(v)) for i, v in enumerate(verts)])
    A = ms.delta_rows(rig.deltas)
    w_true = np.clip(rng.normal(0.2, 0.3, rig.n_shapes), 0, 1)
    b = (ms.positions(evaluate(rig, w_true)) - ms.positions(rig.neutral)).reshape(-1)
    return A, b


def test_bench_global_solve_cold(benchmark, global_problem):
    """A fresh solver and a solve from nothing: 60 markers, 57 shapes."""
    A, b = global_problem
    w = benchmark(lambda: WeightSolver(A, lam_sparsity=1e-4).solve(b))
    assert WeightSolver(A, lam_sparsity=1e-4).is_feasible(w)


def test_bench_global_solve_fresh_start(benchmark, global_problem):
    """The solver reused, but no warm start (the previous behaviour of the 'cold' benchmark)."""
    A, b = global_problem
    s = WeightSolver(A, lam_sparsity=1e-4)
    w = benchmark(s.solve, b)
    assert s.is_feasible(w)


def test_bench_global_solve_warm(benchmark, global_problem):
    """A take frame warm-started from the previous frame (mocap): 60 markers, 57 shapes."""
    A, b = global_problem
    s = WeightSolver(A, lam_sparsity=1e-4, lam_temporal=1e-3)
    w0 = s.solve(b)
    b2 = b + 0.001 * np.random.default_rng(1).normal(size=b.size)
    w = benchmark(lambda: s.solve(b2, w_prev=w0, w_start=w0))
    assert s.is_feasible(w)
