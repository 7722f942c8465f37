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

Per-shape keys (Maya's "key one attribute", Blender's keyed shape key): a key may key only some shapes
(``Keyframe.keyed``, a (K,) mask; None keys every shape). Each shape is a channel of its own, interpolated
through the keys that key it; a shape no key keys holds the first key's value. Keys that key every shape
(the usual "set key on the pose") evaluate exactly as before.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import RigInputError

INTERPOLATIONS = ("linear", "smooth")


@dataclass
class Keyframe:
    """A pose at a time (seconds): weights (K,) or (R+1, K); ``keyed`` (K,) bool: the shapes this key keys
    (None: all of them). The weights of a shape it does not key are the pose it was set on, never evaluated."""

    time: float
    weights: np.ndarray
    keyed: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.time = float(self.time)
        if not np.isfinite(self.time):
            raise RigInputError("A keyframe needs a finite time.")
        self.weights = np.array(self.weights, dtype=np.float64)
        if self.weights.ndim not in (1, 2) or not np.isfinite(self.weights).all():
            raise RigInputError("A keyframe's weights must be a finite (K,) or (R+1, K) array.")
        if self.keyed is not None:
            keyed = np.asarray(self.keyed)
            if keyed.shape != self.weights.shape[-1:]:
                raise RigInputError(f"A keyframe's keyed shapes must be a ({self.weights.shape[-1]},) mask, "
                                    f"not {keyed.shape}.")
            self.keyed = None if keyed.all() else keyed.astype(bool).copy()

    @property
    def mask(self) -> np.ndarray:
        """(K,) bool: the shapes this key keys."""
        return np.ones(self.weights.shape[-1], dtype=bool) if self.keyed is None else self.keyed

    def keys_shape(self, k: int) -> bool:
        return self.keyed is None or bool(self.keyed[k])

    def copy(self) -> "Keyframe":
        return Keyframe(self.time, self.weights, self.keyed)

    def to_dict(self) -> dict:
        d = {"time": self.time, "weights": self.weights.tolist()}
        if self.keyed is not None:
            d["keyed"] = [int(i) for i in np.flatnonzero(self.keyed)]
        return d

    @staticmethod
    def from_dict(d: dict) -> "Keyframe":
        if not isinstance(d, dict) or "time" not in d or "weights" not in d:
            raise RigInputError("A keyframe entry needs a time and weights.")
        w = np.asarray(d["weights"], dtype=np.float64)
        keyed = None
        if d.get("keyed") is not None:
            idx = np.asarray(d["keyed"], dtype=np.int64)
            if w.ndim < 1 or idx.ndim != 1 or (idx.size and (idx.min() < 0 or idx.max() >= w.shape[-1])):
                raise RigInputError("A keyframe's keyed shapes must be shape indices of its weights.")
            keyed = np.zeros(w.shape[-1], dtype=bool)
            keyed[idx] = True
        return Keyframe(d["time"], w, keyed)


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
            self.set_key(k.time, k.weights, k.keyed)

    def copy(self, interpolation: str | None = None) -> "Timeline":
        """An independent copy (keys copied), optionally with another interpolation."""
        return Timeline([k.copy() for k in self.keys], interpolation=interpolation or self.interpolation,
                        mode=self.mode, lower=self.lower, upper=self.upper)

    def __len__(self) -> int:
        return len(self.keys)

    @property
    def times(self) -> np.ndarray:
        return np.array([k.time for k in self.keys])

    def set_key(self, time: float, weights: np.ndarray, keyed=None) -> Keyframe:
        """Add a key at ``time`` or replace the key already there (within a microsecond). ``keyed`` ((K,) bool
        or None: all): the shapes to key; on an existing key only those shapes' weights change (the others keep
        their keys), a new key stores ``weights`` whole and keys only those shapes."""
        key = Keyframe(time, weights, keyed)
        if self.keys and key.weights.shape != self.keys[0].weights.shape:
            raise RigInputError(f"A key of shape {key.weights.shape} does not match the timeline's "
                                f"{self.keys[0].weights.shape}.")
        for i, k in enumerate(self.keys):
            if abs(k.time - key.time) < 1e-6:
                if key.keyed is not None:   # key some shapes on a key that is there: the others stay keyed
                    w = k.weights.copy()
                    w[..., key.keyed] = key.weights[..., key.keyed]
                    key = Keyframe(k.time, w, k.mask | key.keyed)
                self.keys[i] = key
                return key
        self.keys.append(key)
        self.keys.sort(key=lambda k: k.time)
        return key

    def set_shape_key(self, time: float, k: int, value, pose: np.ndarray | None = None) -> Keyframe:
        """Key shape ``k`` alone at ``time`` to ``value`` (a weight, or a (R+1,) column of a regional timeline).
        A new key stores ``pose`` (default: the timeline's pose there) for its other shapes, unkeyed."""
        self._check_shape(k)
        base = self.key_at(time)
        if base is not None:
            w = base.weights.copy()
        elif pose is not None:
            w = np.array(pose, dtype=np.float64)
        elif self.keys:
            w = self.evaluate(time)
        else:
            raise RigInputError("A key of one shape on an empty timeline needs the pose it is set on.")
        w[..., k] = value
        mask = np.zeros(w.shape[-1], dtype=bool)
        mask[k] = True
        return self.set_key(time, w, mask)

    def remove_shape_key(self, time: float, k: int) -> None:
        """Stop keying shape ``k`` at ``time``; a key that then keys no shape goes."""
        self._check_shape(k)
        key = self.key_at(time)
        if key is None or not key.keys_shape(k):
            raise RigInputError(f"There is no key of shape {k} at {float(time):g} s.")
        mask = key.mask.copy()
        mask[k] = False
        if not mask.any():
            self.remove_key(key.time)
        else:
            self.keys[self.keys.index(key)] = Keyframe(key.time, key.weights, mask)

    def move_shape_key(self, k: int, time: float, new_time: float, value: float) -> Keyframe:
        """Move shape ``k``'s key at ``time`` to ``new_time`` with the displayed value ``value``
        (``shape_value``: a regional column moves by the same amount in every region, within the bounds)."""
        key = self.key_at(time)
        if key is None or not key.keys_shape(k):
            raise RigInputError(f"There is no key of shape {k} at {float(time):g} s.")
        column = key.weights[..., k] + (float(value) - shape_value(key.weights, k))
        column = np.clip(column, self.lower, self.upper)
        self.remove_shape_key(time, k)
        pose = key.weights if not self.keys else None
        return self.set_shape_key(new_time, k, column, pose=pose)

    def shape_keys(self, k: int) -> list[Keyframe]:
        """The keys that key shape ``k``, in time order."""
        self._check_shape(k)
        return [key for key in self.keys if key.keys_shape(k)]

    def _check_shape(self, k: int) -> None:
        if self.keys and not 0 <= int(k) < self.keys[0].weights.shape[-1]:
            raise RigInputError(f"There is no shape {k} in a timeline of {self.keys[0].weights.shape[-1]} shapes.")

    def next_key_time(self, t: float, direction: int = 1) -> float | None:
        """The time of the first key after ``t`` (``direction`` -1: before it), or None."""
        T = self.times
        T = T[T > t + 1e-6] if direction > 0 else T[T < t - 1e-6][::-1]
        return float(T[0]) if T.size else None

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
        if all(k.keyed is None for k in self.keys):
            return self._constrain(_interpolate(T, P, t, how))
        # per-shape keys: each group of shapes keyed by the same keys is a channel of its own
        M = np.stack([k.mask for k in self.keys])               # (N, K)
        out = P[0].copy()                                       # a shape no key keys holds the first key's value
        patterns, group = np.unique(M.T, axis=0, return_inverse=True)
        for g, pattern in enumerate(patterns):
            idx = np.flatnonzero(pattern)
            if idx.size:
                cols = np.flatnonzero(group.ravel() == g)
                out[..., cols] = _interpolate(T[idx], [P[i][..., cols] for i in idx], t, how)
        return self._constrain(out)

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


