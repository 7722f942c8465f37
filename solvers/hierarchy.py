"""Region hierarchy (ALGORITHMS.md §3; Joshi et al. 2003, §4).

Level 0 is the finest segmentation; each higher level merges contiguous regions until the top level is
one region (plus the background), which is the global solve.

Merge rule. Every vertex is given to its nearest region core by graph distance (a graph-Voronoi
partition, one multi-source Dijkstra on the unweighted mesh graph). Two regions are *contiguous* when
their cells meet. For such a pair, ``gap`` is the graph distance between their cores (1 when the cores
touch; min over cell-boundary edges (i, j) of d(i) + 1 + d(j)) and ``boundary`` is the number of mesh edges
between the two cells that lie on a path at most ``gap + 2`` long (the length of the front where they are
close). Clusters inherit the smallest gap of their member pairs and the summed boundary of the pairs at
that gap. Merges go by smaller gap first, then largest shared boundary, then smaller label; within one
pass each cluster merges at most once (a greedy matching), and passes repeat until the level's target
count is reached. Regions whose cells never meet (separate mesh pieces) are merged last, closest
centroids first, so the top level is always one region.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError
from .mesh import extent
from .segmentation import _rows_cols, group_sums


def level_targets(n_regions: int, levels: int | None = None) -> list[int]:
    """Region count of each level, strictly decreasing from ``n_regions`` to 1 (Joshi et al. 2003, §4).

    ``levels=None`` halves the count per level (⌈R/2⌉, ⌈R/4⌉, …, 1). A given ``levels`` N spaces the counts
    geometrically, ``R^(1 − i/(N−1))``; N is capped at R (one merge per level) since every level must have
    strictly fewer regions than the one below. ``levels=1`` keeps only level 0.
    """
    R = int(n_regions)
    if R <= 0:
        return []
    if levels is not None:
        if int(levels) < 1:
            raise RigInputError(f"The hierarchy needs at least one level; got {levels}.")
        N = min(int(levels), R)
        if N == 1:
            return [R]
        out = [R]
        for i in range(1, N):
            want = int(round(R ** (1.0 - i / (N - 1))))
            want = max(min(want, out[-1] - 1), N - i)  # strictly decreasing, room for the levels above
            out.append(want)
        return out
    out = [R]
    while out[-1] > 1:
        out.append(int(math.ceil(out[-1] / 2)))
    return out


def region_contacts(labels: np.ndarray, adjacency: sp.spmatrix) -> tuple[np.ndarray, np.ndarray]:
    """Contiguity of regions for the merge rule of Joshi et al. 2003, §4 (see the module doc).

    (R, R) ``gap`` (graph distance between cores, inf if the graph-Voronoi cells never meet) and
    ``boundary`` (mesh edges between the two cells within ``gap + 2`` hops) of every region pair."""
    labels = np.asarray(labels, dtype=np.int64)
    R = int(labels.max()) + 1 if (labels >= 0).any() else 0
    gap = np.full((R, R), np.inf)
    bnd = np.zeros((R, R))
    if R < 2:
        return gap, bnd
    A = sp.csr_matrix(adjacency)
    src = np.flatnonzero(labels >= 0)
    # A is symmetric: its directed traversal is the undirected one (scipy's undirected mode scans each edge twice
    # more, through a transposed copy, and changes nothing: a second relaxation at the same distance never wins)
    dist, _, sources = sp.csgraph.dijkstra(A, directed=True, indices=src, unweighted=True,
                                        min_only=True, return_predecessors=True)
    cell = np.where(sources >= 0, labels[np.maximum(sources, 0)], -1)
    rows, cols = _rows_cols(A)
    m = (rows < cols) & (cell[rows] >= 0) & (cell[cols] >= 0) & (cell[rows] != cell[cols])
    i, j = rows[m], cols[m]
    a, b = cell[i], cell[j]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    length = dist[i] + dist[j] + 1.0
    np.minimum.at(gap, (lo, hi), length)
    near = length <= gap[lo, hi] + 2.0
    np.add.at(bnd, (lo[near], hi[near]), 1.0)
    gap = np.minimum(gap, gap.T)
    bnd = bnd + bnd.T
    return gap, bnd


def mirror_partners(positions: np.ndarray, per_shape_displacement: np.ndarray,
                    tolerance: float = 0.05) -> np.ndarray:
    """(K,) each shape's mirror partner across x = 0 (itself if none): the shape whose displacement-weighted
    centre ``Σ_v ‖d_k(v)‖ x_v / Σ_v ‖d_k(v)‖`` is the reflection of this one's, within ``tolerance`` of the
    rig's size, found both ways. From the geometry alone, so it needs no naming convention."""
    X = np.asarray(positions, dtype=np.float64)
    D = np.asarray(per_shape_displacement, dtype=np.float64)
    K = D.shape[1]
    w = D.sum(axis=0)
    c = (D.T @ X) / np.where(w > 0, w, 1.0)[:, None]
    size = extent(X) or 1.0
    refl = c * np.array([-1.0, 1.0, 1.0])
    dist = np.linalg.norm(refl[:, None, :] - c[None, :, :], axis=2)
    dist[w == 0, :] = np.inf
    dist[:, w == 0] = np.inf
    best = np.argmin(dist, axis=1)
    ok = (dist[np.arange(K), best] < tolerance * size) & (best[best] == np.arange(K))
    return np.where(ok, best, np.arange(K))


