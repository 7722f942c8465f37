"""The bounded least-squares weight solve (Joshi Eq. 2; Ma Eq. 3–4): optimality against scipy, feasibility
on any input, recovery of known weights on the ICT rig, bad input."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear, minimize

from model.errors import RigInputError
from model.pose import evaluate
from solvers.weight_solve import WeightSolver, project_feasible, solve_weights, weight_objective


def _random_problem(rng, M=None, K=None, invisible=0.2):
    M = int(rng.integers(2, 25)) if M is None else M
    K = int(rng.integers(2, 40)) if K is None else K
    A = rng.normal(size=(3 * M, K)) * (rng.random(K) > invisible)  # some shapes invisible to the markers
    b = A @ rng.uniform(-0.5, 1.5, K) + 0.1 * rng.normal(size=3 * M)
    return A, b


def _box_reference(A, b, ls, lt, wp, lr, wr):
    K = A.shape[1]
    Aa = np.vstack([A, np.sqrt(ls) * np.ones((1, K)), np.sqrt(lt) * np.eye(K), np.sqrt(lr) * np.eye(K)])
    ba = np.concatenate([b, [0.0], np.sqrt(lt) * wp, np.sqrt(lr) * wr])
    return lsq_linear(Aa, ba, bounds=(0.0, 1.0), method="bvls", tol=1e-14).x


def test_box_matches_scipy_lsq_linear():
    rng = np.random.default_rng(1)
    for _ in range(120):
        A, b = _random_problem(rng)
        K = A.shape[1]
        ls, lt, lr = rng.choice([0.0, 0.1, 1.0]), rng.choice([0.0, 0.5]), rng.choice([0.0, 0.05])
        wp, wr = rng.random(K), rng.random(K)
        w = WeightSolver(A, lam_sparsity=ls, lam_temporal=lt, lam_reg=lr).solve(b, w_prev=wp, w_ref=wr)
        ref = _box_reference(A, b, ls, lt, wp, lr, wr)
        kw = dict(lam_sparsity=ls, lam_temporal=lt, lam_reg=lr, w_prev=wp, w_ref=wr)
        f, f_ref = weight_objective(A, b, w, **kw), weight_objective(A, b, ref, **kw)
        assert abs(f - f_ref) <= 1e-8 * f_ref + 1e-12 * (1 + np.abs(A).sum()), (f, f_ref)
        assert w.min() >= 0.0 and w.max() <= 1.0


def test_convex_matches_scipy_slsqp():
    rng = np.random.default_rng(2)
    for _ in range(60):
        A, b = _random_problem(rng, K=int(rng.integers(2, 14)), invisible=0.0)
        b = A @ rng.uniform(0, 0.4, A.shape[1]) + 0.1 * rng.normal(size=A.shape[0])
        K = A.shape[1]
        ls = float(rng.choice([0.0, 0.1]))
        w = WeightSolver(A, mode="convex", lam_sparsity=ls).solve(b)
        f = lambda x: weight_objective(A, b, x, lam_sparsity=ls)  # noqa: E731
        jac = lambda x: 2 * A.T @ (A @ x - b) + 2 * ls * x.sum()  # noqa: E731
        ref = minimize(f, np.full(K, 0.5 / K), jac=jac, method="SLSQP", bounds=[(0, None)] * K,
                       constraints=[{"type": "ineq", "fun": lambda x: 1 - x.sum(), "jac": lambda x: -np.ones(K)}],
                       options=dict(ftol=1e-15, maxiter=2000)).x
        assert w.min() >= 0.0 and w.sum() <= 1.0 + 1e-12
        # Ours is never worse than SLSQP's, and SLSQP (ftol 1e-15) comes within 1e-8 of ours.
        assert f(w) <= f(ref) * (1 + 1e-8) + 1e-14
        assert f(ref) - f(w) <= 1e-8 * f(w) + 1e-12


def test_never_leaves_the_constraints_on_random_problems():
    """Property: whatever the data (wild targets, degenerate A, warm starts outside), weights stay feasible."""
    rng = np.random.default_rng(3)
    for trial in range(300):
        A, b = _random_problem(rng)
        b = b * rng.choice([1.0, 100.0, -100.0])
        if trial % 7 == 0:
            A[:, : A.shape[1] // 2] = A[:, [0]]  # identical columns: rank deficient
        K = A.shape[1]
        for mode in ("box", "convex"):
            s = WeightSolver(A, mode=mode, lam_sparsity=float(rng.choice([0.0, 0.1])))
            w = s.solve(b, w_start=rng.normal(scale=3.0, size=K))
            assert np.isfinite(w).all()
            assert w.min() >= 0.0
            if mode == "box":
                assert w.max() <= 1.0
            else:
                assert w.sum() <= 1.0 + 1e-12


def test_warm_start_and_gram_give_the_same_answer():
    rng = np.random.default_rng(4)
    A, b = _random_problem(rng, M=30, K=40)
    s = WeightSolver(A, lam_sparsity=0.1)
    cold = s.solve(b)
    warm = s.solve(b, w_start=cold)
    assert s.last_iterations == 1  # the right active set is confirmed in one step
    np.testing.assert_allclose(warm, cold, atol=1e-10)
    g = WeightSolver.from_gram(A.T @ A, lam_sparsity=0.1).solve_gram(A.T @ b)
    np.testing.assert_allclose(g, cold, atol=1e-9)
    np.testing.assert_allclose(solve_weights(A, b, lam_sparsity=0.1), cold, atol=1e-10)


def test_missing_markers_are_dropped():
    rng = np.random.default_rng(5)
    A, b = _random_problem(rng, M=20, K=10)
    b_nan = b.copy()
    b_nan[6:12] = np.nan  # markers 2 and 3 missing this frame
    keep = np.isfinite(b_nan)
    w = WeightSolver(A).solve(b_nan)
    np.testing.assert_allclose(w, WeightSolver(A[keep]).solve(b[keep]), atol=1e-9)


def test_projection_is_exact_for_the_convex_set():
    rng = np.random.default_rng(6)
    for _ in range(50):
        x = rng.normal(size=12) * 2
        p = project_feasible(x, np.zeros(12), np.full(12, np.inf), 1.0)
        assert p.min() >= 0 and p.sum() <= 1 + 1e-12
        # Optimality of a Euclidean projection: (x − p)·(y − p) ≤ 0 for feasible y.
        for y in rng.dirichlet(np.ones(12), size=20) * rng.random((20, 1)):
            assert (x - p) @ (y - p) <= 1e-10


def test_unreachable_target_gives_the_best_bounded_fit():
    rng = np.random.default_rng(7)
    A, _ = _random_problem(rng, M=10, K=6, invisible=0.0)
    b = A @ np.full(6, 5.0)  # five times beyond the shapes' range
    w = WeightSolver(A, lam_sparsity=0.0).solve(b)
    assert w.min() >= 0.0 and w.max() <= 1.0
    ref = lsq_linear(A, b, bounds=(0, 1), method="bvls", tol=1e-14).x
    assert weight_objective(A, b, w, lam_sparsity=0) <= weight_objective(A, b, ref, lam_sparsity=0) * (1 + 1e-9)


def test_bad_input_raises_rig_input_error():
    A = np.ones((6, 3))
    with pytest.raises(RigInputError):
        WeightSolver(A, mode="simplex")
    with pytest.raises(RigInputError):
        WeightSolver(A, lam_sparsity=-1.0)
    with pytest.raises(RigInputError):
        WeightSolver(A, lower=1.0, upper=0.0)
    with pytest.raises(RigInputError):
        WeightSolver(A).solve(np.ones(5))
    with pytest.raises(RigInputError):
        WeightSolver(np.full((6, 3), np.nan))


def spread_face_vertices(rig, n, moving):
    """n face vertices spread by farthest-point sampling from the lowest chin point (deterministic)."""
    P = rig.neutral[moving]
    idx = [int(np.argmin(P[:, 1]))]
    d = np.linalg.norm(P - P[idx[0]], axis=1)
    for _ in range(n - 1):
        j = int(np.argmax(d))
        idx.append(j)
        d = np.minimum(d, np.linalg.norm(P - P[j], axis=1))
    return moving[idx]


TRUE = {"jawOpen": 0.9, "mouthSmile_L": 0.2, "browInnerUp_R": 0.5, "eyeBlink_L": 0.7,
        "cheekPuff_R": 0.35, "mouthFunnel": 0.6}


@pytest.mark.parametrize("lam_sparsity", [0.0, 1e-6])
def test_recovers_known_ict_pose_from_50_markers(ict_rig, lam_sparsity):
    from model.markers import Marker, MarkerSet

    rig = ict_rig
    mobility = np.abs(rig.deltas[:, :9409]).max(axis=(0, 2))
    moving = np.flatnonzero(mobility > 1e-6)
    verts = spread_face_vertices(rig, 50, moving)
    markers = MarkerSet.for_rig(rig, [Marker(f"M{i:02d}", vertex=int(v)) for i, v in enumerate(verts)])
    w_true = rig.weights_from_dict(TRUE)
    X = evaluate(rig, w_true)
    b = (markers.positions(X) - markers.positions(rig.neutral)).reshape(-1)
    w = WeightSolver(markers.delta_rows(rig.deltas), lam_sparsity=lam_sparsity).solve(b)
    Y = evaluate(rig, w)
    rms = float(np.sqrt(np.mean(np.sum((Y - X)[moving] ** 2, axis=1))))
    print(f"ICT recovery (λ_s={lam_sparsity}): dense RMS {rms * 10:.2e} mm over {moving.size} face vertices")
    assert rms < 0.01  # cm: under 0.1 mm
    assert np.abs(w - w_true).max() < 0.01


def test_the_plain_box_runs_the_compiled_qp_and_finds_the_python_active_sets_minimiser(monkeypatch):
    """Where the compiled take kernel is built, a box with the same bounds for every shape (a marker drag's regions,
    the take solver's global frames) is solved by its QP (``take_kernel.box_qp_fresh``): the minimiser the Python
    active set finds, and lsq_linear's, for bounds other than [0, 1] too; per-shape bounds, a shape held fixed and
    the convex mode keep the Python active set."""
    from solvers import take_kernel, weight_solve
    if not take_kernel.usable_now():
        pytest.skip("the compiled kernel is not built here")
    calls = []
    real = take_kernel.box_qp_fresh
    monkeypatch.setattr(take_kernel, "box_qp_fresh", lambda *a: calls.append(a[3:5]) or real(*a))
    rng = np.random.default_rng(11)
    for trial, (lo, hi) in enumerate([(0.0, 1.0), (-0.5, 2.0), (0.2, 0.6)] * 4):
        A, b = _random_problem(rng, M=int(rng.integers(3, 25)), K=int(rng.integers(5, 60)))
        K = A.shape[1]
        s = WeightSolver(A, lam_sparsity=0.05, lam_reg=0.3, lower=lo, upper=hi)
        w_ref = rng.uniform(lo, hi, K)
        compiled = s.solve(b, w_ref=w_ref, w_start=w_ref)
        assert calls[-1] == (lo, hi) and len(calls) == trial + 1
        with monkeypatch.context() as m:
            m.setattr(weight_solve, "_compiled_box_qp", lambda: None)
            python = s.solve(b, w_ref=w_ref, w_start=w_ref)
        np.testing.assert_allclose(compiled, python, atol=1e-10)
        Aa = np.vstack([A, np.sqrt(0.05) * np.ones((1, K)), np.sqrt(0.3) * np.eye(K)])     # lsq_linear's form
        reference = lsq_linear(Aa, np.concatenate([b, [0.0], np.sqrt(0.3) * w_ref]), bounds=(lo, hi), method="bvls",
                               tol=1e-14).x
        np.testing.assert_allclose(compiled, reference, atol=1e-7)
        at_bounds = np.isclose(compiled, lo) | np.isclose(compiled, hi)
        assert at_bounds.any() and not at_bounds.all()      # the bounds matter, and not only they
    n = len(calls)
    A, b = _random_problem(rng, M=10, K=20)
    for options in (dict(lower=np.r_[0.0, np.zeros(19)], upper=np.r_[0.5, np.ones(19)]),
                    dict(lower=np.r_[0.3, np.zeros(19)], upper=np.r_[0.3, np.ones(19)]), dict(mode="convex")):
        WeightSolver(A, **options).solve(b)
    assert len(calls) == n
