"""Threshold segmentation of a deformation map (ALGORITHMS.md §3; Joshi et al. 2003, §2).

Labels are (V,) int arrays: ``r ≥ 0`` is the core of region r, ``-1`` (``BACKGROUND``) the background.
Functions take the (V, V) CSR vertex adjacency from ``solvers.laplacian``.
"""
from __future__ import annotations

import math
import threading
import weakref

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError
from .laplacian import sorted_unique
from .parallel import cores, ordered_map

BACKGROUND = -1


# --- threshold ----------------------------------------------------------------------------------------

def validate_threshold_t(t) -> float:
    """The threshold quantile t of Joshi et al. 2003, §2 as a float in [0, 1], or RigInputError."""
    try:
        value = float(t)
    except (TypeError, ValueError):
        raise RigInputError(f"The segmentation threshold must be a number between 0 and 1, not {t!r}.") from None
    if not (0.0 <= value <= 1.0) or math.isnan(value):
        raise RigInputError(f"The segmentation threshold t must lie between 0 and 1; got {value:g}.")
    return value


def quantile_threshold(sorted_values: np.ndarray, t: float) -> float:
    """``threshold = D[⌊n·t⌋]`` with D the map sorted ascending (Joshi et al. 2003, §2; ALGORITHMS.md §3).

    t = 1 uses the last element (nothing lies strictly above it).
    """
    t = validate_threshold_t(t)
    D = np.asarray(sorted_values)
    n = D.size
    if n == 0:
        raise RigInputError("The deformation map is empty: the rig has no vertices.")
    return float(D[min(int(math.floor(n * t)), n - 1)])


def connected_regions(mask: np.ndarray, adjacency: sp.spmatrix) -> np.ndarray:
    """Labels of the connected components of the vertex set ``mask`` on the mesh graph; -1 elsewhere.

    Regions are the components of the deforming set (Joshi et al. 2003, §2), numbered by smallest vertex.
    """
    mask = np.asarray(mask, dtype=bool)
    labels = np.full(mask.size, BACKGROUND, dtype=np.int64)
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return labels
    A = sp.csr_matrix(adjacency)[idx][:, idx]
    _, comp = sp.csgraph.connected_components(A, directed=False)
    labels[idx] = comp
    return relabel(labels)


def relabel(labels: np.ndarray) -> np.ndarray:
    """Renumber region labels 0..R-1 by each region's smallest vertex index; -1 stays (ALGORITHMS.md §3)."""
    labels = np.asarray(labels, dtype=np.int64)
    out = np.full(labels.size, BACKGROUND, dtype=np.int64)
    fg = labels >= 0
    if not fg.any():
        return out
    uniq, first = np.unique(labels[fg], return_index=True)
    order = np.argsort(first)  # regions ordered by their first (smallest) vertex
    new_of = np.empty(uniq.size, dtype=np.int64)
    new_of[order] = np.arange(uniq.size)
    out[fg] = new_of[np.searchsorted(uniq, labels[fg])]
    return out


def group_sums(values, vertices: np.ndarray, groups: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups, K) ``Σ_{i: groups[i] = g} values[vertices[i], k]`` of a (V, K) per-vertex, per-shape array or a
    ``ShapeSupport``.

    An (n_groups, V) 0/1 indicator times each shape's row of ``values.T`` (the maps are (K, V) arrays handed
    out as (V, K) views: gathering (V, K) rows would walk across them); every sum is taken in the order of
    ``vertices`` from 0, as ``np.add.at`` or ``np.bincount`` over the same vertices takes it."""
    values = values if isinstance(values, ShapeSupport) else np.asarray(values)
    row = _shape_rows(values)
    vertices = np.asarray(vertices, dtype=np.int64)
    g = np.asarray(groups, dtype=np.int64)
    counts = np.bincount(g, minlength=n_groups)
    order = np.argsort(g.astype(np.uint16) if n_groups <= 1 << 16 else g, kind="stable")  # keeps vertex order
    K, V = values.shape[1], values.shape[0]
    ind = sp.csr_matrix((np.ones(g.size), vertices[order], np.concatenate(([0], np.cumsum(counts)))),
                        shape=(n_groups, V))
    out = np.empty((K, n_groups))
    scratch = np.empty(V)
    for k in range(K):
        out[k] = ind @ row(k, scratch)
    return np.ascontiguousarray(out.T)


def _shape_rows(values):
    """``row(k, scratch)``: shape k's (V,) values of a (V, K) array (a view of its (K, V) memory's row) or of a
    ``ShapeSupport`` (computed into ``scratch``)."""
    if isinstance(values, ShapeSupport):
        return values.row
    VT = np.asarray(values).T
    return lambda k, scratch: VT[k]


_ROWS: list = [None, None]  # (weak reference to the last graph's indptr, its rows): a segmentation asks ~12 times


def _rows_cols(adjacency: sp.spmatrix) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of every stored entry of a CSR graph (both directions of each mesh edge), in CSR order.
    The rows depend on ``indptr`` alone and are kept for the last ``indptr`` array asked for (the graphs here
    are never edited in place)."""
    A = sp.csr_matrix(adjacency)
    ref, rows = _ROWS
    if ref is None or ref() is not A.indptr:
        rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
        _ROWS[:] = [weakref.ref(A.indptr), rows]
    return rows, A.indices


