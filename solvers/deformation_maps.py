"""Deformation maps (ALGORITHMS.md §2; Joshi et al. 2003, §2; Acosta 2015 for the displacement map).

Per-shape Laplacian magnitude ``m_k(v) = ‖L d_k(v)‖``, combined map ``M(v) = max_k m_k(v)``, the arg-max
shape and its Laplacian vector (the RGB view), and the plain displacement map ``max_k ‖d_k(v)‖``.
Each shape goes through the Laplacian as three (V,) sparse matrix-vector products, one per coordinate, on a
(3, V) copy of its deltas (a (V, 3) product runs a length-3 loop per matrix entry and is twice as slow), so the
cost is linear in vertices and shapes and no (V, 3K) transposed copy of all shapes is made.

Per-shape normalisation (``normalised_map``): Joshi's maximum lets shapes with sharp local bending (lips,
lids) outvote shapes that move a broad area smoothly (a brow raise). Dividing each shape's map by a high
quantile of itself, taken over the vertices that shape moves, gives every shape its say before the maximum.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError
from .parallel import for_spans, ordered_map

MAP_KINDS = ("laplacian", "displacement", "laplacian+displacement")
NORMALISE_QUANTILE = 0.99   # each shape's map is divided by this quantile of itself over the vertices it moves
MOVING_FRACTION = 0.01      # a shape moves a vertex when it displaces it by > 1% of its largest displacement
# rows of the Laplacian per compiled call: a call holds Python's lock, and a segmentation runs beside the window
# (a block of four shapes over 32k rows is ~5 ms on a 422k-vertex rig, where a whole call was ~50-400 ms)
KERNEL_ROWS = 1 << 15


@dataclass
class DeformationMaps:
    """Arrays of the deformation maps of one rig (V vertices, K shapes).

    per_shape     (V, K) ``m_k(v) = ‖L d_k(v)‖``.
    combined      (V,)   ``M(v) = max_k m_k(v)``.
    argmax_shape  (V,)   int, the k reaching the maximum (0 where every shape is still).
    vector        (V, 3) ``L d_k(v)`` of the arg-max shape (x, y, z → R, G, B in the vector view), computed on
                  first use from ``laplacian`` and ``deltas`` (only the vector view shows it).
    displacement  (V,)   ``max_k ‖d_k(v)‖``.
    per_shape_displacement (V, K) ``‖d_k(v)‖``.
    """

    per_shape: np.ndarray
    combined: np.ndarray
    argmax_shape: np.ndarray
    displacement: np.ndarray
    per_shape_displacement: np.ndarray | None = None
    laplacian: sp.csr_matrix | None = field(default=None, repr=False)
    deltas: np.ndarray | None = field(default=None, repr=False)
    _vector: np.ndarray | None = field(default=None, init=False, repr=False)

    @property
    def vector(self) -> np.ndarray:
        if self._vector is None:
            self._vector = argmax_vectors(self.laplacian, self.deltas, self.argmax_shape)
        return self._vector

    def per_shape_values(self, kind: str) -> np.ndarray:
        """(V, K) per-shape maps of a kind: 'laplacian' ``‖L d_k‖`` or 'displacement' ``‖d_k‖``."""
        if kind == "laplacian":
            return self.per_shape
        if kind == "displacement":
            return self.per_shape_displacement
        raise RigInputError(f"Unknown per-shape map '{kind}': use 'laplacian' or 'displacement'.")

    def values(self, kind: str) -> np.ndarray:
        """The raw scalar map a segmentation thresholds: 'laplacian' (M), 'displacement', or
        'laplacian+displacement' (the larger of the two; in raw units the displacement mostly)."""
        if kind == "laplacian":
            return self.combined
        if kind == "displacement":
            return self.displacement
        if kind == "laplacian+displacement":
            return np.maximum(self.combined, self.displacement)
        raise RigInputError(f"Unknown map '{kind}': use one of {', '.join(MAP_KINDS)}.")


def _check_deltas(deltas: np.ndarray, n_vertices: int) -> np.ndarray:
    d = np.asarray(deltas, dtype=np.float64)
    if d.ndim != 3 or d.shape[1:] != (n_vertices, 3):
        raise RigInputError(
            f"The shape deltas must be a (K, {n_vertices}, 3) array; got shape {tuple(d.shape)}.")
    return d


def laplacian_vectors(laplacian: sp.spmatrix, deltas: np.ndarray) -> np.ndarray:
    """(V, K, 3) Laplacian vectors ``L d_k(v)`` of all K shapes (Joshi et al. 2003, §2).

    ``(L d_k)(v) = (1/|N(v)|) Σ_{u∈N(v)} (d_k(u) − d_k(v))`` for the umbrella operator.
    """
    L = sp.csr_matrix(laplacian)
    V = L.shape[0]
    d = _check_deltas(deltas, V)
    out = np.empty((V, d.shape[0], 3))
    for k in range(d.shape[0]):
        out[:, k] = L @ d[k]
    return out


def _norm_rows(x: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> None:
    """``out = ‖x‖`` of the columns of a (3, V) array, as ``sqrt((x0² + x2²) + x1²)`` (the order numpy's einsum
    sums a length-3 axis in, so the maps keep their values to the last bit), with no temporary arrays."""
    np.multiply(x[0], x[0], out=out)
    np.multiply(x[2], x[2], out=tmp)
    out += tmp
    np.multiply(x[1], x[1], out=tmp)
    out += tmp
    np.sqrt(out, out=out)


def _compiled_shape_maps(L: sp.csr_matrix):
    """(``shape_kernels_jit.shape_maps``, ``.shape_maps4``) bound to ``L``'s arrays, as ``f(d, lap, disp)`` for one
    shape ((V, 3) deltas, (V,) outputs) and for four ((4, V, 3), (4, V)); None when the compiled module is not built
    on this machine (``solvers.take_kernel.built``) or ``L`` has 64-bit indices (over 2^31 entries)."""
    from . import take_kernel
    module = take_kernel.built()
    if module is None or L.indices.dtype != np.int32 or L.indptr.dtype != np.int32:
        return None
    data = np.ascontiguousarray(L.data, dtype=np.float64)
    V = L.shape[0]
    blocks = [(v, min(v + KERNEL_ROWS, V)) for v in range(0, V, KERNEL_ROWS)]

    def one(d, lap, disp):
        for v0, v1 in blocks:
            module.shape_maps(L.indptr, L.indices, data, d, lap, disp, v0, v1)

    def four(d, lap, disp):
        for v0, v1 in blocks:
            module.shape_maps4(L.indptr, L.indices, data, d, lap, disp, v0, v1)
    return one, four


def _shape_maps(L: sp.csr_matrix, d: np.ndarray, displacement: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """(K, V) ``m_k(v) = ‖L d_k(v)‖`` (Joshi et al. 2003, §2) and, with ``displacement``, (K, V) ``‖d_k(v)‖``:
    where the kernel is built here, one compiled pass over the Laplacian per four shapes (then one per shape left),
    reading their (V, 3) deltas as the rig holds them; else each shape's deltas copied to (3, V) rows and one sparse
    matrix-vector product per coordinate (the same bits)."""
    K, V = d.shape[0], L.shape[0]
    per_shape = np.empty((K, V))
    disp = np.empty((K, V)) if displacement else None
    compiled = _compiled_shape_maps(L)
    if compiled is not None:            # the same bits, the Laplacian read once per four shapes (shape_kernels_jit)
        one, four = compiled
        d = np.ascontiguousarray(d)

        local = threading.local()

        def displacements(k: int, n: int) -> np.ndarray:   # shapes k..k+n-1's: kept, or each thread's scratch
            if displacement:
                return disp[k:k + n]
            if not hasattr(local, "scratch"):
                local.scratch = np.empty((4, V))
            return local.scratch[:n]

        def shapes(k: int) -> None:    # shapes k.. k + 3, or k alone past the last four
            if k < K - K % 4:
                four(d[k:k + 4], per_shape[k:k + 4], displacements(k, 4))
            else:
                one(d[k], per_shape[k], displacements(k, 1)[0])
        # on the machine's cores (the kernel runs outside the GIL), each shape's rows written by one thread
        for _ in ordered_map(shapes, [*range(0, K - K % 4, 4), *range(K - K % 4, K)]):
            pass
        return per_shape, disp
    dt, y, tmp = np.empty((3, V)), np.empty((3, V)), np.empty(V)
    for k in range(K):
        np.copyto(dt, d[k].T)
        for c in range(3):
            y[c] = L @ dt[c]
        _norm_rows(y, per_shape[k], tmp)
        if displacement:
            _norm_rows(dt, disp[k], tmp)
    return per_shape, disp


def laplacian_magnitudes(laplacian: sp.spmatrix, deltas: np.ndarray) -> np.ndarray:
    """(V, K) per-shape deformation maps ``m_k(v) = ‖L d_k(v)‖`` (Joshi et al. 2003, §2)."""
    L = sp.csr_matrix(laplacian)
    return _shape_maps(L, _check_deltas(deltas, L.shape[0]), displacement=False)[0].T


def displacement_map(deltas: np.ndarray) -> np.ndarray:
    """(V,) plain displacement map ``max_k ‖d_k(v)‖`` (Acosta 2015; ALGORITHMS.md §2); zeros if K = 0."""
    d = np.asarray(deltas, dtype=np.float64)
    if d.shape[0] == 0:
        return np.zeros(d.shape[1])
    return np.sqrt(np.einsum("kvc,kvc->kv", d, d).max(axis=0))


def deformation_maps(laplacian: sp.spmatrix, deltas: np.ndarray) -> DeformationMaps:
    """All deformation maps of a rig (Joshi et al. 2003, §2: ``m_k = ‖L d_k‖``, ``M = max_k m_k``).

    ``laplacian`` (V, V) sparse, from ``solvers.laplacian``; ``deltas`` (K, V, 3) with K ≥ 1.
    """
    L = sp.csr_matrix(laplacian)
    V = L.shape[0]
    d = _check_deltas(deltas, V)
    K = d.shape[0]
    if K == 0:
        raise RigInputError("The rig has no blendshapes, so there is no deformation map to compute.")
    # (K, V) rows written contiguously; handed out as their (V, K) transposes (column-major views)
    per_shape, disp = _shape_maps(L, d)
    # the arg-max shape of every vertex (the first of equal maxima, as np.argmax): no per-shape running update
    # over V, and no argmax across the (K, V) rows (numpy copies them to (V, K) for that); its Laplacian vector
    # is computed when the vector view asks for it (``argmax_vectors``)
    combined, arg, displacement = np.empty(V), np.zeros(V, dtype=np.int64), np.empty(V)

    def columns(a: int, b: int) -> None:     # the vertices a..b, on the machine's cores
        np.max(per_shape[:, a:b], axis=0, out=combined[a:b])
        for k in range(K - 1, -1, -1):  # the last write is the smallest k at the maximum
            np.copyto(arg[a:b], k, where=per_shape[k, a:b] == combined[a:b])
        np.max(disp[:, a:b], axis=0, out=displacement[a:b])
    for_spans(columns, V)
    nan = np.isnan(combined)
    if nan.any():  # np.argmax's answer there: the first NaN
        arg[nan] = np.argmax(per_shape[:, nan], axis=0)
    return DeformationMaps(per_shape=per_shape.T, combined=combined, argmax_shape=arg,
                           displacement=displacement, per_shape_displacement=disp.T, laplacian=L, deltas=deltas)


def argmax_vectors(laplacian: sp.spmatrix, deltas: np.ndarray, argmax_shape: np.ndarray) -> np.ndarray:
    """(V, 3) ``L d_k(v)`` with k the arg-max shape of each vertex (Joshi et al. 2003, §2, the vector view):
    one product per shape over the rows it wins (the same row sums as the full product)."""
    L = sp.csr_matrix(laplacian)
    arg = np.asarray(argmax_shape)
    K, V = len(deltas), L.shape[0]
    vector = np.zeros((V, 3))
    order = np.argsort(arg, kind="stable")
    bounds = np.searchsorted(arg[order], np.arange(K + 1))
    L_won = L[order]
    for k in np.flatnonzero(np.diff(bounds)):
        a, b = bounds[k], bounds[k + 1]
        vector[order[a:b]] = L_won[a:b] @ np.asarray(deltas[k], dtype=np.float64)
    return vector


def shape_moves(per_shape_displacement: np.ndarray, fraction: float = MOVING_FRACTION) -> np.ndarray:
    """(V, K) bool: shape k moves vertex v, ``‖d_k(v)‖ > fraction · max_u ‖d_k(u)‖`` (a shape that moves
    nothing moves no vertex)."""
    D = np.asarray(per_shape_displacement)
    top = D.max(axis=0)
    # along the shapes' rows of D's (K, V) memory (the maps are (K, V) arrays handed out transposed): a (V, K)
    # broadcast would walk them across, one page per element on a large rig
    out = np.greater(D.T, (fraction * top)[:, None])
    out[~(top > 0)] = False
    return out.T


def shape_scales(per_shape: np.ndarray, moves: np.ndarray, quantile: float = NORMALISE_QUANTILE) -> np.ndarray:
    """(K,) the ``quantile`` of each shape's map over the vertices that shape moves (1 where it moves none
    or its map is zero there): the scale ``normalised_map`` divides by."""
    P = np.asarray(per_shape)
    K = P.shape[1]
    out = np.ones(K)
    PT, MT = P.T, np.asarray(moves).T  # the shapes' rows of the (K, V) maps
    for k in range(K):
        vals = PT[k][MT[k]]
        if vals.size:
            q = _quantile(vals, quantile)
            if q > 0:
                out[k] = q
    return out


def _quantile(values: np.ndarray, q: float) -> float:
    """``np.quantile(values, q)`` (its default 'linear' method, the same arithmetic to the last bit) of a
    1-D array: one partition at the two order statistics around ``(n − 1)·q`` and numpy's interpolation between
    them, without np.quantile's general-case overhead (a tenth of a millisecond a call, 114 calls on ICT)."""
    n = values.size
    v = (n - 1) * q
    if n < 2 or v >= n - 1 or v < 0 or np.isnan(values).any():
        return float(np.quantile(values, q))
    lo = math.floor(v)
    part = np.partition(values, (lo, lo + 1))
    a, b = float(part[lo]), float(part[lo + 1])
    t = v - lo
    diff = b - a
    return b - diff * (1 - t) if t >= 0.5 else a + diff * t