def region_activity(labels: np.ndarray, support: np.ndarray, partners: np.ndarray | None = None) -> np.ndarray:
    """(R, K) how much each shape moves each region, ``Σ_{v∈core r} support(v, k)``; with ``partners`` a shape
    and its mirror partner count as one (they fire together in symmetric expressions), so the two brows,
    moved by browInnerUp_L and browInnerUp_R, move together."""
    lab = np.asarray(labels, dtype=np.int64)
    R = int(lab.max()) + 1 if (lab >= 0).any() else 0
    fg = np.flatnonzero(lab >= 0)
    act = group_sums(support, fg, lab[fg], R)
    if partners is not None:
        act = act + act[:, partners]
    return act


def region_mirrors(labels: np.ndarray, mirror: np.ndarray) -> np.ndarray:
    """(R,) each region's mirror-image region (itself for a region on the midline), -1 if it has none: the
    region holding most of the mirror vertices (``solvers.symmetry.mirror_map``) of its core, both ways.
    Only the core vertices' entries of ``mirror`` are read."""
    lab = np.asarray(labels, dtype=np.int64)
    R = int(lab.max()) + 1 if (lab >= 0).any() else 0
    fg = np.flatnonzero(lab >= 0)
    other = lab[np.asarray(mirror)[fg]]
    ok = other >= 0
    votes = np.zeros((R, R + 1))
    np.add.at(votes, (lab[fg][ok], other[ok]), 1.0)
    sizes = np.bincount(lab[fg], minlength=R)
    best = votes[:, :R].argmax(axis=1) if R else np.zeros(0, dtype=np.int64)
    good = votes[np.arange(R), best] >= 0.5 * sizes
    out = np.where(good, best, -1)
    mutual = (out >= 0) & (out[np.maximum(out, 0)] == np.arange(R))
    return np.where(mutual, out, -1)


