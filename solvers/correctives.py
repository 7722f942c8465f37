"""Corrective-shape numerics on plain arrays (ALGORITHMS.md §6; Smith 2006 §4.5, §5.6–5.8).

- ``corrective_delta``: Smith's authoring step, e_c = (x_des − x_cur) / a_c(w).
- ``fit_scan_weights`` / ``driver_region`` / ``corrective_from_scan``: a corrective from a scan of a
  combination (Smith §6, future work 1): fit the rig's weights to the scan by bounded least squares, keep
  the residual over the drivers' region.
- ``linearised_correctives``: the correctives' marker displacement and its Jacobian, for solvers that fit the
  rig with its correctives (take solves, marker drags).
- ``shape_overlap`` / ``shape_overshoot`` / ``rank_interference`` / ``interference_heat``: which shape
  pairs interfere and need a corrective, ranked by the overlap of their displacement fields or by how much
  their sum overshoots where both act.
"""
from __future__ import annotations

import numpy as np

from .errors import RigInputError


def _points(a, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise RigInputError(f"The {what} must be a (V, 3) array of points, got shape {a.shape}.")
    if not np.isfinite(a).all():
        raise RigInputError(f"The {what} has NaN or infinite coordinates.")
    return a


def corrective_delta(x_des, x_cur, activation: float) -> np.ndarray:
    """Smith 2006 §5.6 (ALGORITHMS.md §6): e_c = (x_des − x_cur) / a_c(w).

    x_des: (V, 3) desired (sculpted or scanned) surface; x_cur: (V, 3) current surface with the drivers
    set and every lower-order corrective applied; activation: a_c(w) at that pose (must not be ~0).
    """
    x_des = _points(x_des, "desired surface")
    x_cur = _points(x_cur, "current surface")
    if x_des.shape != x_cur.shape:
        raise RigInputError(f"The desired surface has {x_des.shape[0]} vertices but the rig has {x_cur.shape[0]}.")
    a = float(activation)
    if not np.isfinite(a) or abs(a) < 1e-6:
        raise RigInputError(f"The corrective's activation at the authoring pose is {a:g}; set its drivers "
                            "to non-zero weights (normally 1) before authoring.")
    return (x_des - x_cur) / a


def fit_scan_weights(neutral, deltas, scan, free=None, lower: float = 0.0, upper: float = 1.0,
                     ridge: float = 1e-10) -> np.ndarray:
    """Bounded least-squares weights of a scan (Joshi et al. 2003, Eq. 2, over all vertices).

    min_w ‖Σ_k w_k d_k − (scan − b0)‖²  s.t. lower ≤ w_k ≤ upper, for k in ``free`` (default all shapes;
    the others are 0). Solved on the K×K normal equations: with G = D Dᵀ = L Lᵀ (Cholesky) the problem is
    min ‖Lᵀ w − L⁻¹ D r‖², a small dense bounded least squares (scipy lsq_linear, BVLS).
    neutral (V, 3), deltas (K, V, 3), scan (V, 3) -> (K,) weights.
    """
    b0 = _points(neutral, "neutral")
    scan = _points(scan, "scan")
    D = np.asarray(deltas, dtype=np.float64)
    if scan.shape[0] != b0.shape[0]:
        raise RigInputError(f"The scan has {scan.shape[0]} vertices but the rig has {b0.shape[0]}; a scan must "
                            "be in the rig's vertex order.")
    K = D.shape[0]
    free = np.arange(K) if free is None else np.asarray(free, dtype=np.intp)
    w = np.zeros(K)
    if free.size == 0:
        return w
    A = D[free].reshape(free.size, -1)  # (F, 3V)
    r = (scan - b0).reshape(-1)
    G = A @ A.T
    G[np.diag_indices_from(G)] += ridge * max(np.trace(G) / free.size, 1e-30)
    b = A @ r
    L = np.linalg.cholesky(G)
    rhs = np.linalg.solve(L, b)
    from scipy.optimize import lsq_linear     # imported here: scipy.optimize costs 0.3 s to import
    res = lsq_linear(L.T, rhs, bounds=(lower, upper), method="bvls")
    w[free] = res.x
    return w


def smoothstep(t: np.ndarray) -> np.ndarray:
    """3t² − 2t³ on t clipped to [0, 1]."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def driver_region(driver_deltas, moving_fraction: float = 0.01, full_fraction: float = 0.1) -> np.ndarray:
    """(V,) region weight in [0, 1] of the vertices the drivers move, with a smooth falloff.

    m(v) = max over drivers of ‖d_k(v)‖; ρ(v) = smoothstep((m(v) − lo) / (hi − lo)) with
    lo = moving_fraction · max m and hi = full_fraction · max m: 0 where no driver moves (m ≤ lo), 1 where
    a driver moves at least ``full_fraction`` of the largest driver displacement, a smooth ramp between.
    driver_deltas: (n, V, 3).
    """
    D = np.asarray(driver_deltas, dtype=np.float64)
    m = np.linalg.norm(D, axis=2).max(axis=0)
    top = m.max() if m.size else 0.0
    if top <= 0:
        return np.zeros(m.shape)
    lo, hi = moving_fraction * top, full_fraction * top
    return smoothstep((m - lo) / max(hi - lo, 1e-300))


def corrective_from_scan(scan, x_fit, region, activation: float) -> np.ndarray:
    """Smith 2006, future work 1 (ALGORITHMS.md §6): the residual of a fitted scan as a corrective.

    e_c(v) = ρ(v) · (scan(v) − x_fit(v)) / a_c(w_fit), with x_fit the rig at the fitted weights (lower-order
    correctives applied), ρ the drivers' region (``driver_region``), so the residual is zero elsewhere.
    """
    scan = _points(scan, "scan")
    x_fit = _points(x_fit, "fitted surface")
    if scan.shape != x_fit.shape:
        raise RigInputError(f"The scan has {scan.shape[0]} vertices but the rig has {x_fit.shape[0]}.")
    rho = np.asarray(region, dtype=np.float64).reshape(-1, 1)
    return corrective_delta(x_fit + rho * (scan - x_fit), x_fit, activation)


# --- fitting a rig with correctives --------------------------------------------------------------
JACOBIAN_STEP = 1e-6   # forward-difference step of the activation rules' gradient


def linearised_correctives(activate, Em, drivers, W) -> tuple[np.ndarray, np.ndarray]:
    """The correctives' displacement of the markers and its derivative at weights W (R, K) (Smith 2006 §4.5:
    C(w) = Σ_c a_c(w) e_c is nonlinear in w; a solver linearises it, C(w) ≈ C(W) + J (w − W)).

    ``activate`` maps weights (U, K) to activations (U, C), ``Em`` (C, 3M) holds each corrective's marker
    displacement and ``drivers`` (n,) the shapes the activations depend on. Returns C (R, 3M) and J (R, 3M, n),
    J = Σ_c e_c ∂a_c/∂w_d by forward differences (one activation call for every row and driver).
    """
    W = np.atleast_2d(np.asarray(W, dtype=np.float64))
    d = np.asarray(drivers, dtype=np.intp)
    R, n = W.shape[0], d.size
    probe = np.repeat(W[:, None, :], 1 + n, axis=1)                          # (R, 1+n, K)
    probe[:, np.arange(1, n + 1), d] += JACOBIAN_STEP
    a = np.asarray(activate(probe.reshape(R * (1 + n), -1))).reshape(R, 1 + n, -1)   # (R, 1+n, C)
    grad = (a[:, 1:] - a[:, :1]) / JACOBIAN_STEP                              # (R, n, C)
    return a[:, 0] @ Em, np.einsum("rnc,cm->rmn", grad, Em)


# --- interference finder ------------------------------------------------------------------------
def _area_weights(areas, n_vertices: int) -> np.ndarray | None:
    """Per-vertex surface weights for the finder's measures, or None (every vertex counts alike)."""
    if areas is None:
        return None
    a = np.asarray(areas, dtype=np.float64).ravel()
    if a.shape[0] != n_vertices or not np.isfinite(a).all() or (a < 0).any():
        raise RigInputError(f"The vertex areas must be {n_vertices} finite values of zero or more.")
    return a