# --- clean-up -----------------------------------------------------------------------------------------

def absorb_small_regions(labels: np.ndarray, adjacency: sp.spmatrix, min_size: int) -> np.ndarray:
    """Merge every region with fewer than ``min_size`` vertices into the neighbour it shares most boundary with.

    Joshi et al. 2003, §2 (clean-up, ALGORITHMS.md §3). Boundary = number of mesh edges between the two
    vertex sets; the background counts as a neighbour. An island with no neighbour joins the background.
    A small region whose best neighbour is another small region merges into it only if it is the smaller
    of the two (ties by label), so merges never cycle; rounds repeat until no region is small.
    """
    lab = relabel(labels)
    if min_size <= 1:
        return lab
    rows, cols = _rows_cols(adjacency)
    # merging only joins labels, so the edges between two regions are among those between two labels now
    apart = lab[rows] != lab[cols]
    rows, cols = rows[apart], cols[apart]
    while True:
        R = int(lab.max()) + 1
        if R == 0:
            return lab
        sizes = np.bincount(lab[lab >= 0], minlength=R)
        small = sizes < min_size
        if not small.any():
            return lab
        la, lb = lab[rows], lab[cols]
        cross = (la != lb) & (la >= 0)
        cross &= small[np.where(la >= 0, la, 0)]
        a = la[cross]
        b = np.where(lb[cross] >= 0, lb[cross], R)  # R = background
        C = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(R, R + 1)).toarray()
        target = np.full(R, -2, dtype=np.int64)  # -2: keep
        has = C.sum(axis=1) > 0
        best = C.argmax(axis=1)
        for r in np.flatnonzero(small):
            if not has[r]:
                target[r] = BACKGROUND
                continue
            t = int(best[r])
            if t == R:
                target[r] = BACKGROUND
            elif not small[t] or (sizes[r], r) < (sizes[t], t):
                target[r] = t
        # resolve chains r → t → u within one round
        mapping = np.arange(R, dtype=np.int64)
        for r in np.flatnonzero(target != -2):
            mapping[r] = target[r]
        for _ in range(R):
            nxt = np.where(mapping >= 0, mapping[np.maximum(mapping, 0)], BACKGROUND)
            if np.array_equal(nxt, mapping):
                break
            mapping = nxt
        lab = relabel(np.where(lab >= 0, mapping[np.maximum(lab, 0)], BACKGROUND))


def close_regions(labels: np.ndarray, adjacency: sp.spmatrix, rings: int) -> np.ndarray:
    """Reduce concavity by graph closing: grow ``rings`` rings, then shrink ``rings`` rings.

    Joshi et al. 2003, §2 (clean-up). The closing is taken of the union of all regions (so it also
    bridges narrow background gaps); a vertex it adds takes the label of the nearest region (ring-by-ring
    growth). Closing never removes a vertex from a region.
    """
    lab = np.asarray(labels, dtype=np.int64).copy()
    if rings <= 0 or not (lab >= 0).any():
        return lab
    A = sp.csr_matrix(adjacency)
    rows, cols = _rows_cols(A)
    grown = lab.copy()
    for _ in range(rings):  # dilation with nearest-region labels
        take = (grown[rows] >= 0) & (grown[cols] < 0)
        new = grown.copy()
        new[cols[take]] = grown[rows[take]]
        grown = new
    inside = grown >= 0
    for _ in range(rings):  # erosion of the dilated union
        outside_nbr = (A @ (~inside).astype(np.float64)) > 0
        inside = inside & ~outside_nbr
    add = inside & (lab < 0)
    lab[add] = grown[add]
    return lab


