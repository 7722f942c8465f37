"""Residual by radial basis functions (ALGORITHMS.md §5; Joshi et al. 2003, Eq. 3; Fidaleo et al., Eq. 1–5).

After a blendshape projection the markers keep a misfit ``r_j = m_j − P_j``. It is interpolated over the
surface and added: ``V(v) = P(v) + Σ_i φ_i(‖x_v − x_i‖) c_i`` with coefficients from ``(Φ + λI) C = R``
(Tikhonov regularisation, Fidaleo λ = 0.01). Centres ``x_i`` are the markers' rest positions plus fixed
"phantom" points with zero residual around the face boundary, which keep far regions still (Fidaleo).

Kernels (``r`` distance, ``σ`` the length scale):
  joshi         exp(−r / σ)                       (Joshi Eq. 3, scaled by a length)
  gaussian      exp(−(r / σ)²)
  multiquadric  sqrt(r² + s_i²), s_i = min_{j≠i} ‖x_j − x_i‖   (Hardy; Eck's stiffness, Fidaleo Eq. 4–5)

Cost: the kernel system is factored once per subset of present markers (cache keyed by the missing-marker
mask); a frame is one back-substitution (M × 3) and, when the dense surface is wanted, one
(V_eval × M) product.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as la
from scipy.spatial import cKDTree

KERNELS = ("none", "joshi", "gaussian", "multiquadric")
# The power of length in each kernel's values, and so in its Tikhonov λ (``Φ + λI``): the exponentials are
# dimensionless, the multiquadric is a length.
KERNEL_LENGTH_POWER = {"joshi": 0, "gaussian": 0, "multiquadric": 1}


def eck_stiffness(centres: np.ndarray) -> np.ndarray:
    """Eck's per-centre stiffness ``s_i = min_{j≠i} ‖x_j − x_i‖`` (Fidaleo Eq. 5)."""
    d, _ = cKDTree(centres).query(centres, k=2)
    return d[:, 1]


def kernel_matrix(points: np.ndarray, centres: np.ndarray, kernel: str, scale: float,
                  stiffness: np.ndarray | None = None) -> np.ndarray:
    """(N, C) matrix ``φ_j(‖points_n − centres_j‖)`` for one of KERNELS (Joshi Eq. 3; Fidaleo Eq. 1–5).

    The squared distances ‖p‖² + ‖c‖² − 2 p·c and the kernel are computed in the one (N, C) array returned: no
    (N, C) temporaries. The evaluation matrix over a face's vertices is the largest array of a solve with a residual
    (ICT, 17k vertices × 108 centres: 15 MB; a 422k-vertex rig: 365 MB); written as ``exp(-d2 / σ²)`` numpy made
    three of its size on the way, which a batch worker's first take paid for in fresh memory."""
    if kernel not in KERNELS[1:]:
        raise ValueError(f"Unknown RBF kernel '{kernel}': use one of {', '.join(KERNELS[1:])}.")
    points = np.asarray(points, dtype=np.float64)
    centres = np.asarray(centres, dtype=np.float64)
    out = points @ centres.T                      # p·c
    out *= -2.0
    out += np.einsum("nc,nc->n", points, points)[:, None]
    out += np.einsum("mc,mc->m", centres, centres)[None, :]
    np.maximum(out, 0.0, out=out)                 # d², rounding below zero clipped
    if kernel == "gaussian":
        out *= -1.0 / (scale * scale)
    elif kernel == "joshi":
        np.sqrt(out, out=out)
        out *= -1.0 / scale
    else:                                         # multiquadric
        s = eck_stiffness(centres) if stiffness is None else np.asarray(stiffness, dtype=np.float64)
        out += (s * s)[None, :]
        return np.sqrt(out, out=out)
    return np.exp(out, out=out)


def phantom_points(surface: np.ndarray, markers: np.ndarray, distance: float, count: int = 48) -> np.ndarray:
    """Indices of ``count`` surface points forming a ring just outside the markers (Fidaleo's phantoms).

    Candidates are the surface points whose nearest marker is between ``distance`` and 1.5 × ``distance``
    away; farthest-point sampling spreads ``count`` of them evenly.
    """
    d, _ = cKDTree(markers).query(surface)
    cand = np.flatnonzero((d >= distance) & (d <= 1.5 * distance))
    if cand.size == 0:
        return cand
    pts = surface[cand]
    chosen = [int(np.argmax(d[cand]))]
    mind = np.linalg.norm(pts - pts[chosen[0]], axis=1)
    for _ in range(min(count, cand.size) - 1):
        j = int(np.argmax(mind))
        chosen.append(j)
        np.minimum(mind, np.linalg.norm(pts - pts[j], axis=1), out=mind)
    return cand[np.array(chosen)]


