"""Take solve speed and accuracy on the real ICT Live Link take (358 frames, 60 markers).

Target (issue "Motion capture: solve takes onto the rig"): ≥ 500 frames/s for the solve including the
residual coefficients. Accuracy: the dense RMS against truth_dense_face.npz that the README quotes.
Warm figures reuse one solver; cold ones build a fresh solver per solve, as the command line and the GUI do. Figures go into
``benchmark.extra_info`` (see ``--benchmark-json``) and are printed with ``-s``.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp

from model.marker_map import load_marker_map
from model.pose import PoseEvaluator
from model.take_c3d import read_c3d
from model.take_workspace import solve_take
from solvers.take_solve import TakeSolver


# The README's accuracy figures (dense RMS in mm over the moving face, README "Benchmarks"): each benchmark
# asserts its figure to within 0.0005 mm of the README's, so the README stays true.
README_DENSE_RMS_MM = {"default": 0.2025, "correctives": 0.2028, "none": 0.2094, "joshi": 0.2028, "gaussian": 0.2025,
                       "multiquadric": 0.2096, "regional": 0.1974}


def assert_readme_accuracy(err: float, key: str) -> None:
    quoted = README_DENSE_RMS_MM[key]
    assert abs(err - quoted) < 0.0005, f"dense RMS {err:.4f} mm, the README quotes {quoted:.4f} mm ({key})"


@pytest.fixture(scope="module")
def take_and_map(take_dir):
    return read_c3d(take_dir / "take.c3d"), load_marker_map(take_dir / "marker_map.json")


@pytest.fixture(scope="module")
def setup(ict_rig, take_and_map, take_dir):
    take, mm = take_and_map
    labels, cols = mm.match(take)
    return mm.binding(ict_rig, labels), take.positions[:, cols], np.load(take_dir / "truth_dense_face.npz")


@pytest.fixture(scope="module")
def pairs(ict_rig):
    """The antagonist pairs the solve keeps apart by default (``solve_take`` finds them from the rig): the warm
    solvers below get them too, so warm and cold measure the same solve."""
    from model.antagonists import pair_indices, rig_antagonists
    return pair_indices(ict_rig, rig_antagonists(ict_rig))


@pytest.fixture(scope="module")
def rig4(ict_rig):
    """ICT with four correctives (Smith's brow pair and three other top pairs of the finder, each taking back
    20% of the pair's summed motion where both act)."""
    from model.correctives import Corrective, set_correctives
    from solvers.correctives import driver_region
    rig = ict_rig.copy()
    pairs = [["browInnerUp_L", "browInnerUp_R"], ["mouthFunnel", "mouthPucker"], ["eyeLookUp_L", "eyeWide_L"],
             ["cheekRaiser_L", "cheekSquint_L"]]
    cs = []
    for drivers in pairs:
        d = rig.deltas[[rig.shape_index(n) for n in drivers]]
        cs.append(Corrective(drivers=drivers, delta=-0.2 * driver_region(d)[:, None] * d.sum(axis=0)))
    set_correctives(rig, cs)
    return rig


def dense_rms_mm(sol, truth) -> float:
    moving, pos = truth["moving"], truth["positions"].astype(np.float64)
    errs = [np.sqrt(np.mean(np.sum((sol.dense(int(f))[: pos.shape[1]][moving] - pos[i][moving]) ** 2, axis=1)))
            for i, f in enumerate(truth["frames"])]
    return float(np.mean(errs)) * 10.0


def _report(benchmark, what, frames, err):
    fps = frames / benchmark.stats.stats.min
    benchmark.extra_info.update(frames=frames, dense_rms_mm=err, frames_per_second_best=fps)
    print(f"\n{what}: {frames} frames, best {benchmark.stats.stats.min:.3f} s, median "
          f"{benchmark.stats.stats.median:.3f} s = {fps:.0f} fps best, dense RMS {err:.4f} mm")


def test_bench_take_solve(benchmark, ict_rig, setup, pairs):
    """Warm: the solver (everything rig/marker-set dependent) built once, the take solved again and again."""
    B, X, truth = setup
    solver = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, antagonists=pairs,
                        surface=PoseEvaluator(ict_rig, dtype=np.float64).evaluate)  # everything rig/marker-set dependent, once
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=5, iterations=1)
    err = dense_rms_mm(sol, truth)
    benchmark.extra_info.update(marker_rmse_cm=float(np.nanmean(sol.marker_rmse)))
    _report(benchmark, "take solve, warm", X.shape[0], err)
    assert_readme_accuracy(err, "default")


def test_bench_take_solve_cold(benchmark, ict_rig, take_and_map, setup):
    """Cold: a fresh solver for the take, as `blendshape-studio solve` and the Mocap panel's Solve run it
    (``solve_take``: binding, solver set-up, calibration, solve)."""
    take, mm = take_and_map
    sol = benchmark.pedantic(solve_take, args=(ict_rig, take, mm), rounds=3, iterations=1)
    err = dense_rms_mm(sol, setup[2])
    _report(benchmark, "take solve, cold", sol.n_frames, err)
    assert_readme_accuracy(err, "default")


