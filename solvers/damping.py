"""Motion damping for marker dragging (Joshi et al. 2003, §4; ALGORITHMS.md §8).

A point that barely moves in any shape (the tip of the nose) cannot follow a large mouse motion: the solve
would swing the whole face trying. Joshi damps the drag per point with the point's mobility, the largest
displacement any shape makes there, ``m(v) = max_k ‖d_k(v)‖``: the drag is attenuated by a factor
inversely proportional to the point's mobility relative to a typical face point, i.e. the applied gain is

    gain(v) = clip(m(v) / m_typical, min_gain, max_gain),     m_typical = median of m over moving vertices,

so a typical face point follows the mouse one to one (gain ≈ 1), the nose tip moves a fraction of it and
nothing is amplified beyond ``max_gain``. For a face point the mobility is the barycentric mix of its corners'.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def point_mobility(deltas: np.ndarray) -> np.ndarray:
    """(V,) ``m(v) = max_k ‖d_k(v)‖``, the largest displacement any shape makes at each vertex
    (Joshi et al. 2003, §4; the displacement map of ALGORITHMS.md §2). ``deltas`` is (K, V, 3)."""
    d = np.asarray(deltas)
    if d.shape[0] == 0:
        return np.zeros(d.shape[1])
    out = np.zeros(d.shape[1])
    for k in range(d.shape[0]):  # one shape at a time keeps memory at O(V)
        np.maximum(out, np.sqrt(np.einsum("vc,vc->v", d[k], d[k])), out=out)
    return out


def damping_gains(mobility: np.ndarray, *, min_gain: float = 0.05, max_gain: float = 1.5,
                  typical: float | None = None) -> np.ndarray:
    """(V,) per-vertex drag gains ``clip(m(v) / m_typical, min_gain, max_gain)`` (Joshi et al. 2003, §4).

    ``typical`` defaults to the median mobility over the vertices that move (m > 0), so a typical face
    point has a gain of about 1. Vertices no shape moves get ``min_gain``.
    """
    m = np.asarray(mobility, dtype=np.float64)
    if typical is None:
        moving = m[m > 0]
        typical = float(np.median(moving)) if moving.size else 1.0
    if typical <= 0:
        typical = 1.0
    return np.clip(m / typical, min_gain, max_gain)


def damp_displacement(mouse_displacement: np.ndarray, gains: np.ndarray, *, vertex: int | None = None,
                      sampling: sp.spmatrix | np.ndarray | None = None) -> np.ndarray:
    """The damped target displacement for a mouse displacement (3,) or (M, 3) (Joshi et al. 2003, §4).

    Give ``vertex`` for one vertex marker, or ``sampling`` (M, V) (``MarkerSet.S``) for markers on face
    points: each marker's gain is the barycentric mix of its corners' gains.
    """
    d = np.asarray(mouse_displacement, dtype=np.float64)
    g = np.asarray(gains, dtype=np.float64)
    if vertex is not None:
        return d * g[int(vertex)]
    if sampling is None:
        raise ValueError("damp_displacement needs a vertex or a sampling matrix.")
    gm = np.asarray(sampling @ g).reshape(-1)
    return d * (gm[:, None] if d.ndim == 2 else gm[0])
