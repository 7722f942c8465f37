"""The compiled inner loop of a take solve (``solvers.take_solve.TakeSolver._pass``): one causal sweep over the
frames, per frame ``iterations`` alternations of weighted Kabsch (Umeyama 1991, Eq. 40–41) and the box QP of
Joshi et al. 2003, Eq. 2 with Ma et al. 2016, Eq. 3–4's terms, warm-started from the previous frame.

The QP is the same primal active-set method as ``take_solve._CachedBoxQP`` (Nocedal & Wright, Algorithm 16.3,
the same step and pivot rules: a blocked step stops at the first bound on the way, lowest index on ties; else
the most violated multiplier frees its variable), with the Cholesky factor of the free block updated by one
row per change of the working set (append a row for a freed variable, delete a row and restore the triangle
by Givens rotations for a bound one: O(n_free²) a change, Golub & Van Loan §6.5.4 / §12.5) instead of a cache
of inverses. Each QP first runs a few iterations of the primal-dual active set method (Hintermüller, Ito &
Kunisch 2002), which changes every wrongly placed variable per solve instead of one; the primal method finishes
when they do not settle. Compiled by numba (``cache=True``: compiled once per machine, then loaded from ``__pycache__``);
where numba is missing, ``available()`` is False and the solver keeps its Python loop.

This module is the kernel's source: ``solvers.take_kernel`` compiles it ahead of time into an extension module
(numba.pycc) and loads that, so that a fresh process does not pay for importing and initialising numba.
"""
from __future__ import annotations

import math

import numpy as np

try:
    import numba
    from numba import njit
except ImportError:     # pragma: no cover - numba is a dependency; the Python loop stays as the fallback
    numba = None


def available() -> bool:
    return numba is not None


# Floating-point reassociation for the kernels' dot products (so that they vectorise), without numba's no-NaN and
# no-infinity assumptions of fastmath=True: solve_pass tests the markers for NaN (missing ones).
_REASSOC = {"reassoc", "contract", "nsz", "arcp"}