def test_bench_take_solve_with_correctives(benchmark, rig4, setup, pairs):
    """Warm, on ICT with four correctives: Gauss–Newton weight steps."""
    from model.correctives import solver_correctives
    B, X, truth = setup
    solver = TakeSolver(rig4.neutral, rig4.deltas, B, correctives=solver_correctives(rig4), antagonists=pairs,
                        surface=PoseEvaluator(rig4, dtype=np.float64).evaluate)
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=3, iterations=1)
    err = dense_rms_mm(sol, truth)
    _report(benchmark, "take solve with 4 correctives, warm", X.shape[0], err)
    assert_readme_accuracy(err, "correctives")


def test_bench_take_solve_with_correctives_cold(benchmark, rig4, take_and_map, setup):
    """Cold, on ICT with four correctives: a fresh solver each time, as the command line and the GUI run it."""
    take, mm = take_and_map
    sol = benchmark.pedantic(solve_take, args=(rig4, take, mm), rounds=2, iterations=1)
    err = dense_rms_mm(sol, setup[2])
    _report(benchmark, "take solve with 4 correctives, cold", sol.n_frames, err)
    assert_readme_accuracy(err, "correctives")


def test_bench_take_solve_cli_fresh_process(benchmark, ict_dir, take_dir, tmp_path):
    """`blendshape-studio solve ... --cache ... --report ...` in a fresh process, as a user runs it: start-up,
    imports, loading ICT and the take, the solve, the dense PC2 cache (358 frames, 115 MB), the weights CSV and the
    report. Target (issue 20): under 1.5 s. The child's CPU time (user + system, ``RUSAGE_CHILDREN``) is kept
    beside the wall time: on a shared machine the wall time mostly measures the other jobs. Python's bytecode cache
    is on, as in a user's environment (the development sandbox sets PYTHONDONTWRITEBYTECODE=1, under which every
    run compiled the project's ~56 modules again: 0.05-0.09 s); the first of the three runs writes it where it is
    missing."""
    import resource
    from tests.cli_runner import run_cli
    report = tmp_path / "report.json"
    cpu: list[float] = []

    def solve():
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json",
                "-o", tmp_path / "weights.csv", "--cache", tmp_path / "dense.pc2", "--report", report,
                env={"PYTHONDONTWRITEBYTECODE": ""})   # empty: not set
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
        return json.loads(report.read_text())

    out = benchmark.pedantic(solve, rounds=3, iterations=1)
    assert out["frames"] == 358 and out["mode"] == "global" and out["marker_rmse"] < 0.05
    assert (tmp_path / "dense.pc2").stat().st_size == 32 + 358 * ict_dir_vertices(ict_dir) * 12
    benchmark.extra_info.update(solve_seconds_in_process=out["solve_seconds"], cpu_seconds=cpu)
    print(f"\nsolve --cache --report in a fresh process: best {benchmark.stats.stats.min:.2f} s wall, "
          f"{min(cpu):.2f} s CPU (runs: {', '.join(f'{c:.2f}' for c in cpu)}); the solve "
          f"{out['solve_seconds']:.2f} s ({out['frames_per_second']:.0f} fps)")


def ict_dir_vertices(ict_dir) -> int:
    """ICT's vertex count from its neutral's 'v' lines (the PC2's size check, without loading the rig)."""
    return sum(1 for line in (ict_dir / "generic_neutral_mesh.obj").read_bytes().splitlines() if line[:2] == b"v ")


def test_bench_take_dense_all_frames(benchmark, ict_rig, setup):
    """Every frame's dense surface as the exports compute it: float32 blocks of frames, each two matrix products
    (the pose and the RBF residual) with the evaluator's batch evaluation."""
    B, X, _ = setup
    ev = PoseEvaluator(ict_rig, dtype=np.float64)
    sol = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, surface=ev.evaluate, surface_many=ev.evaluate_many
                     ).solve(X, unit_factor=0.1)

    def all_frames():
        n = 0
        for x in sol.dense_blocks():
            n += x.shape[0] * x.shape[1]
        return n

    assert benchmark.pedantic(all_frames, rounds=2, iterations=1) == X.shape[0] * ict_rig.n_vertices


@pytest.mark.parametrize("residual", ["none", "joshi", "gaussian", "multiquadric"])
def test_bench_take_solve_residual_kernels(benchmark, ict_rig, setup, residual, pairs):
    """Accuracy of each residual kernel with the solver's defaults otherwise (scale/λ per kernel below)."""
    B, X, truth = setup
    opts = {"joshi": dict(rbf_scale=3.0, rbf_lambda=0.3), "multiquadric": dict(rbf_lambda=0.01)}.get(residual, {})
    solver = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, residual=residual, antagonists=pairs,
                        surface=PoseEvaluator(ict_rig, dtype=np.float64).evaluate, **opts)
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=1, iterations=1)
    err = dense_rms_mm(sol, truth)
    benchmark.extra_info.update(residual=residual, dense_rms_mm=err)
    print(f"\nresidual {residual}: dense RMS {err:.4f} mm")
    assert_readme_accuracy(err, residual)


def test_bench_take_solve_regional(benchmark, ict_rig, setup, pairs):
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
                        antagonists=pairs,
                        surface=lambda W: ev.evaluate_regional(W, blend))
    sol = benchmark.pedantic(solver.solve, args=(X,), kwargs={"unit_factor": 0.1}, rounds=1, iterations=1)
    err = dense_rms_mm(sol, truth)
    benchmark.extra_info.update(dense_rms_mm=err)
    print(f"\nregional (2 regions): dense RMS {err:.4f} mm")
    assert_readme_accuracy(err, "regional")