def fill_background_holes(labels: np.ndarray, adjacency: sp.spmatrix) -> np.ndarray:
    """Fill background holes inside a region (Joshi et al. 2003, §2 clean-up).

    A hole is a connected piece of background whose every region neighbour is one region r, that is
    smaller than r's core and is not the largest piece of background; it joins r.
    """
    lab = np.asarray(labels, dtype=np.int64).copy()
    bg = np.flatnonzero(lab < 0)
    if bg.size == 0 or bg.size == lab.size:
        return lab
    A = sp.csr_matrix(adjacency)
    ncomp, comp = sp.csgraph.connected_components(A[bg][:, bg], directed=False)
    comp_of = np.full(lab.size, -1, dtype=np.int64)
    comp_of[bg] = comp
    csize = np.bincount(comp, minlength=ncomp)
    rows, cols = _rows_cols(A)
    m = (comp_of[rows] >= 0) & (lab[cols] >= 0)
    R1 = int(lab.max()) + 1
    key = sorted_unique(comp_of[rows[m]] * R1 + lab[cols[m]])  # (piece, region) pairs, sorted
    if key.size == 0:
        return lab
    pairs = np.stack(np.divmod(key, R1), axis=1)
    n_nbr = np.bincount(pairs[:, 0], minlength=ncomp)
    region_of = np.full(ncomp, -1, dtype=np.int64)
    region_of[pairs[:, 0]] = pairs[:, 1]
    rsize = np.bincount(lab[lab >= 0])
    largest = int(csize.argmax())
    fill = (n_nbr == 1) & (np.arange(ncomp) != largest)
    fill &= csize < rsize[np.maximum(region_of, 0)]
    hit = fill[comp_of[bg]]
    lab[bg[hit]] = region_of[comp_of[bg[hit]]]
    return lab


def clean_up(labels: np.ndarray, adjacency: sp.spmatrix, *, min_size: int, concavity_rings: int) -> np.ndarray:
    """Clean-up of ALGORITHMS.md §3 (Joshi et al. 2003, §2), in this order: absorb islands smaller than
    ``min_size``; closing by ``concavity_rings``; fill background holes; absorb again. Relabelled 0..R-1."""
    lab = absorb_small_regions(labels, adjacency, min_size)
    lab = close_regions(lab, adjacency, concavity_rings)
    lab = fill_background_holes(lab, adjacency)
    return absorb_small_regions(lab, adjacency, min_size)


def threshold_labels(values: np.ndarray, adjacency: sp.spmatrix, t: float, *,
                     sorted_values: np.ndarray | None = None, domain: np.ndarray | None = None,
                     split: sp.spmatrix | None = None) -> tuple[np.ndarray, float]:
    """Raw threshold segmentation (Joshi et al. 2003, §2): ``threshold = D[⌊n·t⌋]``, deforming = M > threshold,
    regions = connected components of the deforming set. Returns (labels, threshold).

    ``domain`` (V,) bool: the quantile is taken over these vertices only (the skin that moves) and only they
    can deform; ``sorted_values`` must then be the sorted values on the domain. ``split``: the graph the
    components are taken on (``split_graph``: the mesh cut where the dominant shape group changes)."""
    values = np.asarray(values, dtype=np.float64)
    if sorted_values is not None:
        D = sorted_values
    else:
        D = np.sort(values if domain is None else values[domain])
    thr = quantile_threshold(D, t)
    deforming = values > thr
    if domain is not None:
        deforming &= domain
    return connected_regions(deforming, adjacency if split is None else split), thr


# --- the surface, its separate meshes, and the shapes that move it ------------------------------------