def shape_overlap(deltas, directional: bool = False, areas=None) -> np.ndarray:
    """(K, K) overlap of displacement fields (ALGORITHMS.md §6; Smith §4.5 on shapes in superposition).

    O_ij = Σ_v min(‖d_i(v)‖, ‖d_j(v)‖) / min(Σ_v ‖d_i(v)‖, Σ_v ‖d_j(v)‖), in [0, 1]; the diagonal is 1
    (0 for a shape that does not move). Vectorised via min(a, b) = (a + b − |a − b|) / 2, so
    Σ_v min = (S_i + S_j − ‖n_i − n_j‖₁) / 2 with the L1 distances from one ``pdist`` call, over the
    vertices that two or more shapes move.

    ``areas`` ((V,), ``solvers.laplacian.vertex_areas``) weights every vertex term by its surface area A(v),
    so the sums become surface integrals, ∫ min(‖d_i‖, ‖d_j‖) dA / min(∫ ‖d_i‖ dA, ∫ ‖d_j‖ dA), and a region
    modelled with denser vertices (eyelids, lips) does not count for more than its area.

    ``directional=True`` (our extension) counts only displacements that point the same way, the case in
    which superposition overshoots: each vertex term is weighted by max(0, cos θ_ij(v)), i.e.
    min(‖d_i‖, ‖d_j‖)·max(0, cos θ) = max(0, d_i·d_j) / max(‖d_i‖, ‖d_j‖). Antagonists (jawLeft/jawRight,
    eyeLookIn/eyeLookOut) then drop out of the ranking.
    """
    D = np.asarray(deltas, dtype=np.float64)
    A = _area_weights(areas, D.shape[1])
    n = np.sqrt(np.einsum("kvc,kvc->kv", D, D))  # (K, V)
    keep = (n > 0).sum(axis=0) >= 2  # vertices moved by fewer than two shapes add nothing to any min
    if A is not None:
        n = n * A[None, :]          # A·min(a, b) = min(A·a, A·b): the weights go into the magnitudes
    S = n.sum(axis=1)
    n = n[:, keep]
    if directional:
        # Per vertex the K×K dot products, in float32 chunks of vertices (batched matmul).
        Dv = np.ascontiguousarray(D[:, keep].transpose(1, 0, 2), dtype=np.float32)  # (U, K, 3)
        if A is not None:   # (A d_i)·(A d_j) / (A max(‖d_i‖, ‖d_j‖)) = A·(d_i·d_j / max(‖d_i‖, ‖d_j‖))
            Dv *= A[keep].astype(np.float32)[:, None, None]
        nv = np.ascontiguousarray(n.T, dtype=np.float32)  # (U, K)
        inter = np.zeros((D.shape[0], D.shape[0]))
        for s in range(0, Dv.shape[0], 1024):
            d, nn = Dv[s:s + 1024], nv[s:s + 1024]
            dots = d @ d.transpose(0, 2, 1)
            np.maximum(dots, 0.0, out=dots)
            big = np.maximum(nn[:, :, None], nn[:, None, :])
            big[big == 0] = 1.0
            dots /= big
            inter += dots.sum(axis=0, dtype=np.float64)
    else:
        from scipy.spatial.distance import pdist, squareform
        l1 = squareform(pdist(n, "cityblock"))
        Sk = n.sum(axis=1)
        inter = 0.5 * (Sk[:, None] + Sk[None, :] - l1)
    np.fill_diagonal(inter, S)
    den = np.minimum(S[:, None], S[None, :])
    O = np.where(den > 0, inter / np.where(den > 0, den, 1.0), 0.0)
    return np.clip(O, 0.0, 1.0)


