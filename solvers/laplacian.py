"""Mesh graph and discrete Laplacians on plain arrays (ALGORITHMS.md §2; Joshi et al. 2003, §2).

The mesh is given as polygons (``face_counts`` + flat ``face_indices``, as in ``model.rig.Rig``) or as an
(E, 2) edge list. Everything is built once as ``scipy.sparse`` CSR and reused.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError


def sorted_unique(keys: np.ndarray) -> np.ndarray:
    """The distinct values of a 1-D int array, sorted (sort and mask: numpy's ``np.unique`` is slower here)."""
    k = np.sort(keys)
    return k[np.concatenate(([True], k[1:] != k[:-1]))] if k.size else k


def polygon_edges(face_counts: np.ndarray, face_indices: np.ndarray) -> np.ndarray:
    """(E, 2) unique undirected polygon edges (i < j), sorted; each polygon is closed (last → first).

    The 1-ring graph of Joshi et al. 2003, §2 (ALGORITHMS.md §2).
    """
    counts = np.asarray(face_counts, dtype=np.int64)
    idx = np.asarray(face_indices, dtype=np.int64)
    if int(counts.sum()) != idx.size:
        raise RigInputError("The face list is inconsistent: the polygon sizes do not add up to the indices.")
    if idx.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    nxt = np.arange(idx.size) + 1
    nxt[starts + counts - 1] = starts
    a, b = idx, idx[nxt]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keep = lo != hi
    n = int(hi.max()) + 1
    # deduplicated as the pattern of a sparse (lo, hi) matrix: scipy's conversion to CSR buckets the entries by
    # row in linear time, then sorts each row's few columns and merges repeats (a quarter of the time of sorting
    # all the edges' keys)
    pattern = sp.csr_matrix((np.ones(int(keep.sum()), dtype=np.int8), (lo[keep], hi[keep])), shape=(n, n))
    rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(pattern.indptr))
    return np.stack([rows, pattern.indices.astype(np.int64)], axis=1)


def adjacency_matrix(n_vertices: int, edges: np.ndarray) -> sp.csr_matrix:
    """Symmetric (V, V) 0/1 vertex adjacency (the 1-ring graph N(v) of Joshi et al. 2003, §2) as CSR float64."""
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if e.size and (e.min() < 0 or e.max() >= n_vertices):
        raise RigInputError("An edge refers to a vertex that does not exist.")
    e = e[e[:, 0] != e[:, 1]]
    n = int(n_vertices)
    if e.size and (e[:, 0] < e[:, 1]).all() and (np.diff(e[:, 0] * n + e[:, 1]) > 0).all():
        # distinct edges i < j in sorted order (``polygon_edges``'s): row i's columns are its j > i in order, and
        # the reversed edges (j, i) give row j its i < j in order, so a stable bucketing by row (scipy's linear
        # COO-to-CSR conversion) of the reversed edges followed by the edges is the sorted CSR, nothing to merge
        rows = np.concatenate([e[:, 1], e[:, 0]])
        cols = np.concatenate([e[:, 0], e[:, 1]])
        A = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
        A.has_sorted_indices = True
        return A
    # both directions of every edge as one key row·n + col, sorted and deduplicated: CSR order directly
    key = sorted_unique(np.concatenate([e[:, 0] * n + e[:, 1], e[:, 1] * n + e[:, 0]]))
    rows, cols = np.divmod(key, n)
    indptr = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=n))))
    A = sp.csr_matrix((np.ones(key.size), cols, indptr), shape=(n, n))
    A.has_sorted_indices = True
    return A


def mesh_adjacency(n_vertices: int, face_counts: np.ndarray, face_indices: np.ndarray) -> sp.csr_matrix:
    """Vertex adjacency graph of a polygon mesh: neighbours share a polygon edge (Joshi et al. 2003, §2 N(v))."""
    return adjacency_matrix(n_vertices, polygon_edges(face_counts, face_indices))


