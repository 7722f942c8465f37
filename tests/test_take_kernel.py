"""The compiled take-solve sweep (solvers.take_kernel) against the Python sweep it replaces, the batched dense
results and PC2 blocks against the per-frame ones (issue 20)."""
from __future__ import annotations

import numpy as np
import pytest

from model.marker_map import load_marker_map
from model.pc2 import read_pc2, write_pc2
from model.take_c3d import read_c3d
from model.take_workspace import solve_take
from solvers import take_kernel
from solvers.take_solve import TakeSolver, _CachedBoxQP, _smooth_in_time


@pytest.fixture(scope="module")
def take_setup(ict_rig, take_dir):
    take = read_c3d(take_dir / "take.c3d")
    mm = load_marker_map(take_dir / "marker_map.json")
    labels, cols = mm.match(take)
    return take, mm, mm.binding(ict_rig, labels), take.positions[:, cols]


def test_numba_kernel_is_available():
    assert take_kernel.available(), "numba is a dependency (pyproject.toml): the take solve needs its kernel"


def test_kernel_is_the_ahead_of_time_build_and_a_fresh_solve_does_not_import_numba(ict_dir, take_dir):
    """The sweep runs in the extension module built from take_kernel_jit (numba.pycc), so a fresh process that
    solves a take never pays for importing numba (about 0.5 s of CPU: more than the solve)."""
    import subprocess
    import sys
    from pathlib import Path
    module = take_kernel.kernel()
    assert module.__name__ == "_take_kernel_aot" and Path(module.__file__) == take_kernel._built_path()
    code = ("import sys\n"
            "from model.readers import load_rig\n"
            "from model.take_workspace import TakeWorkspace\n"
            f"ws = TakeWorkspace(load_rig({str(ict_dir)!r}))\n"
            f"ws.load_take({str(take_dir / 'take.c3d')!r}); ws.load_map({str(take_dir / 'marker_map.json')!r})\n"
            "sol = ws.solve({'mode': 'global'})\n"
            "print(sol.n_frames, sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'llvmlite')))\n")
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, check=True,
                         env={**__import__("os").environ, "PYTHONPATH": str(root)})
    assert out.stdout.split() == ["358", "[]"], out.stdout + out.stderr


def test_the_built_kernels_release_the_gil_while_they_run():
    """A thread running a built kernel (here the deformation maps of a 2M-vertex ring graph, ~60 ms a call, four
    calls) leaves the GIL to the others: this thread's Python loop keeps running all through the calls, so nearly
    every 5 ms of them sees it tick. With the GIL held, the loop stands still while each call runs (it ticks only
    between calls: 7 of 46 of the 5 ms slots on a build that holds it)."""
    import threading
    import time
    module = take_kernel.kernel()
    assert module.__name__ == "_take_kernel_aot"
    V = 2_000_000
    indptr = np.arange(0, 8 * V + 1, 8, dtype=np.int32)
    indices = ((np.repeat(np.arange(V), 8) + np.tile(np.arange(8), V)) % V).astype(np.int32)
    data, d = np.ones(8 * V), np.random.default_rng(0).random((V, 3))
    lap, disp = np.empty(V), np.empty(V)
    done = threading.Event()
    span: list[float] = []

    def run():
        span.append(time.perf_counter())
        for _ in range(4):
            module.shape_maps(indptr, indices, data, d, lap, disp, 0, V)
        span.append(time.perf_counter())
        done.set()
    thread = threading.Thread(target=run)
    ticks = []
    thread.start()
    while not done.is_set():
        ticks.append(time.perf_counter())
    thread.join()
    t0, t1 = span
    slots = max(1, int((t1 - t0) / 0.005))
    seen = {int((t - t0) / 0.005) for t in ticks if t0 <= t < t0 + slots * 0.005}
    assert t1 - t0 > 0.08, f"four calls took {(t1 - t0) * 1000:.0f} ms: too short to tell"
    assert len(seen) > 0.5 * slots, (f"this thread ran in {len(seen)} of the {slots} 5 ms slots of the kernel's "
                                     f"{(t1 - t0) * 1000:.0f} ms: the kernel held the GIL")


