"""From the weights a user sets to the blend coefficients the pose is made of: the Shapes list's per-shape
settings (mute, solo, slider ranges, in-betweens) applied in one place for every evaluation
(``model.pose.PoseEvaluator``) and export (``model.export``).

1. Effective weights: each weight clamped to its shape's range (if it has one), then 0 for a muted shape and,
   while any shape is soloed, for every shape that is not. Correctives are activated by the effective weights
   (a muted shape's correctives go quiet with it).
2. Coefficients (Maya's in-betweens): a shape with in-betweens at weights t_1 < ... < t_m has knots
   (0, 0), (t_i, D_i), (1, d_k) (in weight order; in-betweens may lie below 0 or above 1), and its offset at weight
   w is the piecewise linear interpolation through them, extended linearly beyond the first and last knot with
   the end segments. That is ``Σ_j h_j(w) D_j`` with hat functions h_j, so a pose stays one linear product over
   the blocks [shapes (K), in-betweens (N), correctives (C)]: the coefficient of shape k's own row is h at its
   knot 1 (w itself without in-betweens) and each in-between row gets its hat.
A regional pose takes the coefficients of each region's weights, then blends them (each region poses its own
face; the partition of unity blends the results), so in-betweens stay exact inside a region.
"""
from __future__ import annotations

import numpy as np

from .rig import Rig


def live_mask(rig: Rig) -> np.ndarray:
    """(K,) 1.0 for the shapes that take part, 0.0 for the muted ones and, while any shape is soloed, the unsoloed
    ones. Solves multiply the shapes' columns by it: a muted shape explains no marker, so its weight goes to 0."""
    index = {n: i for i, n in enumerate(rig.shape_names)}
    live = np.ones(rig.n_shapes)
    if rig.solo:
        live[:] = 0.0
        live[[index[n] for n in rig.solo]] = 1.0
    live[[index[n] for n in rig.muted]] = 0.0
    return live


class ShapeWeights:
    """The per-shape settings of one rig as arrays: ``effective(W)`` and ``coefficients(W)`` for weight rows
    (..., K). ``trivial`` when nothing changes the weights (no range, mute, solo or in-between)."""

    def __init__(self, rig: Rig) -> None:
        K = rig.n_shapes
        self.K = K
        index = {n: i for i, n in enumerate(rig.shape_names)}
        self.lo = np.full(K, -np.inf)
        self.hi = np.full(K, np.inf)
        for name, (lo, hi) in rig.ranges.items():
            self.lo[index[name]], self.hi[index[name]] = lo, hi
        self.clamped = bool(rig.ranges)
        self.live = live_mask(rig)
        self.masked = bool(rig.solo or rig.muted)
        # per shape with in-betweens: (k, knots (m+2,) sorted with 0 and 1, row of each knot (-1: the zero knot))
        self.curves = []
        rows = []
        for name in rig.shape_names:
            items = rig.inbetweens.get(name)
            if not items:
                continue
            k = index[name]
            knots = [(0.0, -1), (1.0, k)]
            for ib in items:
                knots.append((ib.weight, K + len(rows)))
                rows.append(ib.delta)
            knots.sort()
            self.curves.append((k, np.array([t for t, _ in knots]), np.array([r for _, r in knots])))
        self.inbetween_deltas = np.stack(rows) if rows else np.zeros((0,) + rig.neutral.shape)
        self.N = len(rows)
        self.inbetween_names = [f"{rig.shape_names[k]}@{t:g}" for k, knots, r in self.curves
                                for t, row in zip(knots, r) if row >= K]
        self.trivial = not (self.clamped or self.masked or self.N)

    def effective(self, W: np.ndarray) -> np.ndarray:
        """The weights the pose is made of: clamped to the ranges, 0 where muted or not soloed."""
        W = np.asarray(W, dtype=np.float64)
        if self.clamped:
            W = np.clip(W, self.lo, self.hi)
        if self.masked:
            W = W * self.live
        return W

    def coefficients(self, W_effective: np.ndarray) -> np.ndarray:
        """(..., K + N) coefficients of the shape rows then the in-between rows for effective weights (..., K)."""
        W = np.asarray(W_effective, dtype=np.float64)
        if not self.N:
            return W
        out = np.zeros(W.shape[:-1] + (self.K + self.N,))
        out[..., :self.K] = W
        for k, knots, rows in self.curves:
            w = W[..., k]
            j = np.clip(np.searchsorted(knots, w, side="right") - 1, 0, knots.size - 2)
            t0, t1 = knots[j], knots[j + 1]
            alpha = (w - t0) / (t1 - t0)
            out[..., k] = 0.0
            for q, row in enumerate(rows):
                if row >= 0:   # the zero knot has no row
                    out[..., row] += np.where(j == q, 1.0 - alpha, 0.0) + np.where(j + 1 == q, alpha, 0.0)
        return out

    def row_weights(self, W: np.ndarray, correctives, shape_names, live: np.ndarray | None = None) -> np.ndarray:
        """(..., K+N+C) the weight of every delta row -- shapes, in-betweens, correctives -- for weight rows (..., K):
        the shapes' and in-betweens' coefficients of the effective weights, then the correctives' activations at the
        effective weights times ``live`` (C,) (1 applied, 0 left out; default: the unmuted ones)."""
        We = self.effective(W)
        rows = self.coefficients(We)
        if not correctives:
            return rows
        from .correctives import corrective_activations, corrective_activations_per_vertex
        if live is None:
            live = np.array([0.0 if c.muted else 1.0 for c in correctives])
        if We.ndim == 1:
            a = corrective_activations(correctives, shape_names, We)
        else:
            a = corrective_activations_per_vertex(correctives, shape_names, We)
        return np.concatenate([rows, a * live], axis=-1)


def shape_offset(rig: Rig, name: str, weight: float) -> np.ndarray:
    """(V, 3) the offset shape ``name`` alone gives at ``weight`` (ranges, mute and solo aside): its piecewise
    linear curve through the in-betweens; for tests and the in-between readout."""
    sw = ShapeWeights(rig)   # coefficients() applies the in-betweens only (effective() does the rest)
    w = np.zeros(rig.n_shapes)
    k = rig.shape_index(name)
    w[k] = weight
    c = sw.coefficients(w)
    out = c[k] * rig.deltas[k]
    for i, d in enumerate(sw.inbetween_deltas):
        out = out + c[sw.K + i] * d
    return out