def normalised_map(per_shape: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """(V,) ``max_k m_k(v) / s_k``: every shape's map on its own scale before the maximum (see module doc).
    One shape at a time into a (V,) running maximum: no (V, K) temporary."""
    P = np.asarray(per_shape)
    s = np.asarray(scales, dtype=np.float64)
    out = P[:, 0] / s[0]
    col = np.empty_like(out)
    for k in range(1, P.shape[1]):
        np.divide(P[:, k], s[k], out=col)
        np.maximum(out, col, out=out)
    return out


def smooth_map(values: np.ndarray, adjacency: sp.spmatrix, iterations: int) -> np.ndarray:
    """A light smoothing of a per-vertex map: ``iterations`` rounds of the average over each vertex and its
    1-ring, ``x(v) ← (x(v) + Σ_{u∈N(v)} x(u)) / (1 + |N(v)|)``. Constant maps are unchanged."""
    x = np.asarray(values, dtype=np.float64)
    if iterations <= 0:
        return x.copy()
    A = sp.csr_matrix(adjacency)
    inv = 1.0 / (1.0 + np.diff(A.indptr))
    inv = inv.reshape((-1,) + (1,) * (x.ndim - 1))
    for _ in range(int(iterations)):
        x = (x + A @ x) * inv
    return x


def vector_colors(vector: np.ndarray, scale: float | None = None) -> np.ndarray:
    """(V, 3) RGB in [0, 1] for the vector view: x, y, z → R, G, B, ``0.5 + 0.5·v/scale`` (Joshi §2, Fig. 2).

    ``scale`` defaults to the largest component magnitude, so zero maps to mid-grey.
    """
    v = np.asarray(vector, dtype=np.float64)
    s = float(np.abs(v).max()) if scale is None else float(scale)
    if s <= 0:
        return np.full(v.shape, 0.5)
    return np.clip(0.5 + 0.5 * v / s, 0.0, 1.0)