def test_box_qp_matches_the_python_active_set_on_random_problems():
    rng = np.random.default_rng(3)
    K = 40
    L, order, pos, x, r = np.zeros((K, K)), np.zeros(K, np.int64), np.zeros(K, np.int64), np.zeros(K), np.zeros(K)
    nf = -1
    H = None
    for trial in range(60):
        if trial % 20 == 0:      # a new H every 20 problems; between, the factor is carried over (warm)
            A = rng.normal(size=(90, K)) * (rng.random(K) < 0.7)
            H = A.T @ A + 0.5 * np.eye(K)
            nf = -1
        g = rng.normal(size=K) * 15
        w0 = np.clip(rng.normal(size=K) * 0.5 + 0.3, 0, 1)
        ref = _CachedBoxQP(H, cache=False).solve(g, w0.copy())
        w = w0.copy()
        _, nf = take_kernel.box_qp(H, g, w, 0.0, 1.0, 1e-12 * np.abs(H).max(), 200, L, order, pos, x, r, nf)
        assert np.abs(w - ref).max() < 1e-9
        # and it is the optimum: projected gradient zero
        grad = H @ w - g
        assert np.all(grad[w <= 0] >= -1e-8) and np.all(grad[w >= 1] <= 1e-8)
        assert np.abs(grad[(w > 0) & (w < 1)]).max(initial=0) < 1e-8


def _kkt_violation(H, g, w, lo=0.0, hi=1.0) -> float:
    """How far w is from the box QP's optimum: the projected gradient (0 at the minimiser, Nocedal & Wright
    Thm 12.1 for bounds: ∇ ≥ 0 at the lower bound, ≤ 0 at the upper one, = 0 inside)."""
    grad = H @ w - g
    return max(-grad[w <= lo].min(initial=0.0), grad[w >= hi].max(initial=0.0),
               np.abs(grad[(w > lo) & (w < hi)]).max(initial=0.0))


@pytest.mark.parametrize("form", ["dense", "low-rank"])
def test_box_qp_reaches_the_optimum_of_problems_that_need_hundreds_of_pivots(form):
    """From zero, these optima change ~240 of 300 variables' bounds: one at a time (the primal active set alone)
    that is more than the solver's 200 iterations. The primal-dual phase changes many per solve: both forms
    reach the optimum (the KKT conditions to 1e-9) in a few dozen, from cold and from warm starts, and agree with
    the primal method given all the pivots it needs."""
    rng = np.random.default_rng(11)
    K, m, mu = 300, 61, 0.7
    B = rng.normal(size=(m, K)) * (rng.random((m, K)) < 0.2)
    H = B.T @ B + mu * np.eye(K)
    Bt = np.ascontiguousarray(B.T)
    L, order, pos, x, r = np.zeros((K, K)), np.zeros(K, np.int64), np.zeros(K, np.int64), np.zeros(K), np.zeros(K)
    Lg, s_state, work = np.zeros((m, m)), np.zeros(K), np.zeros((2, K))
    nf, w_prev, iterations = -1, np.zeros(K), []
    for trial in range(12):
        g = 0.5 * w_prev + rng.normal(size=K) * 3
        w = w_prev.copy()
        if form == "dense":
            n, nf = take_kernel.box_qp(H, g, w, 0.0, 1.0, 1e-12 * np.abs(H).max(), 200, L, order, pos, x, r, nf)
        else:
            tol = 1e-12 * ((Bt * Bt).sum(axis=1).max() + mu)
            n = take_kernel.box_qp_lowrank(Bt, mu, g, w, 0.0, 1.0, tol, 200, Lg, s_state, trial == 0, work)
        iterations.append(n)
        assert _kkt_violation(H, g, w) < 1e-9, (trial, n)
        ref = w_prev.copy()      # the primal method alone (no primal-dual phase), with all the pivots it needs
        take_kernel.box_qp(H, g, ref, 0.0, 1.0, 1e-12 * np.abs(H).max(), 5000, np.zeros((K, K)), np.zeros(K, np.int64),
                           np.zeros(K, np.int64), np.zeros(K), np.zeros(K), -1, 0)
        assert np.abs(w - ref).max() < 1e-9
        w_prev = w
    assert iterations[0] < 60 and max(iterations) < 100, iterations


