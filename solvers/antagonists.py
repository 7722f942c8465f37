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
    """[(i, j, cosine)] with i < j, most opposed first, for deltas (K, V, 3).

    Per pair, over the shared support: its size, the displacements' dot products summed over x, y, z, and each
    shape's squared norm. Where the compiled kernel is built (``solvers.shape_kernels_jit.antagonist_sums``), vertex
    by vertex over the pairs acting there (a vertex is in few shapes' support); else all pairs at once as matrix
    products over the supports' indicator A (K, V): A Aᵀ, (A∘d)(A∘d)ᵀ and (A∘‖d‖²) Aᵀ, O(K²V) in BLAS."""
    D = np.asarray(deltas, dtype=np.float64)
    K = D.shape[0]
    n2 = np.einsum("kvc,kvc->kv", D, D)                                # (K, V) squared norms
    top = np.sqrt(n2.max(axis=1)) if K else np.zeros(0)                # the largest norm of each shape
    act = np.empty(n2.shape, dtype=bool)
    for k in range(K):      # row by row: the norms of all shapes at once would be another (K, V) array
        np.greater(np.sqrt(n2[k]), support * max(top[k], 1e-300), out=act[k])
    size = act.sum(axis=1)
    sums = _compiled_sums(D, n2, act)
    if sums is not None:
        shared, dots, sq = sums
    else:
        A = act.astype(np.float64)
        shared = A @ A.T                                               # shared support sizes (exact in float64)
        AD = (D * A[:, :, None]).reshape(K, -1)
        dots = AD @ AD.T                                               # Σ over the shared support of d_i·d_j
        sq = (n2 * A) @ A.T                                            # [i, j]: Σ over the shared support of ‖d_i‖²
    moving = top > 0
    enough = shared >= np.maximum(1, overlap * np.minimum(size[:, None], size[None, :]))
    candidate = np.triu(enough & moving[:, None] & moving[None, :], k=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = dots / np.sqrt(sq * sq.T)
    i, j = np.nonzero(candidate & (cos < cosine))                       # row-major: the (i, j) order of a loop
    return sorted(zip(i.tolist(), j.tolist(), cos[i, j].tolist()), key=lambda p: p[2])


def _compiled_sums(D: np.ndarray, n2: np.ndarray, act: np.ndarray):
    """(shared, dots, sq) of ``antagonist_pairs`` from the compiled kernel (their entries above the diagonal, and
    ``sq``'s below it), or None where it is not built here (``solvers.take_kernel.built``) or where the shapes act
    so broadly that the pairs acting at each vertex are more than a sixteenth of all pairs (a rig of global shapes:
    the matrix products, vectorised by BLAS, are then the faster way)."""
    from . import take_kernel
    module = take_kernel.built()
    K, V = D.shape[0], D.shape[1]
    if module is None or K == 0:
        return None
    acting = act.sum(axis=0, dtype=np.float64)
    if float((acting * (acting - 1)).sum()) / 2 > K * K * V / 32:
        return None
    shared, dots, sq = np.zeros((K, K)), np.zeros((K, K)), np.zeros((K, K))
    module.antagonist_sums(np.ascontiguousarray(D), np.ascontiguousarray(n2), np.ascontiguousarray(act.T),
                           shared, dots, sq)
    return shared, dots, sq


def pair_penalty(pairs, K: int, lam: float) -> np.ndarray:
    """(K, K) symmetric matrix P with wᵀPw = λ Σ_pairs w_i w_j (the antagonist penalty, ALGORITHMS.md §13), to be
    added to a weight QP's Hessian-half ``AᵀA + …``."""
    P = np.zeros((K, K))
    for p in pairs:
        i, j = int(p[0]), int(p[1])
        P[i, j] = P[j, i] = 0.5 * lam
    return P
