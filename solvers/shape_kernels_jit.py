"""Compiled passes over a rig's shapes, for what is computed once per rig: one shape's deformation maps
(``shape_maps``, four shapes at once ``shape_maps4``) and the sums behind the antagonist pairs (``antagonist_sums``);
and, for every frame the viewport draws, the vertex normals of a moving surface (``vertex_normals32``).

**Deformation maps.** ``‖L d(v)‖`` and ``‖d(v)‖`` for every vertex v (Joshi et al. 2003, §2,
``m_k(v) = ‖L d_k(v)‖``; ALGORITHMS.md §2), from the shape's (V, 3) deltas as the rig holds them.
``solvers.deformation_maps`` otherwise copies each shape to (3, V) rows, runs three scipy sparse
matrix-vector products and two norm passes: the Laplacian is read three times per shape. On a rig whose
Laplacian does not fit in the processor's cache (35 MB at 422k vertices) that is what the maps cost: 1.7 s
against 0.5 s here for the 422k-vertex studio rig's 57 shapes into maps already in memory (a segmentation from
scratch also pays ~0.4 s for its fresh maps' pages either way; on ICT FaceKit, whose Laplacian fits in the
cache, the same time either way). Here every row of the Laplacian is read once and its three coordinates summed
together. The sums are scipy's ``csr_matvec``'s, term by term in the row's stored order from 0.0, and the
norms ``_norm_rows``'s ``sqrt((x² + z²) + y²)``, so the maps are the same to the last bit
(``tests/test_laplacian_maps.py`` compares them).

**Antagonist sums** (ALGORITHMS.md §13, ``solvers.antagonists``): over each pair's shared support, its size, the
dot product of the two displacement fields and each shape's squared norm. As matrix products over all shapes and
vertices that is O(K²V) work (55 ms on ICT, a third of a cold take solve); a vertex is in the support of few
shapes (5.6 of ICT's 57 on average), so summed vertex by vertex over the pairs that act there it is 40 times
less arithmetic.

Compiled ahead of time with the take solver's kernel (``solvers.take_kernel``); a process that uses them never
imports numba (its import costs more than they save).
"""
from __future__ import annotations

import math

import numpy as np

try:
    from numba import njit
except ImportError:                         # the callers keep their numpy and scipy products
    njit = None


def shape_maps(indptr, indices, data, d, lap, disp, v0, v1):
    """``lap[v] = ‖Σ_j L[v, j] d[j]‖`` over row v of the CSR Laplacian (``indptr``, ``indices``, ``data``) and
    ``disp[v] = ‖d[v]‖`` for the (V, 3) deltas ``d``, for the rows v0 <= v < v1; ``lap`` and ``disp`` (V,) are
    written in place. Returns the number of rows. (The callers go through a large rig a block of rows at a time,
    so that a cancel is heard between blocks.)"""
    for v in range(v0, v1):
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
    return v1 - v0


def shape_maps4(indptr, indices, data, d, lap, disp, v0, v1):
    """``shape_maps`` of four shapes in one pass over the Laplacian: ``d`` (4, V, 3) their deltas, ``lap`` and
    ``disp`` (4, V) written in place, rows v0 <= v < v1. Each row's entries are read once for the four (a
    Laplacian read 57 times for ICT's shapes is then read 15 times), each shape's sums in the same order as
    ``shape_maps``'s, so the maps are the same to the last bit. Returns the number of rows."""
    for v in range(v0, v1):
        x0 = y0 = z0 = x1 = y1 = z1 = x2 = y2 = z2 = x3 = y3 = z3 = 0.0
        for jj in range(indptr[v], indptr[v + 1]):
            a = data[jj]
            j = indices[jj]
            x0 += a * d[0, j, 0]
            y0 += a * d[0, j, 1]
            z0 += a * d[0, j, 2]
            x1 += a * d[1, j, 0]
            y1 += a * d[1, j, 1]
            z1 += a * d[1, j, 2]
            x2 += a * d[2, j, 0]
            y2 += a * d[2, j, 1]
            z2 += a * d[2, j, 2]
            x3 += a * d[3, j, 0]
            y3 += a * d[3, j, 1]
            z3 += a * d[3, j, 2]
        lap[0, v] = math.sqrt((x0 * x0 + z0 * z0) + y0 * y0)
        lap[1, v] = math.sqrt((x1 * x1 + z1 * z1) + y1 * y1)
        lap[2, v] = math.sqrt((x2 * x2 + z2 * z2) + y2 * y2)
        lap[3, v] = math.sqrt((x3 * x3 + z3 * z3) + y3 * y3)
        for k in range(4):
            x = d[k, v, 0]
            y = d[k, v, 1]
            z = d[k, v, 2]
            disp[k, v] = math.sqrt((x * x + z * z) + y * y)
    return v1 - v0