OVERSHOOT_PRIOR = 10.0   # shrinkage of shape_overshoot, in vertices: a shared area of a few vertices scores ~0


def shape_overshoot(deltas, prior: float = OVERSHOOT_PRIOR, areas=None) -> np.ndarray:
    """(K, K) overshoot of superposition where two shapes both act, in (-1, 1) (Smith §4.5: where shapes
    overlap, their sum bunches or overshoots; the formulation is ours).

    Per vertex, the sum's excess over the larger displacement relative to it:
    e_ij(v) = (‖d_i(v) + d_j(v)‖ − m(v)) / m(v), m(v) = max(‖d_i(v)‖, ‖d_j(v)‖): 1 where the sum doubles the
    motion (equal and parallel), 0 where it adds nothing to the larger one, −1 where the two cancel
    (antagonists such as jawLeft/jawRight). Averaged where both shapes act, with each vertex weighted by how
    strongly both do, w(v) = min(‖d_i(v)‖ / max‖d_i‖, ‖d_j(v)‖ / max‖d_j‖), and shrunk toward 0 for small
    shared areas: O_ij = Σ_v w e / (Σ_v w + prior). A small shape inside a large one (a lip shape inside
    jawOpen) scores low, since superposing them adds little to the large motion. The diagonal is 1.

    ``areas`` ((V,), ``solvers.laplacian.vertex_areas``) multiplies w(v) by the vertex's surface area relative
    to the median area of the vertices the rig moves, so the average is over the surface rather than over
    vertices (a densely modelled eyelid does not outweigh the forehead) and ``prior`` stays "about that many
    typical vertices". One pass per shape over the vertices it moves, all partners at once.
    """
    D = np.asarray(deltas, dtype=np.float32)  # float32 terms, float64 sums: ~1e-6 relative, twice as fast
    K = D.shape[0]
    n = np.sqrt(np.einsum("kvc,kvc->kv", D, D))  # (K, V)
    peak = n.max(axis=1)
    rel = n / np.where(peak > 0, peak, 1.0)[:, None]  # (K, V) in [0, 1]
    floor = 1e-3                                       # below a thousandth of its peak a shape does not act
    A = _area_weights(areas, D.shape[1])
    if A is not None:
        moved = A[(rel > floor).any(axis=0)]
        typical = float(np.median(moved[moved > 0])) if (moved > 0).any() else 1.0
        A = (A / typical).astype(np.float32)
    O = np.zeros((K, K))
    for a in range(K - 1):
        cols = np.flatnonzero(rel[a] > floor)
        if cols.size == 0:
            continue
        Da, na = D[a, cols], n[a, cols]                               # this shape where it acts: (C, 3), (C,)
        Db, nb = D[a + 1:, cols], n[a + 1:, cols]                     # its partners there: (P, C, 3), (P, C)
        w = np.minimum(rel[a, cols][None, :], rel[a + 1:, cols])      # (P, C)
        w[w <= floor] = 0.0
        if A is not None:
            w *= A[cols][None, :]
        m = np.maximum(na[None, :], nb)
        Db += Da[None]                                                # d_i + d_j, in place (Db is a copy)
        e = np.sqrt(np.einsum("pcx,pcx->pc", Db, Db))
        e -= m
        e /= np.where(m > 0, m, 1.0)
        O[a, a + 1:] = np.einsum("pc,pc->p", w, e, dtype=np.float64) / (w.sum(axis=1, dtype=np.float64) + prior)
    O = O + O.T
    np.fill_diagonal(O, np.where(peak > 0, 1.0, 0.0))
    return O