def test_a_take_solve_with_correctives_steps_through_the_compiled_qp_to_the_python_steps_weights(ict_rig, take_setup):
    """With correctives each Gauss–Newton step solves a QP of its own H; the compiled kernel (``box_qp_fresh``,
    exported by the ahead-of-time build) and the Python active set (``_CachedBoxQP``) give the same take."""
    from model.correctives import Corrective, set_correctives, solver_correctives
    from solvers.correctives import driver_region
    assert hasattr(take_kernel.kernel(), "box_qp_fresh")
    rig = ict_rig.copy()
    cs = []
    for drivers in (["browInnerUp_L", "browInnerUp_R"], ["mouthFunnel", "mouthPucker"]):
        d = rig.deltas[[rig.shape_index(n) for n in drivers]]
        cs.append(Corrective(drivers=drivers, delta=-0.2 * driver_region(d)[:, None] * d.sum(axis=0)))
    set_correctives(rig, cs)
    _, _, B, X = take_setup
    s = TakeSolver(rig.neutral, rig.deltas, B, correctives=solver_correctives(rig), residual="none")
    kernel = s._kernel
    calls = []
    real = take_kernel.box_qp_fresh

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)
    out = {}
    try:
        take_kernel.box_qp_fresh = counted
        for name in ("compiled", "python"):
            s._kernel = kernel if name == "compiled" else None
            out[name] = s.solve(X[:120], unit_factor=0.1)
    finally:
        s._kernel = kernel
        take_kernel.box_qp_fresh = real
    assert len(calls) > 200                     # every step of the compiled sweep went through the kernel
    a, b = out["compiled"], out["python"]
    assert np.abs(a.weights - b.weights).max() < 1e-8
    assert a.weights.max() > 0.3


def test_compiled_sweep_equals_the_python_sweep_on_the_ict_take(ict_rig, take_setup):
    """Both sweeps (forward and backward, gaps in the take) give the same weights and head motion."""
    _, _, B, X = take_setup
    s = TakeSolver(ict_rig.neutral, ict_rig.deltas, B, residual="none")
    Xs = _smooth_in_time(X[:200] * 0.1, s.marker_smoothing)
    cal = s.calibrate(Xs, 30)
    Y = Xs @ cal[:3, :3].T + cal[:3, 3]
    assert np.isnan(Y).any()        # the take has occlusion gaps: several missing-marker masks
    kernel = s._kernel
    assert kernel is not None
    out = {}
    for name in ("compiled", "python"):
        s._kernel = kernel if name == "compiled" else None
        order = range(Y.shape[0] - 1, -1, -1)
        out[name] = s._pass(Y, order, np.zeros(s.K), np.eye(3), np.zeros(3), None, None)
    s._kernel = kernel
    (Wc, Rc, tc, okc), (Wp, Rp, tp, okp) = out["compiled"], out["python"]
    assert np.array_equal(okc, okp) and okc.all()
    assert np.abs(Wc - Wp).max() < 1e-9
    assert np.abs(Rc - Rp).max() < 1e-9 and np.abs(tc - tp).max() < 1e-9
    assert Wc.max() > 0.5      # a real expression, not the neutral


def test_dense_blocks_are_the_dense_frames_in_float32(ict_rig, take_setup, tmp_path):
    take, mm, _, _ = take_setup
    sol = solve_take(ict_rig, take, mm)
    blocks = list(sol.dense_blocks(frames=100))
    assert [b.shape[0] for b in blocks] == [100, 100, 100, 58] and blocks[0].dtype == np.float32
    frames = np.concatenate(blocks)
    for f in (0, 99, 100, 201, 357):
        ref = sol.dense(f)
        assert np.abs(frames[f] - ref).max() < 1e-5          # float32 rounding of centimetres
    assert np.abs(frames[150] - sol.dense(149)).max() > 1e-3   # and each block row is its own frame
    # the PC2 writer takes the blocks whole: the same file as frame by frame
    write_pc2(tmp_path / "blocks.pc2", iter(blocks))
    write_pc2(tmp_path / "frames.pc2", (frames[f] for f in range(frames.shape[0])))
    assert (tmp_path / "blocks.pc2").read_bytes() == (tmp_path / "frames.pc2").read_bytes()
    data, _, _ = read_pc2(tmp_path / "blocks.pc2")
    assert np.array_equal(data, frames)


def test_pc2_block_with_a_nan_names_its_frame(tmp_path):
    from model.errors import RigInputError
    good = np.zeros((3, 5, 3), np.float32)
    bad = good.copy()
    bad[2, 1, 0] = np.nan
    with pytest.raises(RigInputError, match="frame 5 has NaN"):
        write_pc2(tmp_path / "x.pc2", iter([good, bad]))
    assert not (tmp_path / "x.pc2").exists()