def shape_value(weights: np.ndarray, k: int) -> float:
    """Shape ``k``'s weight in a pose: its global weight, or a regional pose's largest over the regions (how
    strongly the shape acts anywhere on the face)."""
    return float(np.max(np.asarray(weights)[..., k]))


def _interpolate(T: np.ndarray, P: list[np.ndarray], t: float, how: str) -> np.ndarray:
    """The unconstrained value at ``t`` of keys ``P`` at sorted times ``T``, linear or Catmull–Rom."""
    n = len(P)
    if n == 1 or t <= T[0]:
        return np.array(P[0], dtype=np.float64)
    if t >= T[-1]:
        return np.array(P[-1], dtype=np.float64)
    i = int(np.searchsorted(T, t, side="right")) - 1  # T[i] <= t < T[i+1]
    h = T[i + 1] - T[i]
    s = (t - T[i]) / h
    if how == "linear":
        return (1 - s) * P[i] + s * P[i + 1]

    def tangent(j: int) -> np.ndarray:
        a, b = max(j - 1, 0), min(j + 1, n - 1)
        return (P[b] - P[a]) / (T[b] - T[a])
    m0, m1 = tangent(i), tangent(i + 1)
    s2, s3 = s * s, s * s * s
    h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
    return h00 * P[i] + h10 * h * m0 + h01 * P[i + 1] + h11 * h * m1


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


def shape_curves(timeline: Timeline, times: np.ndarray) -> np.ndarray:
    """(F, K) each shape's weight at each time as the graph editor draws it (``shape_value``: a regional
    timeline's largest over the regions)."""
    W = keyed_frames(timeline, times)
    return W.max(axis=1) if W.ndim == 3 else W


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
