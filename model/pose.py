"""Pose evaluation: one blended product, vectorised (ALGORITHMS.md §1 and §4).

Global pose:   x = b0 + Σ_k w_k d_k + Σ_c a_c(w) e_c   (muted correctives left out)
Regional pose: x(v) = b0(v) + Σ_r φ_r(v) Σ_k W_rk d_k(v) (+ correctives activated per vertex)

``PoseEvaluator`` is built once per rig (and rebuilt when shapes or correctives change): it keeps the
deltas as one float32 (K, 3U) matrix over the U vertices that any shape moves, so a global pose is a
single matrix-vector product plus a copy of the neutral.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .rig import Rig


class PoseEvaluator:
    """Evaluates poses of one rig. Rebuild it after editing the rig's shapes or correctives."""

    def __init__(self, rig: Rig, dtype=np.float32) -> None:
        self.rig = rig
        self.dtype = dtype
        V = rig.n_vertices
        self._neutral = rig.neutral.astype(dtype).reshape(-1)
        corr = list(rig.correctives)
        self._n_corr = len(corr)
        self._live = np.array([0.0 if c.muted else 1.0 for c in corr])  # muted correctives add nothing
        blocks = [rig.deltas.reshape(rig.n_shapes, -1)]
        if corr:
            blocks.append(np.stack([c.delta for c in corr]).reshape(len(corr), -1))
        full = np.concatenate(blocks, axis=0) if len(blocks) > 1 else blocks[0]
        moving = np.flatnonzero(np.abs(full).reshape(full.shape[0], V, 3).max(axis=(0, 2)) > 0)
        self.moving_vertices = moving
        self._cols = (moving[:, None] * 3 + np.arange(3)).reshape(-1)
        # (K+C, 3U) row-major: w @ D is a fast BLAS gemv.
        self._D = np.ascontiguousarray(full[:, self._cols], dtype=dtype)

    def activations(self, weights: np.ndarray) -> np.ndarray:
        """Corrective activations a_c(w) (Smith §4.5); empty when the rig has none."""
        if not self._n_corr:
            return np.zeros(0)
        from .correctives import corrective_activations
        return corrective_activations(self.rig.correctives, self.rig.shape_names, weights)

    def evaluate(self, weights: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(V, 3) surface for a global weight vector (K,)."""
        w = np.asarray(weights, dtype=np.float64)
        if self._n_corr:
            w = np.concatenate([w, self.activations(w) * self._live])
        if out is None:
            out = self._neutral.copy()
        else:
            out = out.reshape(-1)
            out[:] = self._neutral
        out[self._cols] += w.astype(self.dtype) @ self._D
        return out.reshape(-1, 3)

    def evaluate_regional(self, region_weights: np.ndarray, blend: sp.spmatrix) -> np.ndarray:
        """(V, 3) surface for per-region weights (R, K) blended by a partition of unity ``blend`` (V, R).

        Joshi §4: x(v) = b0(v) + Σ_r φ_r(v) Σ_k W_rk d_k(v). Correctives are activated per vertex
        from the blended weights.
        """
        W = np.asarray(region_weights, dtype=np.float64)
        per_vertex = np.asarray(sp.csr_matrix(blend)[self.moving_vertices] @ W)  # (U, K)
        if self._n_corr:
            from .correctives import corrective_activations_per_vertex
            a = corrective_activations_per_vertex(self.rig.correctives, self.rig.shape_names, per_vertex)
            a *= self._live
            per_vertex = np.concatenate([per_vertex, a], axis=1)
        D = self._D.reshape(self._D.shape[0], -1, 3)  # (K+C, U, 3)
        out = self._neutral.copy().reshape(-1, 3)
        out[self.moving_vertices] += np.einsum("uk,kuc->uc", per_vertex.astype(self.dtype), D)
        return out


def evaluate(rig: Rig, weights: np.ndarray) -> np.ndarray:
    """(V, 3) float64 surface of a global pose; convenience for one-off calls (builds an evaluator)."""
    return PoseEvaluator(rig, dtype=np.float64).evaluate(weights)
