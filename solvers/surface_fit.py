"""Global per-shape weights that reproduce a regional pose's surface best (ALGORITHMS.md §4, Joshi et al.
2003 Eq. 2 over the whole surface instead of the markers).

A regional pose moves vertex v by  t(v) = Σ_r φ_r(v) Σ_j W_rj d_j(v)  (Joshi §4, partition of unity φ). A DCC
needs one weight per shape, so a keyed animation is exported as the bounded least-squares fit

    min_w ‖Σ_k w_k d_k − t‖²  (over every vertex)   s.t.  lower ≤ w ≤ upper,

solved on the K×K normal equations with this project's active-set QP (``solvers.weight_solve``):
``H = D Dᵀ``, ``g = D t``. The right-hand side needs no surface at all: with the per-region grams
``M_r = D diag(φ_r) Dᵀ`` (K×K each, formed once per blend), ``g = Σ_r M_r W_r``, so fitting F frames costs
F small QPs after one pass over the deltas.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError
from .weight_solve import WeightSolver


def regional_grams(deltas: np.ndarray, blend) -> np.ndarray:
    """(R, K, K) with M_r = Σ_v φ_r(v) d_k(v)·d_j(v): the gram of the deltas weighted by each region's blend.
    Only the shapes that move some vertex of a region enter its product (the others' entries are 0): local shapes,
    as a studio rig's split ones are, make each region's product small."""
    D = np.asarray(deltas)
    K, V = D.shape[0], D.shape[1]
    B = sp.csc_matrix(blend)
    if B.shape[0] != V:
        raise RigInputError(f"The blend covers {B.shape[0]} vertices but the rig has {V}.")
    out = np.zeros((B.shape[1], K, K))
    for r in range(B.shape[1]):
        lo, hi = B.indptr[r], B.indptr[r + 1]
        verts, phi = B.indices[lo:hi], B.data[lo:hi]
        A = D[:, verts].reshape(K, -1)                     # (K, 3n)
        active = np.flatnonzero(np.any(A != 0, axis=1))
        A = A[active].astype(np.float64, copy=False)
        out[r][np.ix_(active, active)] = (A * np.repeat(phi, 3)) @ A.T
    return out


def global_weights_of_regional(deltas: np.ndarray, blend, region_weights: np.ndarray, *, lower=0.0, upper=1.0,
                               grams: np.ndarray | None = None) -> np.ndarray:
    """(F, K) global weights whose surface is closest to each regional pose ``region_weights`` (F, R, K) blended
    by ``blend`` (V, R); a (R, K) pose gives (K,)."""
    W = np.asarray(region_weights, dtype=np.float64)
    single = W.ndim == 2
    W = W[None] if single else W
    D = np.asarray(deltas, dtype=np.float64)
    K = D.shape[0]
    M = regional_grams(D, blend) if grams is None else grams
    if W.shape[1:] != (M.shape[0], K):
        raise RigInputError(f"Regional weights of shape {W.shape[1:]} do not fit {M.shape[0]} regions x {K} shapes.")
    H = M.sum(axis=0)                                      # Σ_r φ_r = 1: the plain gram D Dᵀ
    solver = WeightSolver(gram=H, lam_sparsity=0.0, lower=lower, upper=upper)
    G = np.einsum("frj,rkj->fk", W, M)
    out = np.empty((W.shape[0], K))
    prev = None
    for f in range(W.shape[0]):
        out[f] = prev = solver.solve_gram(G[f], w_start=prev)
    return out[0] if single else out
