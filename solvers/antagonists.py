"""Antagonist shape pairs of a rig (ALGORITHMS.md §13): shapes whose displacements cancel where both act, so a
solve with few markers can trade one for the other (a mouth corner reached by jawLeft + jawRight + smile).

A pair (i, j) is an antagonist pair when, over their shared support (vertices where each moves more than
``support`` × its own largest displacement) covering at least ``overlap`` of the smaller shape's support,
the cosine of their displacement fields is below ``cosine``:
``Σ_v d_i(v)·d_j(v) / sqrt(Σ_v ‖d_i(v)‖² Σ_v ‖d_j(v)‖²) < cosine``.
Pairs that cancel by design and are used together (ARKit's mouthClose with jawOpen) are not antagonists: the
caller removes them (``model.antagonists``).
"""
from __future__ import annotations

import numpy as np


def antagonist_pairs(deltas: np.ndarray, *, cosine: float = -0.5, support: float = 0.1,
                     overlap: float = 0.5) -> list[tuple[int, int, float]]:
    """[(i, j, cosine)] with i < j, most opposed first, for deltas (K, V, 3)."""
    D = np.asarray(deltas, dtype=np.float64)
    n = np.sqrt(np.einsum("kvc,kvc->kv", D, D))                       # (K, V)
    top = n.max(axis=1)
    act = n > support * np.maximum(top, 1e-300)[:, None]
    size = act.sum(axis=1)
    out = []
    for i in range(D.shape[0]):
        if not top[i]:
            continue
        for j in range(i + 1, D.shape[0]):
            if not top[j]:
                continue
            shared = act[i] & act[j]
            if shared.sum() < max(1, overlap * min(size[i], size[j])):
                continue
            a, b = D[i][shared], D[j][shared]
            c = float(np.einsum("vc,vc->", a, b) / np.sqrt(np.einsum("vc,vc->", a, a) * np.einsum("vc,vc->", b, b)))
            if c < cosine:
                out.append((i, j, c))
    return sorted(out, key=lambda p: p[2])


def pair_penalty(pairs, K: int, lam: float) -> np.ndarray:
    """(K, K) symmetric matrix P with wᵀPw = λ Σ_pairs w_i w_j (the antagonist penalty, ALGORITHMS.md §13), to be
    added to a weight QP's Hessian-half ``AᵀA + …``."""
    P = np.zeros((K, K))
    for p in pairs:
        i, j = int(p[0]), int(p[1])
        P[i, j] = P[j, i] = 0.5 * lam
    return P