if numba is not None:
    @njit(cache=True, nogil=True, fastmath=True)
    def _cho_solve(L, rhs, out, n):
        """Solve L Lᵀ out = rhs[:n] with the lower triangle L[:n, :n] (forward, then back substitution); ``out``
        may be ``rhs`` itself. Both read L by rows, as it is stored: the forward pass as dot products, the back
        substitution (Lᵀ's columns) as row updates, so neither strides down a column."""
        for i in range(n):
            v = rhs[i]
            for k in range(i):
                v -= L[i, k] * out[k]
            out[i] = v / L[i, i]
        for i in range(n - 1, -1, -1):
            v = out[i] / L[i, i]
            out[i] = v
            for k in range(i):
                out[k] -= L[i, k] * v

    @njit(cache=True, nogil=True)
    def _bound_ratio(xi, cur, lo, hi, none):
        """How far along the step from ``cur`` to ``xi`` the variable meets a bound (``none`` if it stays inside)."""
        if xi < lo:
            return (lo - cur) / (xi - cur)
        if xi > hi:
            return (hi - cur) / (xi - cur)
        return none

    @njit(cache=True, nogil=True, fastmath=_REASSOC)
    def _chol_append(L, order, nf, H, j):
        """Append variable j to the factor of H over ``order[:nf]``: returns False when the block would not be
        positive definite (the caller refactors)."""
        for i in range(nf):
            s = H[order[i], j]
            for k in range(i):
                s -= L[i, k] * L[nf, k]
            L[nf, i] = s / L[i, i]
        d = H[j, j]
        for k in range(nf):
            d -= L[nf, k] * L[nf, k]
        if d <= 0.0:
            return False
        L[nf, nf] = math.sqrt(d)
        for k in range(nf + 1, L.shape[1]):
            L[nf, k] = 0.0
        order[nf] = j
        return True

    @njit(cache=True, nogil=True, fastmath=_REASSOC)
    def _chol_delete(L, order, nf, p):
        """Delete position p from the factor over ``order[:nf]`` (rows shift up, Givens rotations on columns
        k, k+1 restore the lower triangle)."""
        for i in range(p, nf - 1):
            order[i] = order[i + 1]
            for k in range(i + 2):
                L[i, k] = L[i + 1, k]
        for k in range(p, nf - 1):
            a, b = L[k, k], L[k, k + 1]
            r = math.hypot(a, b)
            if r == 0.0:
                continue
            c, s = a / r, b / r
            for i in range(k, nf - 1):
                x, y = L[i, k], L[i, k + 1]
                L[i, k] = c * x + s * y
                L[i, k + 1] = -s * x + c * y
            if L[k, k] < 0.0:
                for i in range(k, nf - 1):
                    L[i, k] = -L[i, k]
        for i in range(nf - 1):
            L[i, nf - 1] = 0.0

    @njit(cache=True, nogil=True)
    def _chol_build(L, order, H, s):
        """Factor the free block (s == 0) from scratch; returns the number of free variables."""
        nf = 0
        for j in range(H.shape[0]):
            if s[j] == 0.0:
                if _chol_append(L, order, nf, H, j):
                    nf += 1
        return nf

    @njit(cache=True, nogil=True, fastmath=_REASSOC)
    def box_qp(H, g, w, lo, hi, tol, max_iter, L, order, pos, x, r, nf_in, pd_max=8):
        """Minimise ½wᵀHw − gᵀw over lo ≤ w ≤ hi from ``w`` (changed in place; clipped into the box first).
        L (K, K), order/pos (K,) int, x/r (K,): work space. ``nf_in`` ≥ 0: L already holds the factor of the
        same H over ``order[:nf_in]`` (the last call's free set), updated here to this start's free set by
        row deletions and appends, so a warm start with a nearly unchanged free set costs O(n_free²), not
        O(n_free³); -1 builds it. Returns (iterations, the final free-set size for the next call)."""
        K = H.shape[0]
        s = np.empty(K)
        for k in range(K):
            v = min(max(w[k], lo), hi)
            w[k] = v
            s[k] = 1.0 if v >= hi else (-1.0 if v <= lo else 0.0)
        if nf_in < 0:
            nf = _chol_build(L, order, H, s)
        else:
            nf = nf_in
            i = 0
            while i < nf:
                if s[order[i]] != 0.0:
                    _chol_delete(L, order, nf, i)
                    nf -= 1
                else:
                    i += 1
            for k in range(K):
                pos[k] = 0
            for i in range(nf):
                pos[order[i]] = 1
            for k in range(K):
                if s[k] == 0.0 and pos[k] == 0:
                    if _chol_append(L, order, nf, H, k):
                        nf += 1
                    else:
                        nf = _chol_build(L, order, H, s)
                        break
        held = np.empty(K, dtype=np.int64)
        nz = np.empty(K, dtype=np.int64)
        it_pd, nf = _primal_dual_dense(H, g, w, s, lo, hi, tol, L, order, pos, x, r, nf, held, nz, pd_max)
        if it_pd < 0:                            # converged: w is the minimiser
            for k in range(K):
                w[k] = min(max(w[k], lo), hi)
            return -it_pd, nf
        for it in range(max_iter):
            if nf:
                nh = 0                       # bound variables away from 0 (at the upper bound) pull on the free
                for j in range(K):
                    if s[j] != 0.0 and w[j] != 0.0:
                        held[nh] = j
                        nh += 1
                for i in range(nf):          # the free variables' right-hand side, bound ones held
                    a = order[i]
                    v = g[a]
                    for q in range(nh):
                        v -= H[a, held[q]] * w[held[q]]
                    r[i] = v
                _cho_solve(L, r, x, nf)      # L Lᵀ x = r
                blocked = False
                for i in range(nf):
                    pos[order[i]] = i
                    if x[i] < lo or x[i] > hi:
                        blocked = True
                if blocked:
                    best, jb = np.inf, -1
                    for a in range(K):           # ascending variable order, first minimum (as np.argmin)
                        if s[a] != 0.0:
                            continue
                        i = pos[a]
                        ratio = _bound_ratio(x[i], w[a], lo, hi, np.inf)
                        if ratio < best:
                            best, jb = ratio, a
                    step = max(best, 0.0)
                    for i in range(nf):
                        a = order[i]
                        w[a] = w[a] + step * (x[i] - w[a])
                    if x[pos[jb]] < lo:
                        w[jb], s[jb] = lo, -1.0
                    else:
                        w[jb], s[jb] = hi, 1.0
                    _chol_delete(L, order, nf, pos[jb])
                    nf -= 1
                    continue
                for i in range(nf):
                    w[order[i]] = x[i]
            nnz = 0
            for k in range(K):
                if w[k] != 0.0:
                    nz[nnz] = k
                    nnz += 1
            jmax, vmax = -1, -np.inf
            for j in range(K):                   # the multipliers' violation (0 for free variables)
                if s[j] == 0.0:
                    viol = 0.0
                else:
                    v = -g[j]
                    for q in range(nnz):
                        v += H[j, nz[q]] * w[nz[q]]
                    viol = v * s[j]
                if viol > vmax:
                    vmax, jmax = viol, j
            if vmax <= tol:
                break
            s[jmax] = 0.0
            if not _chol_append(L, order, nf, H, jmax):
                nf = _chol_build(L, order, H, s)
            else:
                nf += 1
        for k in range(K):
            w[k] = min(max(w[k], lo), hi)
        return it_pd + it + 1, nf

    @njit(cache=True, nogil=True)
    def box_qp_fresh(H, g, w, lo, hi, tol, max_iter):
        """``box_qp`` of a one-off H (a Gauss–Newton step's, ``TakeSolver._weights`` with correctives), from ``w``
        (changed in place) with its own work space; returns the iterations."""
        K = H.shape[0]
        n_it, _ = box_qp(H, g, w, lo, hi, tol, max_iter, np.zeros((K, K)), np.zeros(K, dtype=np.int64),
                         np.zeros(K, dtype=np.int64), np.zeros(K), np.zeros(K), -1)
        return n_it

    @njit(cache=True, nogil=True, fastmath=_REASSOC)
    def _primal_dual_dense(H, g, w, s, lo, hi, tol, L, order, pos, x, r, nf, held, nz, n_max):
        """``box_qp_lowrank``'s primal-dual active set phase (Hintermüller, Ito & Kunisch 2002) on the dense
        factor of ``box_qp``: per iteration one solve of the free block, then every variable that leaves the box
        is held at its bound (its row deleted from the factor) and every held one whose multiplier has the wrong
        sign is freed (appended). Returns (-(iterations), nf) when the working set did not change, else
        (iterations, nf) with w feasible and the factor over the free set for the primal method. Stops at once
        when the factor does not hold every free variable (a block that is not positive definite)."""
        K = H.shape[0]
        drop = np.empty(K, dtype=np.int64)
        for it in range(n_max):
            n_free = 0
            for k in range(K):
                if s[k] == 0.0:
                    n_free += 1
            if n_free != nf:
                return it, nf
            nh = 0
            for j in range(K):
                if s[j] != 0.0 and w[j] != 0.0:
                    held[nh] = j
                    nh += 1
            for i in range(nf):
                a = order[i]
                v = g[a]
                for q in range(nh):
                    v -= H[a, held[q]] * w[held[q]]
                r[i] = v
            _cho_solve(L, r, x, nf)
            nnz = 0
            for q in range(nh):
                nz[nnz] = held[q]
                nnz += 1
            n_drop = 0
            for i in range(nf):          # the candidate: x on the free variables, the bounds on the others
                a = order[i]
                pos[a] = i
                if x[i] != 0.0:
                    nz[nnz] = a
                    nnz += 1
                if x[i] < lo or x[i] > hi:
                    drop[n_drop] = i
                    n_drop += 1
            n_add = 0
            for j in range(K):           # held variables whose multiplier has the wrong sign (``held`` reused)
                if s[j] != 0.0:
                    v = -g[j]
                    for q in range(nnz):
                        b = nz[q]
                        v += H[j, b] * (x[pos[b]] if s[b] == 0.0 else w[b])
                    if v * s[j] > tol:
                        held[n_add] = j
                        n_add += 1
            for i in range(nf):
                a = order[i]
                w[a] = min(max(x[i], lo), hi)
                if x[i] < lo:
                    s[a] = -1.0
                elif x[i] > hi:
                    s[a] = 1.0
            if n_drop == 0 and n_add == 0:
                return -(it + 1), nf
            for q in range(n_drop - 1, -1, -1):      # the last position first: the earlier ones stay put
                _chol_delete(L, order, nf, drop[q])
                nf -= 1
            for q in range(n_add):
                j = held[q]
                s[j] = 0.0
                if _chol_append(L, order, nf, H, j):
                    nf += 1
                else:
                    nf = _chol_build(L, order, H, s)
                    break
        return n_max, nf

    @njit(cache=True, nogil=True)
    def _kabsch(P, Y, p, weighted, Rout, tout):
        """Weighted Kabsch / Umeyama 1991 (Eq. 40–41): Y ≈ R P + t over the rows of P, Y (n, 3)."""
        n = P.shape[0]
        mp = np.zeros(3)
        my = np.zeros(3)
        for i in range(n):
            wi = p[i] if weighted else 1.0 / n
            for c in range(3):
                mp[c] += wi * P[i, c]
                my[c] += wi * Y[i, c]
        C = np.zeros((3, 3))
        for i in range(n):
            wi = p[i] if weighted else 1.0
            for a in range(3):
                ya = Y[i, a] - my[a]
                for b in range(3):
                    C[a, b] += ya * (P[i, b] - mp[b]) * wi
        U, _, Vt = np.linalg.svd(C)
        if np.linalg.det(U) * np.linalg.det(Vt) < 0.0:
            for a in range(3):
                U[a, 2] = -U[a, 2]
        R = U @ Vt
        for a in range(3):
            tout[a] = my[a]
            for b in range(3):
                Rout[a, b] = R[a, b]
                tout[a] -= R[a, b] * mp[b]