def rank_partners(overlap, shape: int, top: int = 5) -> list[tuple[int, float]]:
    """The ``top`` shapes overlapping most with ``shape`` (from ``shape_overlap``): [(j, overlap), ...]."""
    row = np.asarray(overlap, dtype=np.float64)[shape].copy()
    row[shape] = -np.inf
    order = np.lexsort((np.arange(row.size), -row))[:top]
    return [(int(j), float(row[j])) for j in order if np.isfinite(row[j])]


def rank_interference(deltas, top: int = 10, overlap=None, directional: bool = False,
                      areas=None) -> list[tuple[int, int, float]]:
    """The ``top`` shape pairs (i < j) with the largest ``shape_overlap``: [(i, j, overlap), ...], best first.

    Pass a precomputed ``overlap`` (K, K) to skip the computation (``deltas`` may then be None).
    """
    O = shape_overlap(deltas, directional, areas) if overlap is None else np.asarray(overlap)
    i, j = np.triu_indices(O.shape[0], k=1)
    s = O[i, j]
    order = np.lexsort((j, i, -s))[:top]
    return [(int(i[o]), int(j[o]), float(s[o])) for o in order]


def merge_mirrored_pairs(ranked, mirror, left=None) -> list[tuple[int, int, float, tuple[int, int, float] | None]]:
    """Fold each pair into one row with its mirror image: (i, j, s, (i', j', s') or None), best first.

    ``ranked`` is [(i, j, score), ...] best first (``rank_interference``); ``mirror`` gives each shape's mirror
    shape (``model.sides.mirror_indices``). The mirror of (i, j) is (mirror[i], mirror[j]); a pair that is its
    own mirror (browInnerUp_L × browInnerUp_R, mouthFunnel × mouthPucker) keeps a row of its own. A row ranks
    by the better of its two scores. With ``left`` ((K,) bool, ``model.sides.is_left``) the side with more
    left-side shapes is the row's pair, as riggers author the left side and mirror it; otherwise, and on a
    tie, the better scoring side is.
    """
    m = np.asarray(mirror, dtype=np.int64)
    lefts = None if left is None else np.asarray(left, dtype=bool)
    score = {(int(i), int(j)): float(s) for i, j, s in ranked}
    rows, folded = [], set()
    for i, j, s in ranked:
        key = (int(i), int(j))
        if key in folded:
            continue
        mi, mj = sorted((int(m[i]), int(m[j])))
        other = (mi, mj)
        if other == key or mi == mj or other not in score:
            rows.append((key[0], key[1], float(s), None))
            continue
        folded.add(other)
        first, second = key, other
        if lefts is not None and int(lefts[list(other)].sum()) > int(lefts[list(key)].sum()):
            first, second = other, key
        rows.append((first[0], first[1], score[first], (second[0], second[1], score[second])))
    return rows


def interference_heat(delta_i, delta_j) -> np.ndarray:
    """(V,) per-vertex interference heat map min(‖d_i(v)‖, ‖d_j(v)‖) of one pair (ALGORITHMS.md §6)."""
    a = np.linalg.norm(np.asarray(delta_i, dtype=np.float64), axis=-1)
    b = np.linalg.norm(np.asarray(delta_j, dtype=np.float64), axis=-1)
    return np.minimum(a, b)


def overshoot_heat(delta_i, delta_j) -> np.ndarray:
    """(V,) how far the pair's sum goes beyond the larger of the two displacements, in rig units:
    max(0, ‖d_i(v) + d_j(v)‖ − max(‖d_i(v)‖, ‖d_j(v)‖)) -- where superposition overshoots (``shape_overshoot``)."""
    di, dj = np.asarray(delta_i, dtype=np.float64), np.asarray(delta_j, dtype=np.float64)
    m = np.maximum(np.linalg.norm(di, axis=-1), np.linalg.norm(dj, axis=-1))
    return np.maximum(np.linalg.norm(di + dj, axis=-1) - m, 0.0)