def antagonist_sums(D, n2, active, shared, dots, sq):
    """For every pair i < j of the (K, V, 3) deltas ``D``, over the vertices where both act (``active`` (V, K),
    row v: the shapes acting at v): ``shared[i, j]`` the count, ``dots[i, j]`` ``Σ d_i(v)·d_j(v)``, and
    ``sq[i, j]``, ``sq[j, i]`` ``Σ ‖d_i(v)‖²`` and ``Σ ‖d_j(v)‖²`` (``n2`` (K, V) the squared norms). The (K, K)
    outputs start at zero; only the entries above the diagonal (and ``sq``'s below it) are written. Returns the
    number of (vertex, pair) terms."""
    V, K = active.shape[0], active.shape[1]
    acting = np.empty(K, np.int64)
    terms = 0
    for v in range(V):
        a = 0
        for k in range(K):
            if active[v, k]:
                acting[a] = k
                a += 1
        for p in range(a):
            i = acting[p]
            xi = D[i, v, 0]
            yi = D[i, v, 1]
            zi = D[i, v, 2]
            for q in range(p + 1, a):
                j = acting[q]
                shared[i, j] += 1.0
                dots[i, j] += xi * D[j, v, 0] + yi * D[j, v, 1] + zi * D[j, v, 2]
                sq[i, j] += n2[i, v]
                sq[j, i] += n2[j, v]
                terms += 1
    return terms


def vertex_normals32(x, a, b, c, out):
    """``solvers.normals.VertexNormals``' normals in one pass: for the (V, 3) float32 points ``x`` and the
    triangles (a[t], b[t], c[t]), ``out[v]`` (V, 3) float32 = the unit sum of e1 × e2 over the triangles at v
    (zero where that sum is zero). The same float32 operations in the same order as the numpy path (each
    triangle's cross product, the sums onto the corners in the triangles' order from 0, then
    ``n · (1 / sqrt((n0² + n1²) + n2²))``), so the same bits. Returns the number of triangles."""
    V = out.shape[0]
    for v in range(V):
        out[v, 0] = 0.0
        out[v, 1] = 0.0
        out[v, 2] = 0.0
    T = a.shape[0]
    for t in range(T):
        i = a[t]
        j = b[t]
        k = c[t]
        ax = x[i, 0]
        ay = x[i, 1]
        az = x[i, 2]
        e1x = x[j, 0] - ax
        e1y = x[j, 1] - ay
        e1z = x[j, 2] - az
        e2x = x[k, 0] - ax
        e2y = x[k, 1] - ay
        e2z = x[k, 2] - az
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        out[i, 0] += nx
        out[i, 1] += ny
        out[i, 2] += nz
        out[j, 0] += nx
        out[j, 1] += ny
        out[j, 2] += nz
        out[k, 0] += nx
        out[k, 1] += ny
        out[k, 2] += nz
    one = np.float32(1.0)
    for v in range(V):
        nx = out[v, 0]
        ny = out[v, 1]
        nz = out[v, 2]
        length = np.sqrt(nx * nx + ny * ny + nz * nz)
        if length > 0:
            inv = one / length
            out[v, 0] = nx * inv
            out[v, 1] = ny * inv
            out[v, 2] = nz * inv
    return T


if njit is not None:
    shape_maps = njit(cache=True, nogil=True)(shape_maps)
    shape_maps4 = njit(cache=True, nogil=True)(shape_maps4)
    antagonist_sums = njit(cache=True, nogil=True)(antagonist_sums)
    vertex_normals32 = njit(cache=True, nogil=True)(vertex_normals32)
