"""Keyframes and the timeline that interpolates them (ALGORITHMS.md §8: keys store poses; a timeline
interpolates them).

A key stores a pose: a global weight vector (K,) or per-region weights (R+1, K) (all keys of a timeline have
the same shape). ``Timeline.evaluate(t)`` interpolates:

* ``"linear"`` — straight lines between neighbouring keys;
* ``"smooth"`` — a cubic Hermite spline through the keys with Catmull–Rom tangents for uneven spacing,
  ``m_i = (p_{i+1} − p_{i−1}) / (t_{i+1} − t_{i−1})`` (one-sided differences at the first and last key),
  so motion is C¹ through every key.

Catmull–Rom can overshoot between keys, so every result is brought back into the weight constraints:
clipped to ``[lower, upper]`` in box mode, projected onto ``{w ≥ 0, Σ w ≤ 1}`` (per region) in convex mode.
Before the first key the first key holds, after the last the last.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import RigInputError

INTERPOLATIONS = ("linear", "smooth")


@dataclass
class Keyframe:
    """A pose at a time (seconds): weights (K,) or (R+1, K)."""

    time: float
    weights: np.ndarray

    def __post_init__(self) -> None:
        self.time = float(self.time)
        if not np.isfinite(self.time):
            raise RigInputError("A keyframe needs a finite time.")
        self.weights = np.array(self.weights, dtype=np.float64)
        if self.weights.ndim not in (1, 2) or not np.isfinite(self.weights).all():
            raise RigInputError("A keyframe's weights must be a finite (K,) or (R+1, K) array.")

    def to_dict(self) -> dict:
        return {"time": self.time, "weights": self.weights.tolist()}

    @staticmethod
    def from_dict(d: dict) -> "Keyframe":
        if not isinstance(d, dict) or "time" not in d or "weights" not in d:
            raise RigInputError("A keyframe entry needs a time and weights.")
        return Keyframe(d["time"], np.asarray(d["weights"], dtype=np.float64))


class Timeline:
    """Keyframes sorted by time, evaluated with linear or smooth (Catmull–Rom) interpolation."""

    def __init__(self, keys: list[Keyframe] | None = None, *, interpolation: str = "smooth", mode: str = "box",
                 lower: float = 0.0, upper: float = 1.0) -> None:
        if interpolation not in INTERPOLATIONS:
            raise RigInputError(f"Unknown interpolation '{interpolation}': use linear or smooth.")
        if mode not in ("box", "convex"):
            raise RigInputError(f"Unknown weight mode '{mode}': use box or convex.")
        self.interpolation = interpolation
        self.mode = mode
        self.lower, self.upper = float(lower), float(upper)
        self.keys: list[Keyframe] = []
        for k in keys or []:
            self.set_key(k.time, k.weights)

    def __len__(self) -> int:
        return len(self.keys)

    @property
    def times(self) -> np.ndarray:
        return np.array([k.time for k in self.keys])

    def set_key(self, time: float, weights: np.ndarray) -> Keyframe:
        """Add a key at ``time`` or replace the key already there (within a microsecond)."""
        key = Keyframe(time, weights)
        if self.keys and key.weights.shape != self.keys[0].weights.shape:
            raise RigInputError(f"A key of shape {key.weights.shape} does not match the timeline's "
                                f"{self.keys[0].weights.shape}.")
        for i, k in enumerate(self.keys):
            if abs(k.time - key.time) < 1e-6:
                self.keys[i] = key
                return key
        self.keys.append(key)
        self.keys.sort(key=lambda k: k.time)
        return key

    def remove_key(self, time: float) -> Keyframe:
        for i, k in enumerate(self.keys):
            if abs(k.time - float(time)) < 1e-6:
                return self.keys.pop(i)
        raise RigInputError(f"There is no key at time {float(time):g} s.")

    def key_at(self, time: float) -> Keyframe | None:
        return next((k for k in self.keys if abs(k.time - float(time)) < 1e-6), None)

    def evaluate(self, t: float, interpolation: str | None = None) -> np.ndarray:
        """The interpolated pose at time ``t`` (seconds), within the weight constraints."""
        if not self.keys:
            raise RigInputError("The timeline has no keys to evaluate.")
        how = interpolation or self.interpolation
        if how not in INTERPOLATIONS:
            raise RigInputError(f"Unknown interpolation '{how}': use linear or smooth.")
        T = self.times
        P = [k.weights for k in self.keys]
        n = len(P)
        if n == 1 or t <= T[0]:
            return self._constrain(P[0].copy())
        if t >= T[-1]:
            return self._constrain(P[-1].copy())
        i = int(np.searchsorted(T, t, side="right")) - 1  # T[i] <= t < T[i+1]
        h = T[i + 1] - T[i]
        s = (t - T[i]) / h
        if how == "linear":
            return self._constrain((1 - s) * P[i] + s * P[i + 1])
        m0 = self._tangent(T, P, i)
        m1 = self._tangent(T, P, i + 1)
        s2, s3 = s * s, s * s * s
        h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
        return self._constrain(h00 * P[i] + h10 * h * m0 + h01 * P[i + 1] + h11 * h * m1)

    @staticmethod
    def _tangent(T, P, i) -> np.ndarray:
        n = len(P)
        a, b = max(i - 1, 0), min(i + 1, n - 1)
        return (P[b] - P[a]) / (T[b] - T[a])

    def _constrain(self, w: np.ndarray) -> np.ndarray:
        if self.mode == "box":
            return np.clip(w, self.lower, self.upper)
        rows = np.atleast_2d(w)
        return np.stack([_project_capped_simplex(r, max(self.lower, 0.0)) for r in rows]).reshape(w.shape)

    def to_dict(self) -> dict:
        return {"interpolation": self.interpolation, "mode": self.mode, "lower": self.lower, "upper": self.upper,
                "keys": [k.to_dict() for k in self.keys]}

    @classmethod
    def from_dict(cls, d: dict) -> "Timeline":
        if not isinstance(d, dict) or not isinstance(d.get("keys", []), list):
            raise RigInputError("The timeline entry must hold a list of keys.")
        return cls([Keyframe.from_dict(k) for k in d.get("keys", [])],
                   interpolation=d.get("interpolation", "smooth"), mode=d.get("mode", "box"),
                   lower=d.get("lower", 0.0), upper=d.get("upper", 1.0))


def _project_capped_simplex(w: np.ndarray, lower: float) -> np.ndarray:
    """Euclidean projection onto {w ≥ lower, Σ w ≤ 1} (sort-based simplex projection when the sum is too big)."""
    x = np.maximum(w, lower)
    if x.sum() <= 1.0:
        return x
    y = w - lower
    budget = 1.0 - lower * w.size
    u = np.sort(y)[::-1]
    css = np.cumsum(u) - budget
    rho = np.flatnonzero(u - css / np.arange(1, u.size + 1) > 0)[-1]
    tau = css[rho] / (rho + 1.0)
    return np.maximum(y - tau, 0.0) + lower


def keyed_frames(timeline: Timeline, times: np.ndarray) -> np.ndarray:
    """The timeline's pose at each time: (F, K) or (F, R+1, K)."""
    return np.stack([timeline.evaluate(float(t)) for t in times])


def keyed_global_weights(timeline: Timeline, times: np.ndarray, deltas: np.ndarray, blend=None) -> np.ndarray:
    """(F, K) global weights per frame, what a DCC plays: a global timeline's own, a regional timeline's (its keys
    per region of ``blend`` (V, R+1)) the bounded least-squares fit of each frame's surface by the global rig
    (``solvers.surface_fit.global_weights_of_regional``)."""
    from solvers.surface_fit import global_weights_of_regional
    W = keyed_frames(timeline, times)
    if W.ndim == 2:
        return W
    if blend is None or deltas is None:
        raise RigInputError("A regional timeline needs the rig's shapes and the partition of unity of its level to "
                            "export global weights.")
    return global_weights_of_regional(deltas, blend, W, lower=timeline.lower, upper=timeline.upper)
