"""Bounded least-squares blendshape weights from points (ALGORITHMS.md §4).

Joshi et al. 2003, Eq. 2 (per-region projection of marker positions onto the shapes) with Ma et al. 2016,
Eq. 3–4 (sparsity term ``λ_s (Σ w)²`` and temporal term ``λ_t ‖w − w_prev‖²``), plus the direct-manipulation
term ``λ_r ‖w − w_ref‖²`` of Joshi §4 (keep a keyframe edit near the current pose):

    min_w  ‖A w − b‖² + λ_s (Σ_k w_k)² + λ_t ‖w − w_prev‖² + λ_r ‖w − w_ref‖²

subject to either

* ``mode="box"`` (default, ARKit/Maya convention):   lower ≤ w ≤ upper            (0 ≤ w ≤ 1)
* ``mode="convex"`` (Joshi §2, neutral in the basis): w ≥ lower, Σ w ≤ sum_max   (w ≥ 0, Σ w ≤ 1)

``A`` is (3M, K): the marker rows of the shape deltas (x, y, z of marker 0, then marker 1, ...), ``b`` is
(3M,): targets minus the neutral at the markers. The objective is the quadratic
``q(w) = ½ wᵀ H w − gᵀ w`` (up to a factor 2 and a constant) with

    H = AᵀA + λ_s 11ᵀ + (λ_t + λ_r + ridge) I,     g = Aᵀb + λ_t w_prev + λ_r w_ref,

which this module minimises with a primal active-set method (Nocedal & Wright, *Numerical Optimization*,
Algorithm 16.3) on the K×K normal equations. Every iterate is feasible, so the answer never leaves the
constraints; a final projection and an assertion make that hold under rounding too. For the plain box (the same
bounds for every shape, no shape held fixed, no sum limit) the compiled take kernel's box QP
(``solvers.take_kernel.box_qp_fresh``: the same method with Cholesky factors updated as the working set changes,
after a few primal-dual steps, Hintermüller, Ito & Kunisch 2002) runs instead where it is built: the same
minimiser (to ~1e-15 on drag-sized problems), ~20x faster (a marker drag's 6 region solves ~3 ms → ~0.2 ms).

Cost. Building a ``WeightSolver`` forms ``AᵀA`` once (O(M K²)). Each ``solve`` is one ``Aᵀb`` (O(M K)) plus
one dense solve of the free-variable system (O(n_free³), n_free ≤ K ≤ ~60, about 10–30 µs) per change of
the active set. Warm-started from the previous frame's weights (``w_start``) with an unchanged active set
it is one system solve and one gradient: typically 30–80 µs per call in CPython. Markers missing from a
frame (NaN in ``b``) are dropped for that call by a rank update of ``AᵀA`` (O(m_missing K²)).

Rank deficiency (shapes the markers cannot see, zero columns of A) is handled by the λ terms and a tiny
ridge (``ridge``, default 1e-10 × (mean diagonal of AᵀA + the λ's)), which keeps H positive definite; the sparsity
term then drives invisible shapes to zero (or, with λ_r, to the reference pose).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dposv as _dposv

from .errors import RigInputError

MODES = ("box", "convex")

__all__ = ["WeightSolver", "solve_weights", "project_feasible", "weight_objective", "qp_tol", "MODES"]


def _as_bounds(value, K: int, name: str) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (K,)).copy()
    if np.isnan(arr).any():
        raise RigInputError(f"The weight solver's {name} bound contains NaN.")
    return arr


def project_feasible(w: np.ndarray, lower: np.ndarray, upper: np.ndarray, sum_max: float | None) -> np.ndarray:
    """Euclidean projection of ``w`` onto ``{lower ≤ w ≤ upper, Σ w ≤ sum_max}`` (no sum limit if None).

    Exact: clips to the box, and if the sum is too large finds the shift τ ≥ 0 with
    ``Σ clip(w − τ, lower, upper) = sum_max`` on the breakpoints of that piecewise-linear function.
    """
    w = np.clip(np.asarray(w, dtype=np.float64), lower, upper)
    if sum_max is None or w.sum() <= sum_max:
        return w
    w0 = np.asarray(w)
    bps = np.concatenate([w0 - upper, w0 - lower])
    bps = np.unique(bps[np.isfinite(bps) & (bps >= 0.0)])
    bps = np.concatenate([[0.0], bps])
    sums = np.clip(w0[None, :] - bps[:, None], lower, upper).sum(axis=1)  # decreasing in τ
    j = int(np.searchsorted(-sums, -sum_max))  # first breakpoint where sum <= sum_max
    if j == 0:
        tau = 0.0
    elif j >= bps.size:
        tau = bps[-1]
    else:
        t0, t1, s0, s1 = bps[j - 1], bps[j], sums[j - 1], sums[j]
        tau = t0 + (s0 - sum_max) * (t1 - t0) / (s0 - s1) if s0 != s1 else t1
    out = np.clip(w0 - tau, lower, upper)
    excess = out.sum() - sum_max
    if excess > 0:  # rounding: take it off the largest component that can give it
        room = out - lower
        i = int(np.argmax(room))
        out[i] -= min(excess, room[i])
    return out


def weight_objective(A, b, w, *, lam_sparsity=0.1, lam_temporal=0.0, lam_reg=0.0, w_prev=None, w_ref=None) -> float:
    """The value of Joshi Eq. 2 + Ma Eq. 3–4 at ``w`` (for tests and reports):
    ``‖A w − b‖² + λ_s (Σ w)² + λ_t ‖w − w_prev‖² + λ_r ‖w − w_ref‖²`` (terms without a vector are skipped)."""
    w = np.asarray(w, dtype=np.float64)
    r = np.asarray(A, dtype=np.float64) @ w - np.asarray(b, dtype=np.float64)
    f = float(r @ r) + lam_sparsity * float(w.sum()) ** 2
    if w_prev is not None and lam_temporal:
        f += lam_temporal * float(np.sum((w - w_prev) ** 2))
    if w_ref is not None and lam_reg:
        f += lam_reg * float(np.sum((w - w_ref) ** 2))
    return f


class WeightSolver:
    """Bounded least-squares weight solve, built once per marker set (Joshi et al. 2003, Eq. 2; Ma et al.
    2016, Eq. 3–4), solved by a warm-startable primal active-set method (Nocedal & Wright Alg. 16.3).

    ``WeightSolver(A, mode="box", lam_sparsity=0.1, lam_temporal=0.0, lam_reg=0.0, lower=0.0, upper=1.0)``
    with A (3M, K), or ``WeightSolver.from_gram(H, ...)`` from a precomputed ``AᵀA`` (K, K) for callers
    that form the normal equations themselves (then use ``solve_gram(g)`` with ``g = Aᵀb``).

    ``lower``/``upper`` may be scalars or (K,) arrays; a shape with ``lower == upper`` is held fixed.
    In convex mode ``upper`` bounds that the sum limit already implies are dropped.
    ``λ_t`` applies only to calls that pass ``w_prev`` and ``λ_r`` only to calls that pass ``w_ref``.
    """

    def __init__(self, A=None, *, gram=None, mode: str = "box", lam_sparsity: float = 0.1,
                 lam_temporal: float = 0.0, lam_reg: float = 0.0, lower=0.0, upper=1.0,
                 sum_max: float = 1.0, ridge: float | None = None, max_iter: int | None = None) -> None:
        if mode not in MODES:
            raise RigInputError(f"Unknown weight solve mode '{mode}': use 'box' or 'convex'.")
        if (A is None) == (gram is None):
            raise RigInputError("The weight solver needs exactly one of A (3M, K) or gram (K, K).")
        for name, lam in (("sparsity", lam_sparsity), ("temporal", lam_temporal), ("reg", lam_reg)):
            if not np.isfinite(lam) or lam < 0:
                raise RigInputError(f"The weight solver's {name} weight must be a finite number ≥ 0, not {lam}.")
        if A is not None:
            A = np.ascontiguousarray(A, dtype=np.float64)
            if A.ndim != 2:
                raise RigInputError(f"The weight solver's A must be a (3M, K) matrix, not shape {A.shape}.")
            if not np.isfinite(A).all():
                raise RigInputError("The weight solver's A contains NaN or infinite values.")
            self.A: np.ndarray | None = A
            self.AtA = A.T @ A
        else:
            gram = np.asarray(gram, dtype=np.float64)
            if gram.ndim != 2 or gram.shape[0] != gram.shape[1] or not np.isfinite(gram).all():
                raise RigInputError("The weight solver's gram matrix must be a finite square (K, K) matrix.")
            self.A = None
            self.AtA = 0.5 * (gram + gram.T)
        K = self.AtA.shape[0]
        self.K = K
        self.mode = mode
        self.lam_sparsity = float(lam_sparsity)
        self.lam_temporal = float(lam_temporal)
        self.lam_reg = float(lam_reg)
        self.lower = _as_bounds(lower, K, "lower")
        self.upper = _as_bounds(upper, K, "upper")
        if (self.lower > self.upper).any():
            raise RigInputError("The weight solver's lower bound exceeds its upper bound for some shape.")
        self.sum_max: float | None = float(sum_max) if mode == "convex" else None
        if self.sum_max is not None:
            if self.lower.sum() > self.sum_max:
                raise RigInputError("The convex weight constraints cannot be met: the lower bounds sum above the limit.")
            # An upper bound the sum limit already implies only makes the active set degenerate.
            implied = self.sum_max - (self.lower.sum() - self.lower)
            self.upper = np.where(self.upper >= implied, np.inf, self.upper)
        if not np.isfinite(self.lower).all():
            raise RigInputError("The weight solver's lower bounds must be finite.")
        mean_diag = float(np.trace(self.AtA)) / max(K, 1)
        size = mean_diag + self.lam_sparsity + self.lam_temporal + self.lam_reg
        self.ridge = float(ridge) if ridge is not None else 1e-10 * (size if size > 0 else 1.0)
        self._H_base = self.AtA + self.lam_sparsity + self.ridge * np.eye(K)  # λ_s 11ᵀ is + λ_s everywhere
        self._scale = max(float(np.abs(self._H_base).max()), 1e-300)
        self._fixed = self.lower == self.upper
        self._has_fixed = bool(self._fixed.any())
        self._finite_hi = bool(np.isfinite(self.upper).any())
        # the compiled box QP takes one lower and one upper bound for every shape (``_compiled_box_qp``)
        self._plain_box = (self.sum_max is None and not self._has_fixed and bool(np.isfinite(self.upper).all())
                           and np.ptp(self.lower) == 0.0 and np.ptp(self.upper) == 0.0) if K else False
        self.max_iter = int(max_iter) if max_iter is not None else 6 * K + 30
        self.last_iterations = 0

    @classmethod
    def from_gram(cls, gram, **options) -> "WeightSolver":
        """A solver from ``AᵀA`` (K, K); solve with ``solve_gram(Aᵀb, ...)``."""
        return cls(gram=gram, **options)

    # ---------------------------------------------------------------------------------------------
    def solve(self, b, *, w_prev=None, w_ref=None, w_start=None) -> np.ndarray:
        """(K,) weights for targets ``b`` (3M,) = marker targets − neutral at the markers.

        NaN entries of ``b`` (missing markers) drop those rows for this call.
        """
        if self.A is None:
            raise RigInputError("This weight solver was built from a gram matrix: call solve_gram(Aᵀb).")
        b = np.asarray(b, dtype=np.float64).reshape(-1)
        if b.shape[0] != self.A.shape[0]:
            raise RigInputError(f"The weight solve got {b.shape[0]} target values for {self.A.shape[0]} marker rows.")
        finite = np.isfinite(b)
        if finite.all():
            return self.solve_gram(self.A.T @ b, w_prev=w_prev, w_ref=w_ref, w_start=w_start)
        Am = self.A[~finite]
        return self.solve_gram(self.A[finite].T @ b[finite], w_prev=w_prev, w_ref=w_ref, w_start=w_start,
                               gram_update=-(Am.T @ Am))

    def solve_gram(self, g, *, w_prev=None, w_ref=None, w_start=None, gram_update=None) -> np.ndarray:
        """(K,) weights from ``g = Aᵀb`` (K,); ``gram_update`` (K, K) is added to AᵀA for this call only."""
        K = self.K
        g = np.array(g, dtype=np.float64).reshape(-1)
        if g.shape[0] != K or not np.isfinite(g).all():
            raise RigInputError(f"The weight solve needs a finite Aᵀb of length {K}.")
        H = self._H_base if gram_update is None else self._H_base + gram_update
        diag = 0.0
        if w_prev is not None and self.lam_temporal:
            g += self.lam_temporal * self._vector(w_prev, "w_prev")
            diag += self.lam_temporal
        if w_ref is not None and self.lam_reg:
            g += self.lam_reg * self._vector(w_ref, "w_ref")
            diag += self.lam_reg
        if diag:
            H = H + diag * np.eye(K)
        if w_start is not None:
            w0 = project_feasible(self._vector(w_start, "w_start"), self.lower, self.upper, self.sum_max)
        else:  # cold start: the projected unconstrained minimiser guesses the active set well
            w0 = project_feasible(np.linalg.solve(H, g), self.lower, self.upper, self.sum_max)
        box_qp = _compiled_box_qp() if self._plain_box else None
        if box_qp is not None:
            w = np.ascontiguousarray(w0, dtype=np.float64).copy()
            self.last_iterations = box_qp(np.ascontiguousarray(H), g, w, float(self.lower[0]), float(self.upper[0]),
                                          qp_tol(H), self.max_iter)
        else:
            w = _active_set(H, g, self.lower, self.upper, self.sum_max, w0, self.max_iter, self._scale, self)
        w = project_feasible(w, self.lower, self.upper, self.sum_max)  # clip-proof under rounding
        assert not ((w < self.lower) | (w > self.upper)).any() and (
            self.sum_max is None or w.sum() <= self.sum_max + 1e-12), "weight solve left the constraints"
        return w

    def is_feasible(self, w, tol: float = 1e-12) -> bool:
        """True if ``w`` satisfies this solver's constraints (to ``tol``)."""
        w = np.asarray(w)
        ok = bool((w >= self.lower - tol).all() and (w <= self.upper + tol).all())
        if self.sum_max is not None:
            ok = ok and float(w.sum()) <= self.sum_max + tol
        return ok

    def _vector(self, v, name: str) -> np.ndarray:
        v = np.asarray(v, dtype=np.float64).reshape(-1)
        if v.shape[0] != self.K or not np.isfinite(v).all():
            raise RigInputError(f"The weight solve's {name} must be {self.K} finite weights.")
        return v


