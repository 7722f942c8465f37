"""One shape's deformation maps in one pass, compiled: ``‖L d(v)‖`` and ``‖d(v)‖`` for every vertex v
(Joshi et al. 2003, §2, ``m_k(v) = ‖L d_k(v)‖``; ALGORITHMS.md §2), from the shape's (V, 3) deltas as the rig
holds them.

``solvers.deformation_maps`` otherwise copies each shape to (3, V) rows, runs three scipy sparse
matrix-vector products and two norm passes: the Laplacian is read three times per shape. On a rig whose
Laplacian does not fit in the processor's cache (35 MB at 422k vertices) that is what the maps cost: 1.7 s
against 0.5 s here for the 422k-vertex studio rig's 57 shapes into maps already in memory (a segmentation from
scratch also pays ~0.4 s for its fresh maps' pages either way; on ICT FaceKit, whose Laplacian fits in the
cache, the same time either way). Here every row of the Laplacian is read once and its three coordinates summed
together. The sums are scipy's ``csr_matvec``'s, term by term in the row's stored order from 0.0, and the
norms ``_norm_rows``'s ``sqrt((x² + z²) + y²)``, so the maps are the same to the last bit
(``tests/test_laplacian_maps.py`` compares them).

Compiled ahead of time with the take solver's kernel (``solvers.take_kernel``); a segmenting process never
imports numba (its import costs more than this saves on a small rig).
"""
from __future__ import annotations

import math

try:
    from numba import njit
except ImportError:                         # the caller keeps the scipy products
    njit = None


def shape_maps(indptr, indices, data, d, lap, disp):
    """``lap[v] = ‖Σ_j L[v, j] d[j]‖`` over row v of the CSR Laplacian (``indptr``, ``indices``, ``data``) and
    ``disp[v] = ‖d[v]‖`` for the (V, 3) deltas ``d``; ``lap`` and ``disp`` (V,) are written in place. Returns V."""
    V = lap.shape[0]
    for v in range(V):
        x = 0.0
        y = 0.0
        z = 0.0
        for jj in range(indptr[v], indptr[v + 1]):
            a = data[jj]
            j = indices[jj]
            x += a * d[j, 0]
            y += a * d[j, 1]
            z += a * d[j, 2]
        lap[v] = math.sqrt((x * x + z * z) + y * y)
        x = d[v, 0]
        y = d[v, 1]
        z = d[v, 2]
        disp[v] = math.sqrt((x * x + z * z) + y * y)
    return V


if njit is not None:
    shape_maps = njit(cache=True, nogil=True)(shape_maps)
