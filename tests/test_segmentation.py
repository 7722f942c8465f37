"""Segmentation, overlap, blend weights and hierarchy (ALGORITHMS.md §3) on the real ICT rig and the sample."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse import csgraph

from model.errors import RigInputError
from model.segmentation import (Segmentation, SegmentationCache, SegmentationSettings, region_statistics,
                                segment_rig, segmentation_to_json)
from solvers import segmentation as S
from solvers.hierarchy import level_targets
from solvers.region_growing import grow_regions
from solvers.region_nudge import nudge_region, polygon_normals

ICT_FACE = 9409  # vertices 0–9408 are the face skin (data README)
MOUTH_CORNERS = (48, 54)  # iBUG-68 landmark numbers in vertex_indices.json


def run(rig, cache=None, **kw) -> Segmentation:
    return segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas,
                       SegmentationSettings(**kw), cache=cache)


@pytest.fixture(scope="module")
def ict_cache(ict_rig):
    cache = SegmentationCache()    # bound to ICT here, so that a test that asks for the cache alone can run alone
    cache.bind(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, ict_rig.deltas)
    return cache


@pytest.fixture(scope="module")
def ict_seg(ict_rig, ict_cache):
    return run(ict_rig, ict_cache)


@pytest.fixture(scope="module")
def landmarks(ict_dir):
    return json.loads((ict_dir / "vertex_indices.json").read_text())["idx_to_landmark_verts"]


def graph_distance(adjacency, sources):
    return csgraph.dijkstra(adjacency, directed=False, indices=sources, unweighted=True, min_only=True)


def check_partition(seg: Segmentation, n_vertices: int):
    for lvl in seg.levels:
        owner = np.zeros(n_vertices, dtype=int)
        for reg in lvl.regions:
            owner[reg.core] += 1
            assert np.all(np.diff(reg.core) > 0) and np.all(np.diff(reg.vertices) > 0)
            assert np.isin(reg.core, reg.vertices).all()
        owner[lvl.background] += 1
        assert np.all(owner == 1), "every vertex is in exactly one core or the background"


def check_overlap(seg: Segmentation, adjacency, rings: int):
    for lvl in seg.levels:
        for reg in lvl.regions:
            d = graph_distance(adjacency, reg.core)
            expected = np.flatnonzero(d <= rings)
            assert np.array_equal(reg.vertices, expected)
            added = np.setdiff1d(reg.vertices, reg.core)  # empty only for a whole mesh piece (a tooth)
            if added.size:
                assert d[added].min() >= 1 and d[added].max() <= rings


def check_blend(seg: Segmentation, rings: int):
    for lvl in seg.levels:
        W = sp.csr_matrix(lvl.blend)
        V = W.shape[0]
        assert W.shape == (V, lvl.n_regions + 1)
        assert np.abs(np.asarray(W.sum(axis=1)).ravel() - 1.0).max() < 1e-12
        assert W.data.min() > 0 and W.data.max() <= 1.0 + 1e-15
        Wc = W.tocsc()
        for r, reg in enumerate(lvl.regions):
            col = Wc[:, r].toarray().ravel()
            assert np.array_equal(np.flatnonzero(col), reg.vertices), "φ_r lives exactly on the region"
            overlap = np.setdiff1d(reg.vertices, reg.core)
            if overlap.size:  # the weight ramps down from the core into the overlap
                assert col[overlap].max() < 1.0
                assert col[reg.core].mean() > col[overlap].mean()
        bgcol = Wc[:, lvl.n_regions].toarray().ravel()
        assert np.array_equal(np.flatnonzero(bgcol), lvl.background)


# --- threshold ---------------------------------------------------------------------------------------

def test_quantile_threshold_rule():
    D = np.arange(10.0)
    assert S.quantile_threshold(D, 0.0) == 0.0
    assert S.quantile_threshold(D, 0.75) == 7.0  # D[floor(10 · 0.75)]
    assert S.quantile_threshold(D, 1.0) == 9.0
    for bad in (-0.1, 1.5, float("nan"), "high"):
        with pytest.raises(RigInputError, match="between 0 and 1"):
            S.quantile_threshold(D, bad)


def test_split_sits_at_the_requested_quantile_of_the_moving_skin(ict_rig, ict_cache, ict_seg):
    s = SegmentationSettings()
    M, D = ict_cache.values(s.map_kind, s.laplacian, s.normalise, s.smoothing)
    domain = ict_cache.domain()
    # the quantile is over the skin that moves: the main surface, not the skull's still back or the teeth
    _, main = ict_cache.pieces()
    assert domain.sum() < main.sum() < ict_rig.n_vertices
    assert not domain[ict_rig.neutral[:, 2] < -8].any()   # the back of the head does not move
    n = int(domain.sum())
    assert np.array_equal(D, np.sort(M[domain]))
    assert ict_seg.threshold_value == D[math.floor(n * s.t)]
    split = ict_cache.split_graph()
    for t in (0.25, 0.5, 0.75, 0.9):
        labels, thr = S.threshold_labels(M, ict_cache.adjacency, t, sorted_values=D, domain=domain, split=split)
        deforming = labels >= 0
        assert np.array_equal(deforming, (M > thr) & domain)
        assert (~deforming[domain]).sum() >= math.floor(n * t) + 1  # at least the values up to D[⌊n·t⌋]
        assert (M[domain] < thr).sum() <= math.floor(n * t)
        # regions are the connected components of the split graph: no kept edge joins two regions ...
        r, c = split.nonzero()
        both = deforming[r] & deforming[c]
        assert np.all(labels[r[both]] == labels[c[both]])
        # ... and the split only cuts edges between vertices that different shape groups dominate
        cut = (ict_cache.adjacency - split)
        cr, cc = cut.nonzero()
        dom = S.dominant_group(ict_cache.support(), ict_cache.shape_groups())
        assert np.all(dom[cr] != dom[cc])


def test_shape_support_read_shape_by_shape_is_the_whole_array(ict_cache):
    """The support is never held as a (V, K) array: its rows, Gram matrix and region sums are the same numbers as
    those of the whole array ``min(‖d_k(v)‖ / s_k, 1)`` made at once from the maps (rows and sums to the bit)."""
    D = ict_cache.maps().per_shape_displacement
    s = ict_cache.scales("displacement")
    whole = np.minimum(D / s[None, :], 1.0)
    support = ict_cache.support()
    assert support.shape == whole.shape
    assert np.array_equal(np.asarray(support), whole)
    assert np.array_equal(support.row(7), whole[:, 7]) and not np.array_equal(support.row(7), whole[:, 8])
    G = support.gram(block=1000)            # blocks that do not divide V: the last one is partial
    assert np.allclose(G, whole.T @ whole, rtol=1e-12, atol=0)
    assert not np.allclose(G, whole.T @ np.minimum(D, 1.0), rtol=1e-3)   # the scales matter
    for threads in (2, 3):                  # a studio rig's blocks are multiplied on the cores: the same bits
        assert np.array_equal(support.gram(block=1000, threads=threads), G)
    labels = np.arange(whole.shape[0]) % 5
    verts = np.flatnonzero(labels != 3)
    assert np.array_equal(S.group_sums(support, verts, labels[verts], 5), S.group_sums(whole, verts, labels[verts], 5))
    groups = ict_cache.shape_groups()
    assert np.array_equal(S.dominant_group(support, groups), S.dominant_group(whole, groups))


def test_shape_groups_are_the_average_linkage_of_the_support_maps_cosine_distances(ict_rig, ict_seg, ict_cache):
    """The groups from the support's Gram matrix against scipy's own cosine distances (pdist) of its columns,
    clustered the same way; and what a user sees of them on ICT: each brow's three shapes form one group, the
    left and right brows two."""
    from scipy.cluster.hierarchy import fcluster, linkage
    from scipy.spatial.distance import pdist
    support = np.asarray(ict_cache.support())
    assert (np.linalg.norm(support, axis=0) > 0).all()   # ICT: every shape moves something
    expected = fcluster(linkage(pdist(support.T, "cosine"), method="average"), 0.6, criterion="distance") - 1
    groups = ict_cache.shape_groups()
    assert np.array_equal(groups, expected)
    assert not np.array_equal(groups, fcluster(linkage(pdist(support.T, "cosine"), method="average"), 0.4,
                                               criterion="distance") - 1)   # the cut matters
    g = {n: groups[k] for k, n in enumerate(ict_rig.shape_names)}
    assert g["browDown_L"] == g["browOuterUp_L"] and g["browDown_R"] == g["browOuterUp_R"]
    assert g["browDown_L"] != g["browDown_R"]
    assert g["jawOpen"] != g["browDown_L"]


def test_higher_t_gives_fewer_deforming_vertices(ict_cache):
    M = ict_cache.maps().combined
    counts = [(S.threshold_labels(M, ict_cache.adjacency, t)[0] >= 0).sum() for t in (0.25, 0.5, 0.75, 0.9)]
    assert all(a > b for a, b in zip(counts, counts[1:]))


def test_every_vertex_in_background_or_one_core(ict_rig, ict_seg):
    check_partition(ict_seg, ict_rig.n_vertices)


def test_overlap_is_exactly_one_ring_by_default(ict_cache, ict_seg):
    assert ict_seg.overlap_rings == 1
    check_overlap(Segmentation(**{**ict_seg.__dict__, "levels": ict_seg.levels[:2]}), ict_cache.adjacency, 1)


def test_overlap_of_two_rings_and_blend(ict_rig, ict_cache):
    seg = run(ict_rig, ict_cache, overlap_rings=2, t=0.9, levels=3)
    assert len(seg.levels) == 3
    check_overlap(seg, ict_cache.adjacency, 2)
    check_blend(seg, 2)
    check_partition(seg, ict_rig.n_vertices)


def test_blend_weights_are_a_partition_of_unity(ict_seg):
    check_blend(ict_seg, 1)


def test_hierarchy_merges_down_to_one_region(ict_rig, ict_seg):
    counts = [lvl.n_regions for lvl in ict_seg.levels]
    assert counts[0] > 5
    assert all(a > b for a, b in zip(counts, counts[1:]))
    assert counts[-1] == 1
    for a, b in zip(counts, counts[1:]):  # default: about halve per level (mirror-image merges go in pairs)
        assert math.ceil(a / 2) - 1 <= b <= math.ceil(a / 2)
    V = ict_rig.n_vertices
    for lo, hi in zip(ict_seg.levels, ict_seg.levels[1:]):
        assert np.array_equal(lo.background, hi.background)
        up = hi.core_labels(V)
        for reg in lo.regions:  # nested: a region of a level lies inside one region of the next
            assert np.unique(up[reg.core]).size == 1


def test_levels_parameter(ict_rig, ict_cache):
    seg = run(ict_rig, ict_cache, levels=3)
    counts = [lvl.n_regions for lvl in seg.levels]
    assert len(counts) == 3 and counts[-1] == 1 and counts[0] > counts[1] > 1
    assert level_targets(4, 10) == [4, 3, 2, 1]
    with pytest.raises(RigInputError, match="levels"):
        SegmentationSettings(levels=0)


def test_no_region_under_the_minimum_size(ict_rig, ict_cache):
    for size in (30, 200):
        seg = run(ict_rig, ict_cache, min_region_size=size)
        for lvl in seg.levels:
            assert min(r.core.size for r in lvl.regions) >= size
    raw, _ = S.threshold_labels(ict_cache.maps().combined, ict_cache.adjacency, 0.75)
    assert np.bincount(raw[raw >= 0]).min() < 30  # so the clean-up had islands to absorb


def test_clean_up_fills_holes_and_closes_concavities():
    # a triangulated 9×9 grid: a ring-shaped region with a one-vertex hole and a notch
    n = 9
    A = sp.lil_matrix((n * n, n * n))
    for i in range(n):
        for j in range(n):
            if i + 1 < n:
                A[i * n + j, (i + 1) * n + j] = A[(i + 1) * n + j, i * n + j] = 1
            if j + 1 < n:
                A[i * n + j, i * n + j + 1] = A[i * n + j + 1, i * n + j] = 1
            if i + 1 < n and j + 1 < n:  # the diagonal of a triangulated grid
                A[i * n + j, (i + 1) * n + j + 1] = A[(i + 1) * n + j + 1, i * n + j] = 1
    A = A.tocsr()
    lab = -np.ones((n, n), dtype=int)
    lab[2:7, 2:7] = 0
    lab[4, 4] = -1  # hole
    lab[2, 4] = -1  # notch on the border
    out = S.fill_background_holes(lab.ravel(), A).reshape(n, n)
    assert out[4, 4] == 0 and out[2, 4] == -1
    closed = S.close_regions(lab.ravel(), A, 1).reshape(n, n)
    assert closed[2, 4] == 0
    assert (closed[lab >= 0] == 0).all()
    assert (closed[0, :] == -1).all()  # closing does not grow the region outward
    small = S.absorb_small_regions(np.where(np.arange(n * n) == 0, 1, lab.ravel()), A, 5)
    assert small[0] == -1 and (small >= 0).sum() == (lab >= 0).sum()


def test_background_is_the_skull(ict_rig, ict_seg):
    x = ict_rig.neutral
    lab = ict_seg.levels[0].core_labels(ict_rig.n_vertices)
    top, back, neck = int(np.argmax(x[:, 1])), int(np.argmin(x[:, 2])), int(np.argmin(x[:, 1]))
    assert x[back, 2] < -8 and x[top, 1] > 14 and x[neck, 1] < -18
    for v in (top, back, neck):
        assert lab[v] == -1
    bg = set(ict_seg.levels[0].background.tolist())
    skull = np.flatnonzero(x[:, 1] > 10)  # the crown of the head
    assert np.mean([v in bg for v in skull]) > 0.99


# --- the face's parts on the landmarks (ICT FaceKit's Multi-PIE 68 points, and the sample's) ------------

def ict_parts(landmarks) -> dict[str, np.ndarray]:
    """Multi-PIE 68-point landmarks of ICT FaceKit (vertex_indices.json): brows 17–26 (17–21 on the face's
    right, x < 0), eyes 36–47, mouth 48–67."""
    lm = np.asarray(landmarks)
    return {"brow_a": lm[17:22], "brow_b": lm[22:27], "eyes": lm[36:48], "mouth": lm[48:68]}


def sample_parts(rig) -> dict[str, np.ndarray]:
    """Landmarks of the bundled sample face, picked from its geometry and shapes (not from any map):
    each brow is 5 skin vertices evenly along the segment from where browInnerUp moves the skin most to
    where browOuterUp does; each eye its two slit corners and two upper and two lower lid-margin vertices
    evenly along the slit; the mouth its two corners and nine upper and nine lower lip-margin vertices."""
    from resources.sample_rig import sample_geometry
    g = sample_geometry()
    x = rig.neutral
    skin = np.flatnonzero(g.skin)

    def spread(a, n):
        a = np.asarray(a)
        return a[np.round(np.linspace(0, len(a) - 1, n)).astype(int)]

    def peak(name):
        return int(np.argmax(np.linalg.norm(rig.deltas[rig.shape_index(name)], axis=1)))

    def brow(side):
        a, b = x[peak(f"browInnerUp_{side}")], x[peak(f"browOuterUp_{side}")]
        pts = a + np.linspace(0, 1, 5)[:, None] * (b - a)
        return np.array([skin[np.argmin(np.linalg.norm(x[skin] - p, axis=1))] for p in pts])

    def slit(s, n):
        return np.concatenate([[s.upper[0], s.upper[-1]], spread(s.upper[1:-1], n), spread(s.lower[1:-1], n)])
    return {"brow_a": brow("R"), "brow_b": brow("L"),
            "eyes": np.concatenate([slit(g.eyes["L"], 2), slit(g.eyes["R"], 2)]), "mouth": slit(g.mouth, 9)}


@pytest.fixture(scope="module", params=["ict", "sample"])
def face(request):
    """(rig, segmentation at the default settings, landmark parts) of ICT FaceKit and the sample face."""
    if request.param == "ict":
        rig = request.getfixturevalue("ict_rig")
        parts = ict_parts(request.getfixturevalue("landmarks"))
    else:
        rig = request.getfixturevalue("sample_rig")
        parts = sample_parts(rig)
    seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, SegmentationSettings())
    return rig, seg, parts


def regions_of(seg, level, vertices) -> set[int]:
    lab = seg.levels[level].core_labels()
    return set(int(r) for r in lab[vertices] if r >= 0)


def test_landmarks_lie_in_level0_regions(face):
    """At the default threshold: ≥ 8 of 10 brow, ≥ 10 of 12 eye and ≥ 18 of 20 mouth landmarks in regions."""
    _, seg, parts = face
    lab = seg.levels[0].core_labels()
    brows = np.concatenate([parts["brow_a"], parts["brow_b"]])
    assert len(brows) == 10 and len(parts["eyes"]) == 12 and len(parts["mouth"]) == 20
    assert (lab[brows] >= 0).sum() >= 8
    assert (lab[parts["eyes"]] >= 0).sum() >= 10
    assert (lab[parts["mouth"]] >= 0).sum() >= 18


def test_brows_eyes_and_mouth_in_different_level0_regions(face):
    _, seg, parts = face
    brows = regions_of(seg, 0, np.concatenate([parts["brow_a"], parts["brow_b"]]))
    eyes, mouth = regions_of(seg, 0, parts["eyes"]), regions_of(seg, 0, parts["mouth"])
    assert brows and eyes and mouth
    assert not brows & eyes and not brows & mouth and not eyes & mouth


def test_left_and_right_brows_in_different_level0_regions(face):
    _, seg, parts = face
    a, b = regions_of(seg, 0, parts["brow_a"]), regions_of(seg, 0, parts["brow_b"])
    assert a and b and not a & b


def test_brows_join_each_other_before_they_join_the_mouth(face):
    """Some level holds both brows in one region that has no mouth landmark; the brows meet the mouth only
    higher up (the hierarchy merges what is contiguous and moves together first)."""
    _, seg, parts = face
    brows = np.concatenate([parts["brow_a"], parts["brow_b"]])
    joined = [lv for lv in range(len(seg.levels)) if len(regions_of(seg, lv, brows)) == 1]
    assert joined, "the brows never share a region"
    first = joined[0]
    assert 0 < first < len(seg.levels) - 1
    assert not regions_of(seg, first, brows) & regions_of(seg, first, parts["mouth"])


def test_separate_meshes_follow_the_region_that_moves_them(ict_rig, ict_cache, ict_seg, landmarks):
    piece, main = ict_cache.pieces()
    assert main.sum() == np.bincount(piece).max()  # ICT: one skin piece; eyes, teeth, lashes are separate
    lab = ict_seg.levels[0].core_labels(ict_rig.n_vertices)
    moved = np.linalg.norm(ict_rig.deltas, axis=2).max(axis=0) > 0
    followed = 0
    for p in np.unique(piece[~main]):
        members = np.flatnonzero(piece == p)
        assert np.unique(lab[members]).size == 1, "a separate mesh is never split between regions"
        if not moved[members].any():
            assert lab[members[0]] == -1, "a mesh no shape moves stays in the background"
        followed += lab[members[0]] >= 0
    assert followed >= 20
    # the left eyelashes (the piece eyeBlink_L moves most) follow the left eye's region, the lower teeth
    # (the piece jawOpen moves most) the region jawOpen moves most, and neither takes a region by proximity
    k_blink, k_jaw = ict_rig.shape_index("eyeBlink_L"), ict_rig.shape_index("jawOpen")
    off = np.flatnonzero(~main)
    for k, expect in ((k_blink, regions_of(ict_seg, 0, np.asarray(landmarks[42:48]))), (k_jaw, None)):
        v = off[np.argmax(np.linalg.norm(ict_rig.deltas[k][off], axis=1))]
        r = int(lab[v])
        assert r >= 0
        if expect is not None:
            assert r in expect
        else:
            core = ict_seg.levels[0].regions[r].core
            on_skin = core[main[core]]
            act = np.linalg.norm(ict_rig.deltas[:, on_skin], axis=2).sum(axis=1)
            assert int(np.argmax(act)) == k_jaw
    # the choice 'background' keeps every separate mesh out of the regions
    seg = run(ict_rig, ict_cache, separate_meshes="background", levels=2)
    for lvl in seg.levels:
        assert (lvl.core_labels(ict_rig.n_vertices)[~main] == -1).all()


def test_hierarchy_pairs_mirror_shapes_and_merges_by_co_activation(ict_rig, ict_cache, ict_seg):
    from model.sides import mirror_name
    from solvers.hierarchy import merge_clusters, region_activity
    names = ict_rig.shape_names
    partners = ict_cache.mirror_partners()
    for k, name in enumerate(names):
        want = mirror_name(name) if mirror_name(name) in names else name
        assert names[partners[k]] == want, name
    # the two brows and the left eye: the left eye lies closer to the left brow than the right brow does,
    # so by contiguity alone it merges first; by co-activation the brows (mirror shapes) merge first
    x = ict_rig.neutral
    V = ict_rig.n_vertices
    support = np.asarray(ict_cache.support())
    _, main = ict_cache.pieces()
    lab = np.full(V, -1)
    lab[main & (support[:, names.index("browOuterUp_L")] > 0.9)] = 0
    lab[main & (support[:, names.index("browOuterUp_R")] > 0.9)] = 1
    lab[main & (support[:, names.index("eyeBlink_L")] > 0.3)] = 2
    assert np.bincount(lab[lab >= 0]).min() > 10
    act = region_activity(lab, support, partners)
    by_contact = merge_clusters(lab, ict_cache.adjacency, x, 3)
    assert by_contact[1][0] == by_contact[1][2] != by_contact[1][1]
    with_act = merge_clusters(lab, ict_cache.adjacency, x, 3, act)
    assert with_act[1][0] == with_act[1][1] != with_act[1][2]
    assert np.allclose(act[0] / act[0].sum(), act[1] / act[1].sum(), atol=0.05)


def test_region_statistics_name_the_right_shapes(ict_rig, ict_cache, ict_seg, landmarks):
    stats = region_statistics(ict_seg, ict_cache.maps(), ict_rig.shape_names)
    lab = ict_seg.levels[0].core_labels(ict_rig.n_vertices)
    mouth = stats[int(lab[landmarks[MOUTH_CORNERS[0]]])]
    assert all(name.startswith(("jaw", "mouth")) for name, _ in mouth["shapes"][:3])
    assert mouth["core_vertices"] == ict_seg.levels[0].regions[mouth["region"]].core.size
    assert mouth["vertices"] > mouth["core_vertices"]
    shares = [s for _, s in mouth["shapes"]]
    assert shares == sorted(shares, reverse=True) and 0 < sum(shares) <= 1
    # the activity behind the shares: each core's sum of every shape's map, to the bit as numpy sums a gather
    P = ict_cache.maps().per_shape
    cores = [r.core for r in ict_seg.levels[1].regions]
    act = S.region_shape_activity(P, cores)
    assert np.array_equal(act, np.stack([P[c].sum(axis=0) for c in cores]))
    assert not np.array_equal(act, np.stack([P[c[1:]].sum(axis=0) for c in cores]))


def test_cache_reuses_maps_and_rethresholds(ict_rig, ict_cache, ict_seg):
    maps = ict_cache.maps()
    seg = run(ict_rig, ict_cache, t=0.3)
    assert ict_cache.maps() is maps
    assert seg.seconds["maps"] < 0.05
    assert seg.threshold_value < ict_seg.threshold_value
    other = SegmentationCache()
    copy = ict_rig.copy()
    copy.deltas = copy.deltas[:3]
    run(copy, other)
    assert other.maps().per_shape.shape[1] == 3


def test_displacement_map_segmentation(ict_rig, ict_cache):
    seg = run(ict_rig, ict_cache, map_kind="displacement", t=0.75)
    D = ict_cache.maps().displacement
    assert np.allclose(D, np.linalg.norm(ict_rig.deltas, axis=2).max(axis=0))
    vals, srt = ict_cache.values("displacement", "uniform", True, 1)
    assert seg.threshold_value == srt[math.floor(srt.size * 0.75)]
    assert seg.levels[-1].n_regions == 1
    check_partition(seg, ict_rig.n_vertices)


def test_raw_map_is_kept_for_comparison(ict_rig, ict_cache, landmarks):
    """Joshi's raw maximum (no per-shape normalisation) is still there: its threshold is a quantile of the
    raw map over the moving skin, and at the old t = 0.75 it leaves the brows in the background (the
    measurement that chose the normalised default)."""
    seg = run(ict_rig, ict_cache, map_kind="laplacian", normalise=False, split_by_shapes=False, t=0.75)
    raw, srt = ict_cache.values("laplacian", "uniform", False, 0)
    assert raw is ict_cache.maps().combined
    assert seg.threshold_value == srt[math.floor(srt.size * 0.75)]
    lab = seg.levels[0].core_labels(ict_rig.n_vertices)
    assert (lab[np.asarray(landmarks[17:27])] >= 0).sum() == 0
    norm, _ = ict_cache.values("laplacian", "uniform", True, 0)
    assert not np.allclose(norm / norm.max(), raw / raw.max())


def test_segment_json_format(ict_rig, ict_seg):
    doc = segmentation_to_json(ict_seg)
    assert set(doc) == {"threshold", "levels", "seconds"}
    assert doc["threshold"] == SegmentationSettings().t == ict_seg.threshold_t
    text = json.dumps(doc)
    back = json.loads(text)
    assert [lvl["level"] for lvl in back["levels"]] == list(range(len(ict_seg.levels)))
    for lvl, ref in zip(back["levels"], ict_seg.levels):
        assert set(lvl) == {"level", "regions", "background"}
        assert lvl["background"] == ref.background.tolist()
        for reg, r in zip(lvl["regions"], ref.regions):
            assert set(reg) == {"vertices", "core"}
            assert reg["vertices"] == r.vertices.tolist() and reg["core"] == r.core.tolist()
    assert back["seconds"]["total"] > 0


def test_settings_round_trip_and_validation():
    s = SegmentationSettings(t=0.25, levels=4, map_kind="displacement", min_region_size=10, overlap_rings=2,
                             concavity_rings=0, method="region-growing")
    d = s.to_dict()
    assert json.loads(json.dumps(d)) == d
    assert SegmentationSettings.from_dict(d) == s
    assert SegmentationSettings.from_dict({"t": 0.5, "future_option": 1}).t == 0.5
    for kw, msg in [({"t": 1.2}, "between 0 and 1"), ({"t": -0.01}, "between 0 and 1"),
                    ({"map_kind": "curvature"}, "Unknown deformation map"),
                    ({"method": "kmeans"}, "Unknown segmentation method"),
                    ({"overlap_rings": -1}, "overlap_rings"), ({"growth_ratio": 0}, "ratio")]:
        with pytest.raises(RigInputError, match=msg):
            SegmentationSettings(**kw)


def test_bad_rigs_are_refused_with_a_sentence(ict_rig):
    V = ict_rig.n_vertices
    args = (ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices)
    with pytest.raises(RigInputError, match="no blendshapes") as e:
        segment_rig(*args, np.zeros((0, V, 3)))
    assert str(e.value).count(".") == 1
    with pytest.raises(RigInputError, match="all displacements are zero"):
        segment_rig(*args, np.zeros((2, V, 3)))
    translated = np.broadcast_to(np.array([0.0, 1.0, 0.0]), (1, V, 3))
    with pytest.raises(RigInputError, match="laplacian map is zero everywhere"):
        segment_rig(*args, translated)
    with pytest.raises(RigInputError, match="between 0 and 1"):
        s = SegmentationSettings()
        s.t = 2.0
        segment_rig(*args, ict_rig.deltas, s)
    with pytest.raises(RigInputError, match="leaves no region"):
        segment_rig(*args, ict_rig.deltas, SegmentationSettings(t=1.0))


# --- Acosta: region growing and nudging ----------------------------------------------------------------

def test_region_growing_follows_acosta(ict_rig, ict_cache):
    D = ict_cache.maps().displacement
    A = ict_cache.adjacency
    groups = grow_regions(D, A, ratio=0.75, max_groups=5)
    G = groups.max() + 1
    assert G == 5
    taken = np.zeros(D.size, dtype=bool)
    for g in range(G):
        members = np.flatnonzero(groups == g)
        free = np.flatnonzero(~taken)
        seed = free[np.argmax(D[free])]
        assert groups[seed] == g
        assert D[members].min() >= 0.75 * D[seed]
        sub = A[members][:, members]
        assert csgraph.connected_components(sub, directed=False)[0] == 1
        # maximal: no free neighbour above the bar was left out
        nb = np.unique(A[members].indices)
        left = nb[(groups[nb] != g) & (groups[nb] < 0)]
        assert np.all(D[left] < 0.75 * D[seed])
        taken[members] = True
    seg = run(ict_rig, ict_cache, method="region-growing", map_kind="displacement", min_region_size=1,
              concavity_rings=0)
    assert seg.threshold_value is None and seg.levels[-1].n_regions == 1
    # on the normalised map, the groups on the skin are the regions; the separate meshes (teeth, lashes)
    # follow them and never make their own (on the raw map four of the five groups are teeth and gums)
    _, main = ict_cache.pieces()
    vals, _ = ict_cache.values("displacement", "uniform", True, 1)
    on_skin = grow_regions(vals, A, ratio=0.75, max_groups=5)[main]
    assert seg.levels[0].n_regions == np.unique(on_skin[on_skin >= 0]).size >= 3
    check_partition(seg, ict_rig.n_vertices)


def test_vertex_normals_point_out_of_the_face(ict_rig, landmarks):
    n = polygon_normals(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices)
    assert np.allclose(np.linalg.norm(n[:ICT_FACE], axis=1), 1.0)
    nose_tip = landmarks[30]
    assert n[nose_tip, 2] > 0.8
    assert n[int(np.argmax(ict_rig.neutral[:, 1])), 1] > 0.8  # top of the head points up


def test_nudge_moves_only_the_region_with_a_soft_edge(ict_rig, ict_seg):
    lvl = ict_seg.levels[0]
    r = 0
    reg = lvl.regions[r]
    phi = lvl.blend.tocsc()[:, r].toarray().ravel()[reg.vertices]
    x = ict_rig.neutral
    out = nudge_region(x, reg.vertices, 0.2, direction="out", weights=phi,
                       face_counts=ict_rig.face_counts, face_indices=ict_rig.face_indices)
    moved = np.linalg.norm(out - x, axis=1)
    others = np.setdiff1d(np.arange(x.shape[0]), reg.vertices)
    assert moved[others].max() == 0
    assert np.allclose(moved[reg.vertices], 0.2 * phi)
    n = polygon_normals(x, ict_rig.face_counts, ict_rig.face_indices)
    inward = nudge_region(x, reg.vertices, 0.2, direction="in", normals=n)
    assert np.allclose(inward[reg.core] - x[reg.core], -0.2 * n[reg.core])
    up = nudge_region(x, reg.vertices, 0.5, direction=[0, 2, 0])
    assert np.allclose(up[reg.vertices] - x[reg.vertices], [0, 0.5, 0])
    with pytest.raises(RigInputError, match="non-zero 3D vector"):
        nudge_region(x, reg.vertices, 0.5, direction=[0, 0, 0])
    with pytest.raises(RigInputError, match="blend weights"):
        nudge_region(x, reg.vertices, 0.5, direction=[0, 1, 0], weights=phi[:-1])


# --- the bundled sample rig ----------------------------------------------------------------------------

def test_sample_rig_segmentation(sample_rig):
    cache = SegmentationCache()
    seg = run(sample_rig, cache)
    V = sample_rig.n_vertices
    counts = [lvl.n_regions for lvl in seg.levels]
    assert counts[0] >= 3 and counts[-1] == 1
    assert all(a > b for a, b in zip(counts, counts[1:]))
    check_partition(seg, V)
    check_overlap(seg, cache.adjacency, 1)
    check_blend(seg, 1)
    s = SegmentationSettings()
    M, D = cache.values(s.map_kind, s.laplacian, s.normalise, s.smoothing)
    assert seg.threshold_value == D[math.floor(D.size * s.t)]
    # the region statistics cover every level-0 region and name real shapes
    stats = region_statistics(seg, cache.maps(), sample_rig.shape_names)
    assert len(stats) == counts[0]
    assert all(name in sample_rig.shape_names for st in stats for name, _ in st["shapes"])
    assert all(share >= 0.005 for st in stats for _, share in st["shapes"][1:])   # no "0%" entries


# --- the command line ----------------------------------------------------------------------------------

def test_segment_command_options(tmp_path):
    """`segment` writes the JSON; --map/--normalise/--split/--separate-meshes reach the settings (the raw
    Joshi map differs from the default), and a bad value is one sentence and exit 2."""
    from resources.sample_rig import write_sample
    from tests.cli_runner import run_cli
    folder = write_sample(tmp_path / "sample")
    out_default, out_raw = tmp_path / "default.json", tmp_path / "raw.json"
    run_cli("segment", folder, "-o", out_default, "--levels", "3")
    run_cli("segment", folder, "-o", out_raw, "--levels", "3", "--map", "laplacian", "--normalise", "none",
            "--split", "none", "--smoothing", "0", "--separate-meshes", "background", "--threshold", "0.75")
    default, raw = json.loads(out_default.read_text()), json.loads(out_raw.read_text())
    assert default["threshold"] == SegmentationSettings().t and raw["threshold"] == 0.75
    from model.readers import load_rig
    r = load_rig(folder)  # as the command reads it (the OBJ text rounds the coordinates)
    ref = segment_rig(r.neutral, r.face_counts, r.face_indices, r.deltas, SegmentationSettings(levels=3))
    assert [reg["core"] for reg in default["levels"][0]["regions"]] == [reg.core.tolist() for reg in ref.levels[0].regions]
    ref_raw = segment_rig(r.neutral, r.face_counts, r.face_indices, r.deltas, SegmentationSettings(
        levels=3, map_kind="laplacian", normalise=False, split_by_shapes=False, smoothing=0,
        separate_meshes="background", t=0.75))
    assert [reg["core"] for reg in raw["levels"][0]["regions"]] == [reg.core.tolist() for reg in ref_raw.levels[0].regions]
    assert default["levels"][0]["background"] != raw["levels"][0]["background"]
    bad = run_cli("segment", folder, "-o", tmp_path / "x.json", "--smoothing", "-1", check=False)
    assert bad.returncode == 2 and "smoothing" in bad.stderr and bad.stderr.strip().count("\n") == 0


def test_segmentation_runs_with_ordinary_pages_and_gives_numpy_its_huge_page_setting_back(ict_rig, monkeypatch):
    """A segmentation asks for ordinary pages while it runs (model.pages.small_pages: the kernel's compaction
    for huge pages cost more than they save); numpy's own setting comes back after, also when two segmentations
    overlap in threads."""
    from model import segmentation as S
    from model.pages import small_pages
    from tests.test_pages import no_runs_in_flight
    no_runs_in_flight()            # a segmentation an earlier test's window started holds numpy's setting till it ends
    toggle = np._core.multiarray._set_madvise_hugepage
    before = toggle(True)
    try:
        with small_pages():
            assert toggle(False) is False            # off inside (and left off)
            with small_pages():                      # an overlapping run
                pass
            assert toggle(False) is False            # still off: the outer run is not over
        assert toggle(True) is True                  # back on after the last run
        seen = []
        maps = S.deformation_maps

        def spy(*args):                              # the setting while ICT's maps are made
            seen.append(toggle(False))
            return maps(*args)
        monkeypatch.setattr(S, "deformation_maps", spy)
        S.segment_rig(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, ict_rig.deltas)
        assert seen == [False]                       # ordinary pages, on a rig of ICT's size too
        assert toggle(True) is True                  # and numpy's setting back after it
    finally:
        toggle(before)