# --- the low-rank form, for rigs with more shapes than marker coordinates ------------------------------------
# H = BᵀB + μI with B = [A; √λ_s 1ᵀ] (m × K, m = 3M + 1): the free block's system H_ff x = r is solved by the
# Woodbury identity, x = (r − B_fᵀ G⁻¹ B_f r) / μ with G = μI + B_f B_fᵀ (m × m), whose Cholesky factor follows
# the working set by rank-one updates and downdates (Golub & Van Loan §6.5.4). A step costs O(m·n_free + m²):
# linear in the number of shapes, where the dense factor costs O(n_free²).

_BIG = 1e300      # "no ratio yet" / "no violation yet" in the fastmath kernel (which assumes no infinities)

if numba is not None:
    @njit(cache=True, nogil=True)
    def _chol_rank1(L, x, sign):
        """L Lᵀ ± x xᵀ in place (x is overwritten); returns False when a downdate loses definiteness."""
        n = L.shape[0]
        for k in range(n):
            d = L[k, k] * L[k, k] + sign * x[k] * x[k]
            if d <= 0.0:
                return False
            r = math.sqrt(d)
            c = r / L[k, k]
            s = x[k] / L[k, k]
            L[k, k] = r
            for i in range(k + 1, n):
                L[i, k] = (L[i, k] + sign * s * x[i]) / c
                x[i] = c * x[i] - s * L[i, k]
        return True

    @njit(cache=True, nogil=True)
    def _gram_build(Lg, Bt, s, mu):
        """Cholesky factor of G = μI + Σ_{free j} b_j b_jᵀ."""
        K, m = Bt.shape
        for a in range(m):
            for b in range(m):
                Lg[a, b] = 0.0
        for j in range(K):
            if s[j] == 0.0:
                for a in range(m):
                    bja = Bt[j, a]
                    if bja != 0.0:
                        for b in range(a + 1):
                            Lg[a, b] += bja * Bt[j, b]
        for a in range(m):
            Lg[a, a] += mu
        for j in range(m):                 # in-place Cholesky (lower triangle)
            d = Lg[j, j]
            for k in range(j):
                d -= Lg[j, k] * Lg[j, k]
            d = math.sqrt(d)
            Lg[j, j] = d
            for i in range(j + 1, m):
                v = Lg[i, j]
                for k in range(j):
                    v -= Lg[i, k] * Lg[j, k]
                Lg[i, j] = v / d
            for k in range(j + 1, m):
                Lg[j, k] = 0.0

    @njit(cache=True, nogil=True, fastmath=True)
    def _lowrank_free_solve(Bt, mu, g, w, s, Lg, x, r, v, t):
        """The free variables' values x_f with the held ones fixed, for H = BᵀB + μI (Woodbury, with Lg the Cholesky
        factor of G = μI + B_f B_fᵀ): v = B_b w_b (the held variables' pull), r = g_f − (BᵀB w_b)_f (μI has no
        off-diagonal pull), t = G⁻¹ B_f r (= y), x_f = (r − B_fᵀ y) / μ. Returns the number of free variables
        (nothing but v is written when there are none)."""
        K, m = Bt.shape
        nfree = 0
        nheld = 0
        for a in range(m):
            v[a] = 0.0
        for j in range(K):
            if s[j] == 0.0:
                nfree += 1
            elif w[j] != 0.0:
                nheld += 1
                for a in range(m):
                    v[a] += Bt[j, a] * w[j]
        if nfree:
            for a in range(m):
                t[a] = 0.0
            for j in range(K):
                if s[j] == 0.0:
                    q = g[j]
                    if nheld:
                        for a in range(m):
                            q -= Bt[j, a] * v[a]
                    r[j] = q
                    for a in range(m):
                        t[a] += Bt[j, a] * q
            _cho_solve(Lg, t, t, m)          # G Gᵀ y = t, in place
            for j in range(K):
                if s[j] == 0.0:
                    q = r[j]
                    for a in range(m):
                        q -= Bt[j, a] * t[a]
                    x[j] = q / mu
        return nfree

    @njit(cache=True, nogil=True, fastmath=True)
    def box_qp_lowrank(Bt, mu, g, w, lo, hi, tol, max_iter, Lg, s, fresh, work, pd_max=8):
        """The box QP of ``box_qp`` for H = BᵀB + μI given as Bt = Bᵀ (K, m): the same phases, steps and pivot rules.
        ``s`` holds the last call's working set and Lg its Gram factor unless ``fresh``; both are updated to this
        start and kept for the next call. Returns the number of iterations. Compiled with fastmath (the
        dot products vectorise; inputs are finite, so sentinels are finite too)."""
        K, m = Bt.shape
        x = work[0]
        r = work[1]
        v = np.zeros(m)
        t = np.zeros(m)
        tmp = np.zeros(m)
        s_new = np.empty(K)
        for k in range(K):
            val = min(max(w[k], lo), hi)
            w[k] = val
            s_new[k] = 1.0 if val >= hi else (-1.0 if val <= lo else 0.0)
        if fresh:
            _gram_build(Lg, Bt, s_new, mu)
        else:
            ok = True
            for k in range(K):
                if (s_new[k] == 0.0) != (s[k] == 0.0):
                    for a in range(m):
                        tmp[a] = Bt[k, a]
                    if not _chol_rank1(Lg, tmp, 1.0 if s_new[k] == 0.0 else -1.0):
                        ok = False
                        break
            if not ok:
                _gram_build(Lg, Bt, s_new, mu)
        for k in range(K):
            s[k] = s_new[k]
        it_pd = _primal_dual_phase(Bt, mu, g, w, lo, hi, tol, Lg, s, x, r, v, t, tmp, pd_max)
        if it_pd < 0:                            # converged: w is the minimiser
            for k in range(K):
                w[k] = min(max(w[k], lo), hi)
            return -it_pd
        for it in range(max_iter):
            nfree = _lowrank_free_solve(Bt, mu, g, w, s, Lg, x, r, v, t)
            have_u = False
            if nfree:
                blocked = False
                for j in range(K):
                    if s[j] == 0.0 and (x[j] < lo or x[j] > hi):
                        blocked = True
                        break
                if blocked:
                    best, jb = _BIG, -1
                    for j in range(K):
                        if s[j] != 0.0:
                            continue
                        ratio = _bound_ratio(x[j], w[j], lo, hi, _BIG)
                        if ratio < best:
                            best, jb = ratio, j
                    step = max(best, 0.0)
                    for j in range(K):
                        if s[j] == 0.0:
                            w[j] = w[j] + step * (x[j] - w[j])
                    if x[jb] < lo:
                        w[jb], s[jb] = lo, -1.0
                    else:
                        w[jb], s[jb] = hi, 1.0
                    for a in range(m):
                        tmp[a] = Bt[jb, a]
                    if not _chol_rank1(Lg, tmp, -1.0):
                        _gram_build(Lg, Bt, s, mu)
                    continue
                for j in range(K):
                    if s[j] == 0.0:
                        w[j] = x[j]
                for a in range(m):               # B_f x = (t − (G − μI) y) / μ = y: so B w = y + v, no pass
                    v[a] += t[a]
                have_u = True
            if not have_u:
                for a in range(m):               # u = B w
                    v[a] = 0.0
                for j in range(K):
                    if w[j] != 0.0:
                        for a in range(m):
                            v[a] += Bt[j, a] * w[j]
            jmax, vmax = -1, -_BIG
            for j in range(K):                   # the multipliers' violation (0 for free variables)
                if s[j] == 0.0:
                    viol = 0.0
                else:
                    q = mu * w[j] - g[j]
                    for a in range(m):
                        q += Bt[j, a] * v[a]
                    viol = q * s[j]
                if viol > vmax:
                    vmax, jmax = viol, j
            if vmax <= tol:
                break
            s[jmax] = 0.0
            for a in range(m):
                tmp[a] = Bt[jmax, a]
            _chol_rank1(Lg, tmp, 1.0)
        for k in range(K):
            w[k] = min(max(w[k], lo), hi)
        return it_pd + it + 1

    @njit(cache=True, nogil=True, fastmath=True)
    def _primal_dual_phase(Bt, mu, g, w, lo, hi, tol, Lg, s, x, r, v, t, tmp, n_max):
        """Up to ``n_max`` iterations of the primal-dual active set method (Hintermüller, Ito & Kunisch 2002,
        Alg. 1; a semismooth Newton method for box constraints) on the QP of ``box_qp_lowrank``: solve the free
        variables with the bound ones held, then change every variable whose value leaves the box or whose
        multiplier has the wrong sign at once (the primal method changes one a solve). With a warm start (the
        previous frame's or alternation's working set) it typically stops after one or two solves.
        Returns -(iterations) when the working set did not change (w, s: the minimiser and its working set, to
        ``tol``), else the iterations run, with w feasible and s, Lg consistent for the primal method to go on."""
        K, m = Bt.shape
        for it in range(n_max):
            if _lowrank_free_solve(Bt, mu, g, w, s, Lg, x, r, v, t):
                for a in range(m):               # u = B w at the candidate: B_f x_f = y (see box_qp_lowrank)
                    v[a] += t[a]
            changes = 0
            rebuild = False
            for j in range(K):
                if s[j] == 0.0:
                    xj = x[j]
                    if xj < lo or xj > hi:       # leaves the box: held at the bound it crossed
                        w[j], s[j] = (lo, -1.0) if xj < lo else (hi, 1.0)
                        changes += 1
                        if not rebuild:
                            for a in range(m):
                                tmp[a] = Bt[j, a]
                            rebuild = not _chol_rank1(Lg, tmp, -1.0)
                    else:
                        w[j] = xj
                else:
                    q = mu * w[j] - g[j]         # its multiplier at the candidate
                    for a in range(m):
                        q += Bt[j, a] * v[a]
                    if q * s[j] > tol:           # the wrong sign: freed (its value comes from the next solve)
                        s[j] = 0.0
                        changes += 1
                        if not rebuild:
                            for a in range(m):
                                tmp[a] = Bt[j, a]
                            _chol_rank1(Lg, tmp, 1.0)
            if rebuild:
                _gram_build(Lg, Bt, s, mu)
            if changes == 0:
                return -(it + 1)
        return n_max

    @njit(cache=True, nogil=True, fastmath=_REASSOC)
    def solve_pass(Y, order, w, R, t, rest, Dm, At, Hs, Bts, mu, tols, mask_of, lam_t, iterations, rw, rw0, lo,
                   hi, max_iter, W, Rs, ts, solved, first_solved_before):
        """One causal sweep over ``order`` (see the module docstring). Y (F, M, 3) calibrated markers (NaN
        missing), Dm (K, 3M) the shapes at the markers, At = Dm (Aᵀ), Hs (n_masks, K, K) the QP's H per
        missing-marker mask and ``mask_of`` (F,) each frame's mask (-1: fewer than 3 markers, the pose is held).
        With Bts (n_masks, K, m) non-empty the QP runs in the low-rank form (``box_qp_lowrank``, H = BᵀB + μI per
        mask) and Hs is not read.
        Writes W (F, K), Rs (F, 3, 3), ts (F, 3), solved (F,); returns the number of active-set iterations. ``first_solved_before``: a frame of this sweep was
        solved before ``order`` (a chunk after the first); until one is, the temporal term pulls towards the
        current weights (``_pass``'s w_prev None)."""
        K = Dm.shape[0]
        M = rest.shape[0]
        L = np.zeros((K, K))
        od = np.zeros(K, dtype=np.int64)
        pos = np.zeros(K, dtype=np.int64)
        x = np.zeros(K)
        rr = np.zeros(K)
        wp = np.empty(K)
        disp = np.zeros(3 * M)
        b = np.zeros(3 * M)
        g = np.zeros(K)
        P = np.zeros((M, 3))
        Q = np.zeros((M, 3))
        pw = np.zeros(M)
        valid = np.zeros(M, dtype=np.bool_)
        have_prev = first_solved_before
        iters = 0
        nf = -1
        last_mask = -1
        lowrank = Bts.shape[2] > 0
        s_state = np.zeros(K)
        Lg = np.zeros((Bts.shape[2], Bts.shape[2]))
        work = np.zeros((2, K))
        for f in order:
            m = mask_of[f]
            if m >= 0:
                nv = 0
                for i in range(M):
                    ok = True
                    for c in range(3):
                        if not np.isfinite(Y[f, i, c]):
                            ok = False
                    valid[i] = ok
                    if ok:
                        nv += 1
                for k in range(K):
                    wp[k] = w[k]
                for _ in range(iterations):
                    if not have_prev:      # the sweep's first solved frame: the temporal term pulls to w itself
                        for k in range(K):
                            wp[k] = w[k]
                    for q in range(3 * M):
                        disp[q] = 0.0
                    for k in range(K):
                        if w[k] != 0.0:
                            for q in range(3 * M):
                                disp[q] += w[k] * Dm[k, q]
                    n = 0
                    tot = 0.0
                    for i in range(M):
                        if valid[i]:
                            d2 = 0.0
                            for c in range(3):
                                P[n, c] = rest[i, c] + disp[3 * i + c]
                                Q[n, c] = Y[f, i, c]
                                d2 += disp[3 * i + c] * disp[3 * i + c]
                            pw[n] = 1.0 / (rw0 + rw * d2) if rw != 0.0 else 1.0
                            tot += pw[n]
                            n += 1
                    for i in range(n):
                        pw[i] /= tot
                    _kabsch(P[:n], Q[:n], pw[:n], rw != 0.0, R, t)
                    for i in range(M):     # z = Rᵀ (y − t), b = z − rest over the present markers
                        for c in range(3):
                            if valid[i]:
                                v = 0.0
                                for a in range(3):
                                    v += (Y[f, i, a] - t[a]) * R[a, c]
                                b[3 * i + c] = v - rest[i, c]
                            else:
                                b[3 * i + c] = 0.0
                    for k in range(K):
                        v = lam_t * wp[k]
                        for q in range(3 * M):
                            v += At[k, q] * b[q]
                        g[k] = v
                    if m != last_mask:
                        nf = -1                # another H: the factor is built afresh
                        last_mask = m
                    if lowrank:
                        iters += box_qp_lowrank(Bts[m], mu, g, w, lo, hi, tols[m], max_iter, Lg, s_state, nf < 0,
                                                work)
                        nf = 0
                    else:
                        n_it, nf = box_qp(Hs[m], g, w, lo, hi, tols[m], max_iter, L, od, pos, x, rr, nf)
                        iters += n_it
                solved[f] = True
                have_prev = True
            for k in range(K):
                W[f, k] = w[k]
            for a in range(3):
                ts[f, a] = t[a]
                for c in range(3):
                    Rs[f, a, c] = R[a, c]
        return iters