class RBFResidual:
    """RBF interpolation of marker misfits over a point set (Joshi et al. 2003, Eq. 3; Fidaleo Eq. 1–5).

    centres   (M, 3) marker rest positions (rig units).
    phantoms  (P, 3) fixed points with zero residual (may be empty).
    points    (N, 3) where the residual is evaluated (e.g. the face vertices at rest).
    kernel    'joshi' | 'gaussian' | 'multiquadric'; ``scale`` the length σ; ``lam`` the Tikhonov λ.

    ``coefficients(residual)`` takes (M, 3) misfits with NaN rows for missing markers and returns the
    (M + P, 3) coefficients (zero for missing markers); ``evaluate(C)`` gives the (N, 3) displacement.
    """

    def __init__(self, centres: np.ndarray, phantoms: np.ndarray | None = None, points: np.ndarray | None = None,
                 *, kernel: str = "gaussian", scale: float = 1.0, lam: float = 0.01) -> None:
        if kernel not in KERNELS[1:]:
            raise ValueError(f"Unknown RBF kernel '{kernel}': use one of {', '.join(KERNELS[1:])}.")
        self.kernel, self.scale, self.lam = kernel, float(scale), float(lam)
        centres = np.asarray(centres, dtype=np.float64)
        phantoms = np.zeros((0, 3)) if phantoms is None else np.asarray(phantoms, dtype=np.float64)
        self.n_markers, self.n_phantoms = centres.shape[0], phantoms.shape[0]
        self.centres = np.vstack([centres, phantoms])
        self.stiffness = eck_stiffness(self.centres) if kernel == "multiquadric" else None
        self.Phi = kernel_matrix(self.centres, self.centres, kernel, self.scale, self.stiffness)
        self.points = None if points is None else np.asarray(points, dtype=np.float64)
        self._eval: np.ndarray | None = None
        self._cache: dict[bytes, tuple] = {}
        self.symmetric = kernel != "multiquadric"

    def _factor(self, present: np.ndarray):
        key = np.packbits(present).tobytes()
        hit = self._cache.get(key)
        if hit is None:
            idx = np.concatenate([np.flatnonzero(present), self.n_markers + np.arange(self.n_phantoms)])
            A = self.Phi[np.ix_(idx, idx)] + self.lam * np.eye(idx.size)
            fac = la.cho_factor(A) if self.symmetric else la.lu_factor(A)
            hit = (idx, fac)
            self._cache[key] = hit
        return hit

    def coefficients(self, residual: np.ndarray) -> np.ndarray:
        """(M + P, 3) coefficients C from ``(Φ + λI) C = R`` over the present markers and the phantoms."""
        residual = np.asarray(residual, dtype=np.float64)
        present = np.isfinite(residual).all(axis=1)
        idx, fac = self._factor(present)
        R = np.zeros((idx.size, 3))
        npres = int(present.sum())
        R[:npres] = residual[present]
        sol = la.cho_solve(fac, R) if self.symmetric else la.lu_solve(fac, R)
        C = np.zeros((self.centres.shape[0], 3))
        C[idx] = sol
        return C

    def coefficients_batch(self, residuals: np.ndarray) -> np.ndarray:
        """(F, M + P, 3) coefficients for F frames that share one missing-marker mask (one factorisation,
        one multi-right-hand-side back-substitution)."""
        residuals = np.asarray(residuals, dtype=np.float64)
        F = residuals.shape[0]
        present = np.isfinite(residuals[0]).all(axis=1)
        idx, fac = self._factor(present)
        npres = int(present.sum())
        R = np.zeros((idx.size, F * 3))
        R[:npres] = residuals[:, present].transpose(1, 0, 2).reshape(npres, F * 3)
        sol = la.cho_solve(fac, R) if self.symmetric else la.lu_solve(fac, R)
        C = np.zeros((F, self.centres.shape[0], 3))
        C[:, idx] = sol.reshape(idx.size, F, 3).transpose(1, 0, 2)
        return C

    @property
    def eval_matrix(self) -> np.ndarray:
        """(N, M + P) kernel values at the evaluation points, built on first use."""
        if self._eval is None:
            if self.points is None:
                raise ValueError("This RBF residual has no evaluation points.")
            self._eval = kernel_matrix(self.points, self.centres, self.kernel, self.scale, self.stiffness)
        return self._eval

    def eval_matrix_as(self, dtype) -> np.ndarray:
        """``eval_matrix`` in ``dtype`` (a float32 copy for batched exports, made once)."""
        E = self.eval_matrix
        if E.dtype == np.dtype(dtype):
            return E
        if getattr(self, "_eval_cast", None) is None or self._eval_cast.dtype != np.dtype(dtype):
            self._eval_cast = E.astype(dtype)
        return self._eval_cast

    def evaluate(self, C: np.ndarray) -> np.ndarray:
        """(N, 3) interpolated residual at the evaluation points (Joshi Eq. 3: Σ_i φ_i(‖x_v − x_i‖) c_i)."""
        return self.eval_matrix @ C

    def at(self, points: np.ndarray, C: np.ndarray) -> np.ndarray:
        """(n, 3) interpolated residual at arbitrary points."""
        return kernel_matrix(np.asarray(points, dtype=np.float64), self.centres, self.kernel, self.scale,
                             self.stiffness) @ C
