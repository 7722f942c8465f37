"""Retargeting an actor who is not the rig (ALGORITHMS.md §12): the actor's neutral from a take, a smooth
warp from the rig's marker points to the actor's, and the warp's local linear map that carries the markers'
motion into the rig's frame.

* ``neutral_stretch`` finds the most neutral stretch of a take when it has no neutral lead-in: the frames
  where the markers are stillest and the face least open (ALGORITHMS.md §12 (a)).
* ``SmoothWarp`` is a Gaussian RBF plus affine warp fitted with Tikhonov regularisation (Fidaleo et al.,
  Eq. 1–5; Joshi et al. 2003, Eq. 3), with its Jacobian: fitted from the rig's marker points to the actor's
  neutral markers (after the Umeyama similarity), it gives per marker the local linear map J_φ that takes a
  rig displacement to the actor's (§12 (b)–(c)).
* ``refit_points`` re-fits each marker's rig point from the take's motion: among the rig points near where the
  registration put it, the one whose motion under the solved weights best explains the marker's motion, against a
  prior that keeps it near the registration (§12 (b), a calibration step of production facial solvers).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as la


def _gauss(x: np.ndarray, c: np.ndarray, scale: float) -> np.ndarray:
    d2 = (x * x).sum(1)[:, None] + (c * c).sum(1)[None, :] - 2.0 * x @ c.T
    return np.exp(-np.maximum(d2, 0.0) / (scale * scale))


class SmoothWarp:
    """x ↦ x + xᵀL + t + Σ_i φ(‖x − c_i‖) a_i with a Gaussian φ of length ``scale`` (Fidaleo Eq. 1–5, Joshi Eq. 3),
    fitted so that ``source`` maps near ``target``: the affine part (L, t) by least squares with a ridge
    ``affine_ridge`` toward the identity, the RBF part on what the affine leaves, with Tikhonov ``lam``
    (relative to the kernel's diagonal). A large ``scale`` and ``lam`` keep the warp smooth: the identity
    difference of two faces is low-frequency, marker noise is not."""

    def __init__(self, source: np.ndarray, target: np.ndarray, *, scale: float = 3.0, lam: float = 0.1,
                 affine_ridge: float = 1e-2) -> None:
        src = np.asarray(source, dtype=np.float64)
        dst = np.asarray(target, dtype=np.float64)
        ok = np.isfinite(src).all(1) & np.isfinite(dst).all(1)
        src, dst = src[ok], dst[ok]
        if src.shape[0] < 4:
            raise ValueError("A warp needs at least 4 points seen in the neutral.")
        self.centres, self.scale = src, float(scale)
        self.origin = src.mean(0)
        P = np.hstack([src - self.origin, np.ones((src.shape[0], 1))])       # (N, 4)
        delta = dst - src
        # affine part: min ‖P [L; t] − δ‖² + ridge·N‖L‖² (toward the identity map)
        reg = np.diag([1.0, 1.0, 1.0, 0.0]) * affine_ridge * src.shape[0] * max(float(np.mean((src - self.origin) ** 2)), 1e-12)
        self.affine = np.linalg.solve(P.T @ P + reg, P.T @ delta)             # (4, 3)
        rest = delta - P @ self.affine
        Phi = _gauss(src, src, self.scale)
        self.coef = la.solve(Phi + lam * np.eye(src.shape[0]), rest, assume_a="pos")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        return x + (x - self.origin) @ self.affine[:3] + self.affine[3] + _gauss(x, self.centres, self.scale) @ self.coef

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """(N, 3, 3) ∂φ/∂x at the points: J[n, a, b] = ∂φ_a/∂x_b."""
        x = np.asarray(x, dtype=np.float64)
        G = _gauss(x, self.centres, self.scale)                               # (N, C)
        diff = x[:, None, :] - self.centres[None, :, :]                      # (N, C, 3)
        dG = (-2.0 / self.scale ** 2) * G[:, :, None] * diff                 # (N, C, 3): ∂φ_i/∂x_b
        J = np.einsum("nib,ia->nab", dG, self.coef)
        return J + np.eye(3)[None] + self.affine[:3].T[None]


def neutral_stretch(positions: np.ndarray, rest: np.ndarray, length: int) -> tuple[int, int, dict]:
    """(first, last, why) of the most neutral ``length`` frames of a take (ALGORITHMS.md §12 (a)), for a take with
    no neutral lead-in. ``positions`` (F, M, 3) in rig units (NaN where missing), ``rest`` (M, 3) the rig's
    marker points at rest. A frame is scored by how far its markers are from the rig's neutral after the best
    similarity (Umeyama 1991, scale included): an actor's identity is there in every frame, an expression is
    added on top, so the least open, most neutral frames are nearest. Stillness (the frame-to-frame change of
    the distances between markers, which head motion leaves alone) breaks ties between equally neutral
    stretches. ``why``: the chosen stretch's mean distance and stillness, each relative to the take's median."""
    from .rigid import umeyama
    X = np.asarray(positions, dtype=np.float64)
    F, M, _ = X.shape
    length = int(max(1, min(length, F)))
    seen = np.isfinite(X).all(axis=2)
    usable = seen.sum(axis=1) >= 3
    far = np.full(F, np.inf)
    if usable.any():
        Xu = X[usable]
        s, R, t = umeyama(Xu, np.broadcast_to(rest, Xu.shape), seen[usable].astype(np.float64), scale=True)
        Y = np.einsum("f,fij,fmj->fmi", s, R, np.nan_to_num(Xu)) + t[:, None]
        err = np.where(seen[usable], np.einsum("fmc,fmc->fm", Y - rest, Y - rest), 0.0)
        far[usable] = np.sqrt(err.sum(axis=1) / seen[usable].sum(axis=1))
    speed = np.zeros(F)
    if F > 1:
        i, j = np.triu_indices(M, 1)
        d = np.linalg.norm(X[:, i] - X[:, j], axis=2)
        with np.errstate(invalid="ignore"):
            step = np.nanmean(np.abs(np.diff(d, axis=0)), axis=1)
        step = np.nan_to_num(step, nan=np.nanmax(step) if np.isfinite(step).any() else 0.0)
        speed[1:] = step
        speed[0] = step[0]
    finite = np.isfinite(far)
    med_far = float(np.median(far[finite])) if finite.any() else 1.0
    med_speed = max(float(np.median(speed)), 1e-12)
    score = np.where(finite, far / max(med_far, 1e-12), 1e6) + 0.25 * speed / med_speed
    win = np.convolve(score, np.ones(length) / length, mode="valid")          # (F − length + 1,)
    a = int(np.argmin(win))
    why = {"distance_to_rig_neutral": float(np.mean(far[a:a + length]) / max(med_far, 1e-12)),
           "stillness": float(np.mean(speed[a:a + length]) / med_speed)}
    return a, a + length - 1, why


def refit_points(motion: np.ndarray, weights: np.ndarray, deltas: np.ndarray, candidates: list[np.ndarray],
                 prior: list[np.ndarray], lam: float) -> np.ndarray:
    """The rig point (a vertex) each marker sits on, re-fitted from its motion over a take (ALGORITHMS.md §12 (b)).

    ``motion`` (F, M, 3) the markers' head-stabilised motion from the actor's neutral carried into the rig's frame
    (NaN where missing), ``weights`` (F, K) the weights solved with the current points, ``deltas`` (K, V, 3) the
    rig's shapes, ``candidates[j]`` the vertices marker j may sit on and ``prior[j]`` their squared distance from
    where the registration put it, in units of that placement's uncertainty (‖p − p₀‖² / σ_j²). Marker j takes the
    candidate v minimising ``r_j(v) / min_u r_j(u) + lam · prior[j][v]`` with r_j(v) = Σ_t ‖m_jt − Σ_k w_tk d_kv‖²:
    the residual relative to the best candidate's, so ``lam`` reads as "a move of one σ must explain ``lam`` of the
    marker's residual". Geometry alone cannot say where along the surface a marker of another face sits (the
    registration's tangential error); the shapes' motion can, once the weights are roughly right, so this
    alternates with the solve. Returns (M,) vertex indices."""
    X = np.asarray(motion, dtype=np.float64)
    W = np.asarray(weights, dtype=np.float64)
    chosen = np.empty(X.shape[1], dtype=np.int64)
    for j, (cand, pr) in enumerate(zip(candidates, prior)):
        cand = np.asarray(cand, dtype=np.int64)
        ok = np.isfinite(X[:, j]).all(axis=1)
        if cand.size == 1 or not ok.any():
            chosen[j] = cand[np.argmin(pr)]
            continue
        pred = np.einsum("fk,kvc->vfc", W[ok], deltas[:, cand])              # (C, F, 3) each candidate's motion
        r = np.einsum("vfc,vfc->v", pred - X[ok, j][None], pred - X[ok, j][None])
        cost = r / max(float(r.min()), 1e-300) + lam * np.asarray(pr, dtype=np.float64)
        chosen[j] = cand[np.argmin(cost)]
    return chosen