def merge_clusters(labels: np.ndarray, adjacency: sp.spmatrix, positions: np.ndarray,
                   levels: int | None = None, activity: np.ndarray | None = None,
                   mirrors: np.ndarray | None = None) -> list[np.ndarray]:
    """Cluster id of each level-0 region for every level (Joshi et al. 2003, §4; rule in the module doc).

    With ``activity`` (R, K) (``region_activity``), contiguous clusters that move together merge first: pairs
    whose cores come within the smaller cluster's radius (``sqrt(size/π)`` rings) of each other go first, by
    the cosine similarity of their summed activity (shape co-activation), then the rule above.
    With ``mirrors`` (R,) (``region_mirrors``) and the default halving levels, a merge and its mirror image
    are made together, so a symmetric face keeps a symmetric hierarchy; a level may then hold one region
    fewer than half of the level below (⌈n/2⌉ − 1), and a merge that has no mirror image partner left is
    made alone only when nothing else can merge.
    Returns a list of (R,) int arrays, level 0 first (the identity), the last all zeros (one region).
    """
    labels = np.asarray(labels, dtype=np.int64)
    R = int(labels.max()) + 1 if (labels >= 0).any() else 0
    targets = level_targets(R, levels)
    if not targets:
        return []
    paired = mirrors is not None and levels is None
    gap, bnd = region_contacts(labels, adjacency)
    P = np.asarray(positions, dtype=np.float64)
    fg = labels >= 0
    sizes = np.bincount(labels[fg], minlength=R).astype(np.float64)
    sums = np.stack([np.bincount(labels[fg], weights=P[fg, c], minlength=R) for c in range(3)], axis=1)
    cluster = np.arange(R)
    out = [cluster.copy()]
    ii, jj = np.triu_indices(R, 1)
    level_index = 1
    while True:
        n_now = np.unique(cluster).size
        if n_now <= 1:
            break
        if paired:
            target, floor = int(math.ceil(n_now / 2)), max(int(math.ceil(n_now / 2)) - 1, 1)
        else:
            if level_index >= len(targets):
                break
            target = floor = targets[level_index]
        level_index += 1
        while True:
            uniq, cluster = np.unique(cluster, return_inverse=True)
            n = uniq.size
            if n <= target:
                break
            ci, cj = cluster[ii], cluster[jj]
            lo, hi = np.minimum(ci, cj), np.maximum(ci, cj)
            keep = lo != hi
            cg = np.full((n, n), np.inf)
            np.minimum.at(cg, (lo[keep], hi[keep]), gap[ii[keep], jj[keep]])
            at_min = keep & (gap[ii, jj] == cg[lo, hi]) & np.isfinite(gap[ii, jj])
            cb = np.zeros((n, n))
            np.add.at(cb, (lo[at_min], hi[at_min]), bnd[ii[at_min], jj[at_min]])
            pa, pb = np.triu_indices(n, 1)
            g = cg[pa, pb]
            finite = np.isfinite(g)
            if finite.any():
                pa, pb, g, b = pa[finite], pb[finite], g[finite], cb[pa[finite], pb[finite]]
                if activity is None:
                    order = np.lexsort((pb, pa, -b, g))
                else:
                    ca = np.zeros((n, activity.shape[1]))
                    np.add.at(ca, cluster, activity)
                    ca /= np.maximum(np.linalg.norm(ca, axis=1, keepdims=True), 1e-300)
                    sim = np.round(np.einsum("ij,ij->i", ca[pa], ca[pb]), 2)  # ties go to the rule above
                    # near: the cores come within the smaller cluster's radius (in rings) of each other
                    csz = np.bincount(cluster, weights=sizes, minlength=n)
                    near = g <= np.sqrt(np.minimum(csz[pa], csz[pb]) / np.pi)
                    order = np.lexsort((pb, pa, -b, g, -sim, ~near))
                pairs = list(zip(pa[order], pb[order]))
            else:  # no contiguous pair left: closest centroids (separate mesh pieces)
                csum = np.zeros((n, 3))
                np.add.at(csum, cluster, sums)
                csz = np.bincount(cluster, weights=sizes, minlength=n)
                cen = csum / csz[:, None]
                dd = np.linalg.norm(cen[pa] - cen[pb], axis=1)
                k = int(np.argmin(dd))
                pairs = [(pa[k], pb[k])]
            cmirror = _cluster_mirrors(cluster, mirrors, n) if paired else None
            used = np.zeros(n, dtype=bool)
            merge_to = np.arange(n)
            count = n
            for a, b in pairs:
                if count <= target:
                    break
                if used[a] or used[b]:
                    continue
                groups = [{int(a), int(b)}]
                if cmirror is not None:
                    ma, mb = int(cmirror[a]), int(cmirror[b])
                    if ma >= 0 and mb >= 0:
                        # the merge and its mirror image together: two merges, or one of three clusters
                        # when they share one (a region on the midline between two mirror images)
                        if ma != mb and not np.isfinite(cg[min(ma, mb), max(ma, mb)]):
                            continue
                        if {ma, mb} & groups[0]:
                            groups[0] |= {ma, mb}
                        else:
                            groups.append({ma, mb})
                members = set().union(*groups)
                merges = sum(len(gr) - 1 for gr in groups)
                if any(used[c] for c in members) or count - merges < floor:
                    continue  # its mirror image cannot merge with it now: leave it for later
                for gr in groups:
                    root = min(gr)
                    for c in gr:
                        used[c] = True
                        merge_to[c] = root
                count -= merges
            if count == n:  # nothing could merge in mirror pairs: the best pair alone
                a, b = pairs[0]
                merge_to[max(a, b)] = min(a, b)
            cluster = merge_to[cluster]
        _, cluster = np.unique(cluster, return_inverse=True)
        out.append(cluster.copy())
    return out


def _cluster_mirrors(cluster: np.ndarray, mirrors: np.ndarray, n: int) -> np.ndarray:
    """(n,) the mirror-image cluster of each cluster (the clusters of its regions' mirrors, if one), else -1."""
    out = np.full(n, -1, dtype=np.int64)
    for c in range(n):
        members = np.flatnonzero(cluster == c)
        m = mirrors[members]
        if (m >= 0).all():
            targets = np.unique(cluster[m])
            if targets.size == 1:
                out[c] = targets[0]
    return out


def hierarchy_labels(labels: np.ndarray, adjacency: sp.spmatrix, positions: np.ndarray,
                     levels: int | None = None, activity: np.ndarray | None = None,
                     mirrors: np.ndarray | None = None) -> list[np.ndarray]:
    """Per-vertex core labels of every level (level 0 = ``labels``); background (-1) is kept at every level.

    Joshi et al. 2003, §4: each level merges contiguous regions of the level below; the top has one region.
    """
    labels = np.asarray(labels, dtype=np.int64)
    fg = labels >= 0
    out = []
    for cl in merge_clusters(labels, adjacency, positions, levels, activity, mirrors):
        lab = np.full(labels.size, -1, dtype=np.int64)
        lab[fg] = cl[labels[fg]]
        out.append(lab)
    return out