def qp_tol(H: np.ndarray) -> float:
    """The compiled box QP's stopping tolerance on the multipliers for H (here and in ``solvers.take_solve``):
    relative, as H scales with the rig's units²."""
    return 1e-12 * max(float(np.abs(H).max()), 1e-300)


def _compiled_box_qp():
    """``solvers.take_kernel.box_qp_fresh`` where the compiled kernel runs without compiling first, else None (the
    Python active set below: no solve waits for a build)."""
    from . import take_kernel
    return take_kernel.box_qp_fresh if take_kernel.usable_now() else None


def _spd_solve(M: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Solve M X = R for symmetric positive definite M (LAPACK posv); least squares if M is not."""
    _, x, info = _dposv(M, R, lower=1)
    if info == 0:
        return x
    return np.linalg.lstsq(M, R, rcond=None)[0]


def _active_set(H, g, lo, hi, s, w0, max_iter, scale, owner) -> np.ndarray:
    """Primal active-set QP: min ½wᵀHw − gᵀw s.t. lo ≤ w ≤ hi (and Σw ≤ s if s is not None), from the
    feasible ``w0`` (Nocedal & Wright, Algorithm 16.3). H must be symmetric positive definite.

    Working set: each variable is free (0), held at its lower (−1) or upper (+1) bound, or fixed (2, lo == hi);
    plus whether the sum constraint is held as an equality. Every iterate is feasible and the objective
    never increases. At a working-set minimiser all bounds with a negative multiplier are released at
    once (the step is still a descent direction, since the larger subspace contains the single-release
    step); after a zero-length step only the most negative one is released, which restores the textbook
    method's finite termination.
    """
    K = g.shape[0]
    w = w0.copy()  # feasible, with bound values exact (it comes from project_feasible's clip)
    state = np.where(w <= lo, -1, np.where(w >= hi, 1, 0)).astype(np.int8)
    if owner._has_fixed:
        state[owner._fixed] = 2
    has_sum = s is not None
    sum_on = has_sum and w.sum() >= s - 1e-14 * max(1.0, abs(s)) and bool((state == 0).any())
    tol = 1e-12 * (scale * max(1.0, float(np.abs(w0).max(initial=0.0))) + float(np.abs(g).max(initial=0.0)))
    finite_hi = owner._finite_hi
    at_min = False
    single_release = False
    it = 0
    for it in range(max_iter):
        free = state == 0
        F = np.flatnonzero(free)
        nF = F.size
        if not at_min and nF:
            if nF == K:
                Hff, r = H, g
            else:
                HF = H.take(F, 0)
                Hff = HF.take(F, 1)
                r = g.take(F) - HF @ np.where(free, 0.0, w)
            if sum_on:
                R = np.empty((nF, 2))
                R[:, 0] = r
                R[:, 1] = 1.0
                sol = _spd_solve(Hff, R)
                y, z = sol[:, 0], sol[:, 1]
                nu = (y.sum() - (s - (w.sum() - w.take(F).sum()))) / z.sum()
                wf = y - nu * z
            else:
                wf = _spd_solve(Hff, r)
            wcur = w.take(F)
            p = wf - wcur
            alpha, block, kind = 1.0, -1, 0
            # Blocking constraints (N&W Eq. 16.41): the first bound or the sum limit the step reaches.
            with np.errstate(divide="ignore", invalid="ignore"):
                ratios = np.where(p < 0, (lo.take(F) - wcur) / p, np.inf)
                if finite_hi:
                    ratios = np.minimum(ratios, np.where(p > 0, (hi.take(F) - wcur) / p, np.inf))
            j = int(np.argmin(ratios))
            if ratios[j] < 1.0:
                alpha, block, kind = max(float(ratios[j]), 0.0), int(F[j]), (-1 if p[j] < 0 else 1)
            if has_sum and not sum_on:
                ps = float(p.sum())
                if ps > 0:
                    ratio = (s - float(w.sum())) / ps
                    if ratio < alpha:
                        alpha, kind = max(ratio, 0.0), 3
            w[F] = wcur + alpha * p
            if kind:
                if kind == 3:
                    sum_on = True
                else:
                    state[block] = kind
                    w[block] = lo[block] if kind == -1 else hi[block]
                single_release = alpha == 0.0
                continue
            at_min = True
        # At the minimiser of the working set: check the Lagrange multipliers (N&W Eq. 16.42).
        G = H @ w - g
        nu = -float(G.take(F).mean()) if (sum_on and nF) else 0.0
        mult = np.where(state == -1, G + nu, np.where(state == 1, -(G + nu), np.inf))
        j = int(np.argmin(mult))
        worst = float(mult[j])
        if sum_on and nu < min(worst, -tol):
            sum_on = False
        elif worst < -tol:
            if single_release:
                state[j] = 0
            else:
                state[mult < -tol] = 0
        else:
            break
        at_min = False
        single_release = False
    owner.last_iterations = it + 1
    return w


def solve_weights(A, b, *, mode: str = "box", lam_sparsity: float = 0.1, lam_temporal: float = 0.0,
                  lam_reg: float = 0.0, lower=0.0, upper=1.0, sum_max: float = 1.0, w_prev=None, w_ref=None,
                  w_start=None, ridge: float | None = None) -> np.ndarray:
    """One-off bounded least-squares weight solve (Joshi et al. 2003, Eq. 2; Ma et al. 2016, Eq. 3–4):
    builds a ``WeightSolver`` from A (3M, K) and solves for b (3M,). Use the class for repeated solves."""
    solver = WeightSolver(A, mode=mode, lam_sparsity=lam_sparsity, lam_temporal=lam_temporal,
                          lam_reg=lam_reg, lower=lower, upper=upper, sum_max=sum_max, ridge=ridge)
    return solver.solve(b, w_prev=w_prev, w_ref=w_ref, w_start=w_start)