def mesh_pieces(adjacency: sp.spmatrix, main_fraction: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """(piece, main): the connected component of every vertex, and which vertices lie on the main surface
    (the largest piece and any piece at least ``main_fraction`` of its size). The other pieces are the rig's
    separate meshes (eyeballs, teeth, tongue, eyelashes in ICT FaceKit)."""
    _, piece = sp.csgraph.connected_components(sp.csr_matrix(adjacency), directed=False)
    sizes = np.bincount(piece)
    main = sizes[piece] >= main_fraction * sizes.max()
    return piece.astype(np.int64), main


class ShapeSupport:
    """(V, K) where each shape acts, ``min(‖d_k(v)‖ / s_k, 1)``: its displacement over its own scale (the 99%
    quantile over the vertices it moves), at most 1. Read a shape's row at a time (``row``) from the
    per-shape displacement maps and never held whole: on a 422k-vertex rig of 228 shapes the (V, K) array was
    0.77 GB of new memory (seconds on a machine that backs new memory lazily), for four readers that each go
    through it shape by shape (``group_sums``, ``dominant_group``) or in blocks of vertices (``gram``).
    ``np.asarray(support)`` gives the whole array (the same values)."""

    def __init__(self, per_shape_displacement: np.ndarray, scales: np.ndarray) -> None:
        self._DT = np.asarray(per_shape_displacement).T         # the maps' (K, V) rows
        self._scales = np.asarray(scales, dtype=np.float64)
        self.shape = (self._DT.shape[1], self._DT.shape[0])
        self.dtype = np.dtype(np.float64)

    @staticmethod
    def _into(displacement: np.ndarray, scales, out: np.ndarray) -> np.ndarray:
        """``out = min(displacement / scales, 1)``: the support's one formula, for a row or a block of rows."""
        np.divide(displacement, scales, out=out)
        np.minimum(out, 1.0, out=out)
        return out

    def row(self, k: int, out: np.ndarray | None = None) -> np.ndarray:
        """(V,) shape k's support (into ``out``)."""
        return self._into(self._DT[k], self._scales[k], np.empty(self.shape[0]) if out is None else out)

    def gram(self, block: int = 1 << 14, threads: int | None = None) -> np.ndarray:
        """(K, K) ``SᵀS``, summed over blocks of ``block`` vertices in their order (one (K, block) scratch a
        thread, no (V, K) array). From 2³⁰ multiply-adds on (a 106k-vertex rig of 228 shapes has 5·10⁹; 0.9 s
        at 422k on one core) the blocks' products are made on the machine's cores (``threads``) and added here in
        the same order: the same sums to the bit on any number of threads."""
        K, V = self._DT.shape
        G = np.zeros((K, K))
        local = threading.local()

        def product(a: int) -> np.ndarray:
            if not hasattr(local, "scratch"):
                local.scratch = np.empty((K, min(block, V)))
            S = self._into(self._DT[:, a:a + block], self._scales[:, None], local.scratch[:, :min(block, V - a)])
            return S @ S.T
        n = threads or (cores() if K * K * V >= 1 << 30 else 1)
        for P in ordered_map(product, range(0, V, block), threads=n):
            G += P
        return G

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        o = np.empty(self.shape[::-1])
        for k in range(self.shape[1]):
            self.row(k, o[k])
        return o.T if dtype is None else o.T.astype(dtype)


def shape_groups(support: np.ndarray, cut: float = 0.6) -> np.ndarray:
    """(K,) group of every shape: shapes that act on the same part of the face (average-linkage clustering
    of the cosine distance between their (V,) support maps, cut at ``cut``), e.g. a brow's three shapes, an
    eye's lid and gaze shapes, one side of the mouth. Shapes that move nothing form one group each.
    The cosines come from the (K, K) Gram matrix ``G = SᵀS`` of the support as it is, ``G_ij / (n_i n_j)`` with
    ``n_i = √G_ii``: products along the maps' (K, V) rows (in blocks of vertices for a ``ShapeSupport``), no
    normalised (V, K) copy (190 MB on a 422k-vertex rig) and no second pass for the norms."""
    from scipy.cluster.hierarchy import fcluster, linkage
    support = support if isinstance(support, ShapeSupport) else np.asarray(support, dtype=np.float64)
    K = support.shape[1]
    if K == 1:
        return np.zeros(1, dtype=np.int64)
    if isinstance(support, ShapeSupport):
        G = support.gram()
    else:
        G = support.T @ support
    n = np.sqrt(np.diag(G).copy())
    scale = np.where(n > 0, n, 1.0)
    D = np.clip(1.0 - G / scale[:, None] / scale[None, :], 0.0, 2.0)
    D[n == 0, :] = D[:, n == 0] = 1.0
    np.fill_diagonal(D, 0.0)
    Z = linkage(D[np.triu_indices(K, 1)], method="average")
    return (fcluster(Z, cut, criterion="distance") - 1).astype(np.int64)


def dominant_group(support: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """(V,) the shape group with the largest support at each vertex (``max_{k∈g} support(v, k)``); ``support`` a
    (V, K) array or a ``ShapeSupport``."""
    support = support if isinstance(support, ShapeSupport) else np.asarray(support)
    row = _shape_rows(support)   # the shapes' rows: a running maximum, no (V, |g|) copies
    G = int(groups.max()) + 1
    V = support.shape[0]
    best = np.full(V, -1.0)
    out = np.zeros(V, dtype=np.int64)
    m, scratch = np.empty(V), np.empty(V)
    better = np.empty(V, dtype=bool)
    for g in range(G):
        ks = np.flatnonzero(groups == g)
        np.copyto(m, row(ks[0], scratch))
        for k in ks[1:]:
            np.maximum(m, row(k, scratch), out=m)
        np.greater(m, best, out=better)
        np.copyto(best, m, where=better)
        np.copyto(out, g, where=better)
    return out


def split_graph(adjacency: sp.spmatrix, dominant: np.ndarray) -> sp.csr_matrix:
    """The mesh graph without the edges whose ends are dominated by different shape groups: its components
    within the deforming set are regions that one group of shapes moves (a brow, an eye, a mouth side)."""
    A = sp.csr_matrix(adjacency)
    rows, cols = _rows_cols(A)
    keep = dominant[rows] == dominant[cols]
    indptr = np.concatenate(([0], np.cumsum(np.bincount(rows[keep], minlength=A.shape[0]))))
    return sp.csr_matrix((A.data[keep], cols[keep], indptr), shape=A.shape)


def attach_separate_meshes(labels: np.ndarray, piece: np.ndarray, main: np.ndarray, support: np.ndarray,
                           min_similarity: float = 0.3) -> np.ndarray:
    """Give every separate mesh (a piece off the main surface) to the region of the skin that carries it.

    A piece follows the region whose shape activity (``Σ_{v∈core} support(v, k)``, per shape) is most like
    its own (cosine ≥ ``min_similarity``): the lower teeth follow the jaw, an eyeball its eye. A piece no
    shape moves, or none like any region, stays in the background. Nothing is joined by proximity."""
    lab = np.asarray(labels, dtype=np.int64).copy()
    off = np.flatnonzero(~main)
    lab[off] = BACKGROUND
    R = int(lab.max()) + 1 if (lab >= 0).any() else 0
    if R == 0 or off.size == 0:
        return lab
    fg = np.flatnonzero(lab >= 0)
    ids, pid = np.unique(piece[off], return_inverse=True)
    # (R, K) per region and (P, K) per piece in one pass over the shapes (each sum in its own vertices' order)
    both = group_sums(support, np.concatenate((fg, off)), np.concatenate((lab[fg], R + pid)), R + ids.size)
    act, pact = both[:R], both[R:]
    act /= np.maximum(np.linalg.norm(act, axis=1, keepdims=True), 1e-300)
    norm = np.linalg.norm(pact, axis=1)
    sim = (pact / np.maximum(norm, 1e-300)[:, None]) @ act.T
    best = sim.argmax(axis=1)
    ok = (norm > 0) & (sim[np.arange(ids.size), best] >= min_similarity)
    lab[off] = np.where(ok, best, BACKGROUND)[pid]
    return lab


# --- overlap and blending -----------------------------------------------------------------------------

def region_cores(labels: np.ndarray) -> list[np.ndarray]:
    """Sorted core vertex indices of each region 0..R-1 of a label array (ALGORITHMS.md §3)."""
    labels = np.asarray(labels)
    fg = np.flatnonzero(labels >= 0)
    if fg.size == 0:
        return []
    lab = labels[fg]
    counts = np.bincount(lab)
    order = fg[np.argsort(lab.astype(np.uint16) if counts.size <= 1 << 16 else lab, kind="stable")]  # radix
    return [c.copy() for c in np.split(order, np.cumsum(counts)[:-1])]  # each ascending: fg is, the sort stable


def _blend_matrix(own: np.ndarray, ring_keys: list[np.ndarray], weight: np.ndarray, M: int) -> sp.csr_matrix:
    """The (V, M) partition of unity of ``overlap_and_blend``: each vertex's own entry (its core's column, or the
    background's, ``own``) with raw weight 1, and the ring pairs ``ring_keys`` (keys ``(v·M + c)·C + d``, sorted
    within each ring) with raw weight ``weight[d]``; each row divided by its sum, columns in order. Few vertices
    are in a ring (2% of a 422k-vertex rig's at the finest level), so the ring entries are placed among the V own
    ones, which fill the places left in vertex order, and only the ring vertices' rows are summed: a handful of
    passes over the vertices, none of them a sort, a cumulative sum or a scattered write (each several times a
    plain pass on V entries)."""
    V, C = own.size, weight.size
    ring = np.sort(np.concatenate(ring_keys), kind="stable") if ring_keys else np.zeros(0, np.int64)  # merges
    pair, d = np.divmod(ring, C)
    rv, rc = np.divmod(pair, M)
    rw = weight[d]
    n = ring.size
    starts = np.flatnonzero(np.diff(rv, prepend=-1))   # each ring vertex's first entry (rv is sorted)
    u, cnt = rv[starts], np.diff(np.append(starts, n))
    grp = np.repeat(np.arange(u.size), cnt)             # each ring entry's ring vertex, numbered
    # row v starts after the v own entries and the ring entries of the rows before it: a step up after each ring row
    index = np.int32 if V + n < np.iinfo(np.int32).max else np.int64   # scipy's own choice (it would convert)
    indptr = np.arange(V + 1, dtype=index)
    indptr += np.repeat(np.append(0, np.cumsum(cnt)).astype(index), np.diff(np.concatenate(([0], u + 1, [V + 1]))))
    own_first = own[rv] < rc                            # the row's own entry comes before this ring entry
    ring_pos = np.arange(n) + rv + own_first
    own_pos = indptr[u + 1] - 1 - np.bincount(grp[own_first], minlength=u.size)   # the ring rows' own entries
    # the ring rows' sums, the own entry's raw weight 1 added last (with one ring, halves: the same in any order)
    s = np.bincount(grp, weights=rw, minlength=u.size) + 1.0
    free = np.ones(V + n, bool)
    free[ring_pos] = False
    indices = np.empty(V + n, index)
    indices[free] = own
    indices[ring_pos] = rc
    data = np.ones(V + n)                               # a row without ring entries: its own entry alone, 1
    data[own_pos] = 1.0 / s
    data[ring_pos] = rw / s[grp]
    W = sp.csr_matrix((data, indices, indptr), shape=(V, M))
    W.has_sorted_indices = True
    return W


def leaving_edges(labels: np.ndarray, adjacency: sp.spmatrix,
                  edges: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the directed mesh edges that leave a region's core (from a core vertex to a vertex not
    in that core), among ``edges`` (default: all of the graph's). Those of a coarser level of a hierarchy are
    among those of a finer one (merging regions only removes boundaries), so the finest level's edges can be
    handed to ``overlap_and_blend`` for every level."""
    labels = np.asarray(labels, dtype=np.int64)
    rows, cols = _rows_cols(adjacency) if edges is None else edges
    lr = labels[rows]
    leave = (lr >= 0) & (lr != labels[cols])
    return rows[leave], cols[leave]


def overlap_and_blend(labels: np.ndarray, adjacency: sp.spmatrix, rings: int,
                      edges: tuple[np.ndarray, np.ndarray] | None = None
                      ) -> tuple[list[np.ndarray], list[np.ndarray], sp.csr_matrix]:
    """Grow every region by ``rings`` rings and build partition-of-unity blend weights (ALGORITHMS.md §3).

    Joshi et al. 2003, §2–4: regions overlap by one ring [default] and a partition of unity
    ``φ_r(v)``, ``Σ_r φ_r(v) = 1``, joins their results. Raw weights: 1 on a region's core, the linear ramp
    ``(rings + 1 − d)/(rings + 1)`` at ring distance d in its overlap, 1 on the background for background
    vertices; each row is divided by its sum. Returns (cores, vertices, blend) with ``vertices`` = core ∪
    overlap (sorted) and ``blend`` (V, R+1) CSR whose last column is the background. ``edges``: directed mesh
    edges that include every edge leaving a core (``leaving_edges`` of a finer level); default all edges.
    """
    labels = np.asarray(labels, dtype=np.int64)
    if rings < 0:
        raise RigInputError(f"The overlap must be zero or more rings; got {rings}.")
    A = sp.csr_matrix(adjacency)
    cores = region_cores(labels)
    R = len(cores)
    M = R + 1  # a (vertex, column) pair as one key v·M + c, so that sorted keys are CSR order; column R = background
    C = rings + 1  # a ring pair's key with its ring distance d in the low digit
    in_core = labels >= 0
    ring_keys, ring_pairs = [], []       # each ring's pairs (sorted), with and without d
    weight = np.ones(C)
    # ring 1 of every region at once: the far ends of the mesh edges that leave its core; ring d: the neighbours
    # of ring d-1 in neither the region's core (a vertex's label) nor a ring before (a few pairs: a search)
    rows, cols = leaving_edges(labels, A, edges)
    new = sorted_unique(cols * M + labels[rows])
    deg = np.diff(A.indptr)
    for d in range(1, rings + 1):
        if d > 1:
            v, r = np.divmod(new, M)
            n = deg[v]
            first = np.repeat(A.indptr[v] - (np.cumsum(n) - n), n) + np.arange(int(n.sum()))
            cand = sorted_unique(A.indices[first] * M + np.repeat(r, n))
            cand = cand[labels[cand // M] != cand % M]
            before = np.sort(np.concatenate(ring_pairs))
            pos = np.minimum(np.searchsorted(before, cand), before.size - 1)
            new = cand[before[pos] != cand]
        if new.size == 0:
            break
        ring_keys.append(new * C + d)
        ring_pairs.append(new)
        weight[d] = (rings + 1.0 - d) / (rings + 1.0)
    W = _blend_matrix(np.where(in_core, labels, R), ring_keys, weight, M)
    # each region's core and overlap vertices, sorted: its core merged with its ring vertices (few)
    pairs = np.concatenate(ring_pairs) if ring_pairs else np.zeros(0, np.int64)
    v, r = np.divmod(pairs, M)
    order = np.lexsort((v, r))
    ring_of = np.split(v[order], np.cumsum(np.bincount(r, minlength=R))[:-1]) if R else []
    verts = [np.sort(np.concatenate((c, g)), kind="stable") if g.size else c.copy() for c, g in zip(cores, ring_of)]
    return cores, verts, W


# --- statistics ---------------------------------------------------------------------------------------

def region_shape_activity(per_shape: np.ndarray, cores: list[np.ndarray]) -> np.ndarray:
    """(R, K) activity of each shape in each region: ``Σ_{v∈core} m_k(v)`` (Joshi et al. 2003, §2 maps), summed
    in each core's vertex order along the shapes' rows (``group_sums``): a core's (n, K) gather walked across the
    maps' (K, V) rows, 0.5 GB of new memory a level on a 422k-vertex rig of 228 shapes."""
    P = np.asarray(per_shape)
    if not cores:
        return np.zeros((0, P.shape[1]))
    vertices = np.concatenate(cores)
    groups = np.repeat(np.arange(len(cores)), [c.size for c in cores])
    return group_sums(P, vertices, groups, len(cores))


def most_active_shapes(activity: np.ndarray, shape_names: list[str], n: int = 5,
                       min_share: float = 0.005) -> list[list[tuple[str, float]]]:
    """Per region, up to ``n`` shapes with the largest activity ``Σ_core m_k`` (Joshi et al. 2003, §2), as
    (name, share of the region's total); shapes below ``min_share`` of it are left out (a region one shape
    drives lists that shape alone, not four more at 0%), the first is always kept."""
    out = []
    for row in np.asarray(activity):
        total = float(row.sum())
        top = np.argsort(-row, kind="stable")[:n]
        shares = [(shape_names[k], float(row[k] / total) if total > 0 else 0.0) for k in top]
        out.append(shares[:1] + [x for x in shares[1:] if x[1] >= min_share])
    return out
