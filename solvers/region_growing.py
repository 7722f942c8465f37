"""Region-growing segmentation, Acosta's alternative to thresholding (ALGORITHMS.md §3; Acosta 2015)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError


def grow_regions(values: np.ndarray, adjacency: sp.spmatrix, ratio: float = 0.75,
                 max_groups: int = 5) -> np.ndarray:
    """(V,) group labels 0..G-1 (-1 = in no group) by Acosta's region growing (Acosta 2015; ALGORITHMS.md §3).

    Vertices are taken by decreasing ``values`` (the displacement map ``max_k ‖d_k(v)‖``). The highest
    vertex not yet in a group seeds a group, which grows through mesh neighbours whose value is
    ``≥ ratio · value(seed)`` [ρ = 0.75] and that are in no group yet; up to ``max_groups`` groups [G = 5].
    A vertex belongs to at most one group. Seeds with value 0 start no group.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if not (0.0 < float(ratio) <= 1.0):
        raise RigInputError(f"The region-growing ratio must lie in (0, 1]; got {ratio}.")
    if int(max_groups) < 1:
        raise RigInputError(f"Region growing needs at least one group; got {max_groups}.")
    A = sp.csr_matrix(adjacency)
    labels = np.full(v.size, -1, dtype=np.int64)
    order = np.argsort(-v, kind="stable")
    pos = 0
    for g in range(int(max_groups)):
        while pos < order.size and labels[order[pos]] >= 0:
            pos += 1
        if pos >= order.size:
            break
        seed = int(order[pos])
        if v[seed] <= 0:
            break
        cand = np.flatnonzero((v >= ratio * v[seed]) & (labels < 0))
        _, comp = sp.csgraph.connected_components(A[cand][:, cand], directed=False)
        seed_comp = comp[np.searchsorted(cand, seed)]
        labels[cand[comp == seed_comp]] = g
    return labels