def test_low_rank_qp_sweep_equals_the_python_sweep_with_many_shapes():
    """400 local shapes seen by 20 markers (K > 2(3M + 1)): the low-rank QP, same weights as the Python sweep."""
    rng = np.random.default_rng(7)
    V, K, M, F = 300, 400, 20, 40
    neutral = rng.normal(size=(V, 3)) * 5
    deltas = np.zeros((K, V, 3))
    for k in range(K):                     # each shape moves a patch of 30 vertices
        c = rng.integers(0, V - 30)
        deltas[k, c:c + 30] = rng.normal(size=(30, 3)) * 0.3
    markers = np.sort(rng.choice(V, M, replace=False))
    W = np.clip(rng.normal(0.2, 0.3, size=(F, K)), 0, 1)
    W[:5] = 0.0
    X = neutral[markers][None] + np.einsum("fk,kmc->fmc", W, deltas[:, markers])
    X[12:15, 3] = np.nan                   # a gap: a second missing-marker mask
    s = TakeSolver(neutral, deltas, markers, residual="none", lam_sparsity=0.05, marker_smoothing=0.0)
    assert s.K > 2 * (3 * s.M + 1)
    kernel = s._kernel
    out = {}
    for name in ("compiled", "python"):
        s._kernel = kernel if name == "compiled" else None
        out[name] = s.solve(X, calibration_frames=5)
    s._kernel = kernel
    a, b = out["compiled"], out["python"]
    assert np.abs(a.weights - b.weights).max() < 1e-8
    assert np.abs(a.head - b.head).max() < 1e-8
    assert 0.0 < a.weights.max() <= 1.0 and a.weights.min() >= 0.0


def test_a_process_needing_the_kernel_waits_for_a_build_under_way_instead_of_building_it_again(tmp_path, monkeypatch):
    """Two builders of one cache folder (the GUI's background build and a solve started meanwhile, or a batch's
    workers): the second waits on the build lock, then loads what the first built; the kernel is compiled once."""
    import shutil
    import threading
    import time
    built = take_kernel._built_path() or (take_kernel.kernel() and take_kernel._built_path())
    monkeypatch.setattr(take_kernel, "_cache_dirs", lambda: [tmp_path])
    compiled = []

    def slow_compile(folder, name):           # the real build's result, after a real build's kind of wait
        compiled.append(name)
        time.sleep(0.6)
        shutil.copy(built, folder / name)
    monkeypatch.setattr(take_kernel, "_compile", slow_compile)
    assert not take_kernel._built_path()
    results = []
    first = threading.Thread(target=lambda: results.append(take_kernel._build()))
    first.start()
    time.sleep(0.2)                            # the first holds the lock and is compiling
    t0 = time.perf_counter()
    results.append(take_kernel._build())
    waited = time.perf_counter() - t0
    first.join()
    assert len(compiled) == 1, compiled
    assert waited > 0.2 and all(r is not None and hasattr(r, "solve_pass") for r in results)
    assert take_kernel._built_path() == tmp_path / compiled[0]


def test_a_rig_loading_while_a_solve_builds_the_kernel_does_not_wait_for_the_build(tmp_path, monkeypatch):
    """The OBJ reader asks for the built kernel (``built()``) while a solve thread may be compiling it
    (``kernel()``, up to half a minute): the reader gets None at once and reads with numpy, the build still under
    way when the rig is in; once the build is in, both get the same module."""
    import shutil
    import threading
    import time

    from model.readers import load_rig
    from resources.sample_rig import write_sample
    folder = write_sample(tmp_path / "sample")
    real = take_kernel._built_path() or (take_kernel.kernel() and take_kernel._built_path())
    monkeypatch.setattr(take_kernel, "_cache_dirs", lambda: [tmp_path])
    monkeypatch.setattr(take_kernel, "_impl", None)
    building = threading.Event()

    def slow_compile(folder, name):
        building.set()
        time.sleep(4.0)
        shutil.copy(real, folder / name)
    monkeypatch.setattr(take_kernel, "_compile", slow_compile)
    solve = threading.Thread(target=take_kernel.kernel)
    solve.start()
    assert building.wait(30)                     # the solve thread is compiling
    assert take_kernel.built() is None
    rig = load_rig(folder)                       # numpy's reader, not waiting for the build
    assert solve.is_alive() and rig.n_vertices > 0
    solve.join()
    assert take_kernel.built() is take_kernel.kernel() and hasattr(take_kernel.built(), "parse_vertex_lines")


@pytest.mark.parametrize("ready", [False, True])
def test_a_solve_that_must_compile_the_solver_says_so_first(ready, monkeypatch, capsys, ict_dir, take_dir, tmp_path):
    """The first `solve` after installing compiles the take solver before solving (up to half a minute): it says
    so on stderr instead of sitting silent; once it is built, nothing is said."""
    from app.cli import main
    monkeypatch.setattr(take_kernel, "ready", lambda: ready)
    rc = main(["solve", str(ict_dir), str(take_dir / "take.c3d"), "--map", str(take_dir / "marker_map.json"),
               "-o", str(tmp_path / "w.csv")])
    err = capsys.readouterr().err
    assert rc == 0 and (tmp_path / "w.csv").is_file()
    assert (take_kernel.BUILD_MESSAGE in err) is (not ready), err
