"""Rigid and similarity alignment of point sets (ALGORITHMS.md §7).

Weighted Kabsch / Umeyama: the rotation R, translation t and optional uniform scale s minimising
``Σ_i w_i ‖y_i − (s R x_i + t)‖²`` (Umeyama 1991, "Least-squares estimation of transformation parameters
between two point patterns", Eq. 40–42; used per frame for head motion in Ma et al. 2016, §3.1).
Vectorised over frames: pass (F, N, 3) arrays and (F, N) weights to align F pairs in one batched SVD.
"""
from __future__ import annotations

import numpy as np


def umeyama(source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None, *,
            scale: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted Umeyama 1991 (Eq. 40–42): ``target ≈ s R source + t``.

    source, target: (N, 3) or (F, N, 3); weights: (N,) or (F, N), ≥ 0 (0 drops a point, e.g. a missing
    marker; NaN points are dropped too). Returns (s, R, t) with shapes () / (3, 3) / (3,) or batched
    (F,) / (F, 3, 3) / (F, 3). With ``scale=False`` s is 1 (Kabsch). R is a proper rotation (det +1).
    """
    X = np.asarray(source, dtype=np.float64)
    Y = np.asarray(target, dtype=np.float64)
    single = X.ndim == 2
    if single:
        X, Y = X[None], Y[None]
    F, N, _ = X.shape
    W = np.ones((F, N)) if weights is None else np.broadcast_to(np.asarray(weights, dtype=np.float64), (F, N)).copy()
    bad = ~(np.isfinite(X).all(axis=2) & np.isfinite(Y).all(axis=2))
    W[bad] = 0.0
    X = np.where(bad[..., None], 0.0, X)
    Y = np.where(bad[..., None], 0.0, Y)
    wsum = W.sum(axis=1)
    if (wsum <= 0).any():
        raise ValueError("Rigid alignment needs at least one point with positive weight in every frame.")
    p = W / wsum[:, None]
    mx = np.einsum("fn,fnc->fc", p, X)
    my = np.einsum("fn,fnc->fc", p, Y)
    Xc = X - mx[:, None]
    Yc = Y - my[:, None]
    cov = np.einsum("fn,fni,fnj->fij", p, Yc, Xc)  # Σ_xy (Umeyama Eq. 38)
    U, D, Vt = np.linalg.svd(cov)
    S = np.ones((F, 3))
    S[:, 2] = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    S[S[:, 2] == 0, 2] = 1.0
    R = np.einsum("fij,fj,fjk->fik", U, S, Vt)  # Eq. 40
    if scale:
        var_x = np.einsum("fn,fnc,fnc->f", p, Xc, Xc)  # σ_x² (Eq. 36)
        s = (D * S).sum(axis=1) / var_x  # Eq. 42
    else:
        s = np.ones(F)
    t = my - s[:, None] * np.einsum("fij,fj->fi", R, mx)  # Eq. 41
    if single:
        return s[0], R[0], t[0]
    return s, R, t


def kabsch(source, target, weights=None):
    """Weighted Kabsch: (R, t) with ``target ≈ R source + t`` (Umeyama 1991 without scale)."""
    _, R, t = umeyama(source, target, weights, scale=False)
    return R, t


def to_matrix(s, R, t) -> np.ndarray:
    """4×4 (or (F, 4, 4)) homogeneous matrix of ``x ↦ s R x + t``."""
    R = np.asarray(R)
    single = R.ndim == 2
    Rb = R[None] if single else R
    sb = np.broadcast_to(np.asarray(s, dtype=np.float64), (Rb.shape[0],))
    tb = np.asarray(t).reshape(-1, 3)
    M = np.zeros((Rb.shape[0], 4, 4))
    M[:, :3, :3] = sb[:, None, None] * Rb
    M[:, :3, 3] = tb
    M[:, 3, 3] = 1.0
    return M[0] if single else M
