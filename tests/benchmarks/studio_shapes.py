"""Studio-scale shape sets and a synthetic marker take for them (issue 20: 228 and 700 shapes on the ~106k-vertex
rig of ``studio_rig``), made from ICT's real shapes so that they stay local like a production rig's:

* 228 shapes: every ICT shape split into left/right × upper/lower parts by a smooth partition of unity centred on
  the shape's own motion (the four parts sum to the shape);
* 700 shapes: those 228 plus 472 in-betweens: the largest parts (each once or twice) with their motion reshaped
  over the face by a random smooth field (0.6 + 0.8·s(x, y), so an in-between is not a multiple of its part).

The take: the Live Link Face weights of the ICT take (``truth_weights.csv``), spread onto the parts with smooth
random gains per part and onto the in-betweens, posed at the ICT marker vertices (the subdivision keeps the
original vertices first, so the marker map's indices hold), plus a smooth rigid head motion and 0.03 mm noise,
in rig units (cm). The first 30 frames stay neutral for the calibration.
"""
from __future__ import annotations

import json

import numpy as np

from tests.benchmarks.studio_rig import studio_rig


def _smooth01(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def split_shapes(neutral: np.ndarray, deltas: np.ndarray, n_shapes: int, seed: int = 0) -> np.ndarray:
    """(n_shapes, V, 3) float32 local shapes from ``deltas`` (K, V, 3): 4 parts per shape (n_shapes ≥ 4K), then
    in-betweens of the largest parts."""
    K = deltas.shape[0]
    x, y = neutral[:, 0], neutral[:, 1]
    parts = []
    for k in range(K):
        d = deltas[k]
        mag = np.linalg.norm(d, axis=1)
        wsum = float(mag.sum()) or 1.0
        cx, cy = float(mag @ x) / wsum, float(mag @ y) / wsum
        right = _smooth01((x - cx) / 2.0 + 0.5)[:, None].astype(np.float32)   # 2 cm wide blend
        upper = _smooth01((y - cy) / 2.0 + 0.5)[:, None].astype(np.float32)
        for lr in (right, 1.0 - right):
            for ud in (upper, 1.0 - upper):
                parts.append(d * (lr * ud))
    parts = np.stack(parts).astype(np.float32)                                   # (4K, V, 3)
    extra = n_shapes - parts.shape[0]
    if extra <= 0:
        return parts[:n_shapes]
    rng = np.random.default_rng(seed)
    size = np.abs(parts).reshape(parts.shape[0], -1).max(axis=1)
    order = np.resize(np.argsort(-size), extra)     # the largest parts first, again with other fields if needed
    span = np.ptp(neutral[:, :2], axis=0)
    ib = np.empty((extra,) + parts.shape[1:], dtype=np.float32)
    for i, p in enumerate(order):
        fx, fy, ph = rng.uniform(1.0, 3.0), rng.uniform(1.0, 3.0), rng.uniform(0, 2 * np.pi)
        field = 0.5 + 0.5 * np.sin(2 * np.pi * (fx * x / span[0] + fy * y / span[1]) + ph)
        ib[i] = parts[p] * (0.6 + 0.8 * field)[:, None].astype(np.float32)
    return np.concatenate([parts, ib])


def posed_take(neutral: np.ndarray, shapes: np.ndarray, markers: np.ndarray, W: np.ndarray,
               seed: int = 1) -> np.ndarray:
    """(F, M, 3) marker positions (cm) of the rig posed by W (F, K) at ``markers``, moved by a smooth rigid head
    motion (about 4° and 0.5 cm; none over the first 30 frames) plus 0.03 mm noise."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(seed)
    F = W.shape[0]
    local = neutral[markers][None] + np.einsum("fk,kmc->fmc", W, shapes[:, markers].astype(np.float64))
    t = np.arange(F) / 60.0
    ang = np.deg2rad(4.0) * np.stack([np.sin(0.7 * t), np.sin(0.45 * t + 1.0), 0.5 * np.sin(0.3 * t)], axis=1)
    shift = np.stack([0.5 * np.sin(0.5 * t), 0.3 * np.sin(0.8 * t), 0.2 * np.sin(0.6 * t)], axis=1)
    ang[:30] = 0.0
    shift[:30] = 0.0
    pos = np.einsum("fij,fmj->fmi", Rotation.from_rotvec(ang).as_matrix(), local) + shift[:, None]
    return pos + rng.normal(scale=0.003, size=pos.shape)


def studio_weights(shapes: np.ndarray, ict_weights: np.ndarray, seed: int = 1) -> np.ndarray:
    """(F, K) weights for ``shapes`` (built by ``split_shapes`` from the 57 ICT shapes, or ICT's own) from the
    ICT take's weights (F, 57): every part follows its shape with a random gain, in-betweens their part at half."""
    rng = np.random.default_rng(seed)
    K57 = ict_weights.shape[1]
    K = shapes.shape[0]
    gains = rng.uniform(0.5, 1.0, size=(K,))
    if K == K57:
        return np.clip(ict_weights * gains, 0.0, 1.0)
    parent = np.repeat(np.arange(K57), 4)[:min(K, 4 * K57)]
    if K > 4 * K57:   # in-betweens follow the part they were made from (split_shapes' order)
        size = np.abs(shapes[:4 * K57]).reshape(4 * K57, -1).max(axis=1)
        parent = np.concatenate([parent, parent[np.resize(np.argsort(-size), K - 4 * K57)]])
        gains[4 * K57:] *= 0.5
    return np.clip(ict_weights[:, parent] * gains, 0.0, 1.0)


def studio_problem(n_shapes: int, levels: int = 1, source=None, take_dir=None):
    """(neutral, shapes (K, V, 3) float32, marker vertices (M,), positions (F, M, 3) cm, true weights (F, K)) of
    ``n_shapes`` studio shapes on the ICT rig subdivided ``levels`` times (57 = ICT's own shapes)."""
    if take_dir is None:
        from tests.conftest import TAKE_DIR
        take_dir = TAKE_DIR
    neutral, _, _, deltas = studio_rig(levels, source)
    shapes = deltas if n_shapes == deltas.shape[0] else split_shapes(neutral, deltas, n_shapes)
    markers = np.array(list(json.loads((take_dir / "marker_map.json").read_text())["markers"].values()))
    table = np.loadtxt(take_dir / "truth_weights.csv", delimiter=",", skiprows=1)[:, 1:]
    W = studio_weights(shapes, table)
    return neutral, shapes, markers, posed_take(neutral, shapes, markers, W), W