def uniform_laplacian(adjacency: sp.spmatrix) -> sp.csr_matrix:
    """Umbrella Laplacian ``L = D⁻¹A − I`` (Joshi et al. 2003, §2; ALGORITHMS.md §2).

    ``(L x)(v) = (1/|N(v)|) Σ_{u∈N(v)} (x(u) − x(v))`` over the 1-ring N(v). Isolated vertices get a zero
    row. The constant vector is in the kernel, so the Laplacian of a translation is exactly zero.
    """
    A = sp.csr_matrix(adjacency, dtype=np.float64)
    n = A.shape[0]
    deg = np.diff(A.indptr)
    inv = np.zeros(n)
    inv[deg > 0] = 1.0 / deg[deg > 0]
    W = sp.csr_matrix((A.data * np.repeat(inv, deg), A.indices, A.indptr), shape=A.shape)
    L = W - sp.diags((deg > 0).astype(np.float64), format="csr")
    L = sp.csr_matrix(L)
    L.sort_indices()
    return L


def cotangent_weights(vertices: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Symmetric (V, V) cotangent weights ``w_ij = (cot α_ij + cot β_ij) / 2`` over a triangle mesh.

    Pinkall & Polthier 1993 / Meyer et al. 2003, the cotangent option of ALGORITHMS.md §2.
    """
    X = np.asarray(vertices, dtype=np.float64)
    T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    n = X.shape[0]
    rows, cols, vals = [], [], []
    for k in range(3):  # the angle at corner k is opposite edge (i, j)
        i, j, o = T[:, (k + 1) % 3], T[:, (k + 2) % 3], T[:, k]
        a, b = X[i] - X[o], X[j] - X[o]
        cross = np.linalg.norm(np.cross(a, b), axis=1)
        dot = np.einsum("ij,ij->i", a, b)
        cot = np.where(cross > 1e-300, dot / np.maximum(cross, 1e-300), 0.0)
        rows += [i, j]
        cols += [j, i]
        vals += [0.5 * cot, 0.5 * cot]
    W = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    W.sum_duplicates()
    W.setdiag(0.0)
    W.eliminate_zeros()
    return W


def cotangent_laplacian(vertices: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Row-normalised cotangent Laplacian ``(L x)(v) = Σ_u w_vu (x(u) − x(v)) / Σ_u w_vu``.

    Cotangent weights (Pinkall & Polthier 1993) in the normalised form of the umbrella operator (Joshi et al.
    2003, §2), so both maps are unitless and comparable. Rows whose weight sum is not positive (degenerate
    or very obtuse neighbourhoods) fall back to the uniform weights, so translations stay in the kernel.
    """
    X = np.asarray(vertices, dtype=np.float64)
    W = cotangent_weights(X, triangles)
    n = X.shape[0]
    s = np.asarray(W.sum(axis=1)).ravel()
    bad = s <= 1e-12
    if bad.any():
        deg = np.diff(W.indptr)
        row_of = np.repeat(np.arange(n), deg)
        W.data = np.where(bad[row_of], 1.0, W.data)
        s = np.asarray(W.sum(axis=1)).ravel()
    deg = np.diff(W.indptr)
    inv = np.zeros(n)
    inv[s > 0] = 1.0 / s[s > 0]
    Wn = sp.csr_matrix((W.data * np.repeat(inv, deg), W.indices, W.indptr), shape=W.shape)
    L = sp.csr_matrix(Wn - sp.diags((s > 0).astype(np.float64), format="csr"))
    L.sort_indices()
    return L


def vertex_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(V,) barycentric vertex areas: a third of the area of every triangle at the vertex, the lumped mass
    matrix of the cotangent Laplacian (Meyer et al. 2003, §3.3). Σ_v A(v) is the surface area, so a sum over
    vertices weighted by A approximates a surface integral whatever the tessellation. Vertices in no triangle
    get 0."""
    X = np.asarray(vertices, dtype=np.float64)
    T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    cross = np.cross(X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]])
    third = np.linalg.norm(cross, axis=1) / 6.0
    return np.bincount(T.ravel(), weights=np.repeat(third, 3), minlength=X.shape[0])


def mesh_laplacian(vertices: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
                   kind: str = "uniform", adjacency: sp.spmatrix | None = None) -> sp.csr_matrix:
    """The mesh Laplacian of ALGORITHMS.md §2 (Joshi et al. 2003, §2): ``kind`` 'uniform' or 'cotangent'."""
    n = int(np.asarray(vertices).shape[0])
    if kind == "uniform":
        A = adjacency if adjacency is not None else mesh_adjacency(n, face_counts, face_indices)
        return uniform_laplacian(A)
    if kind == "cotangent":
        from .mesh import fan_triangulate
        return cotangent_laplacian(vertices, fan_triangulate(face_counts, face_indices))
    raise RigInputError(f"Unknown Laplacian '{kind}': use 'uniform' or 'cotangent'.")
