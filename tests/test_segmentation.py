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
    return SegmentationCache()


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


def test_split_sits_at_the_requested_quantile(ict_rig, ict_cache, ict_seg):
    M = ict_cache.maps().combined
    n = M.size
    D = np.sort(M)
    assert ict_seg.threshold_value == D[math.floor(n * 0.75)]
    for t in (0.25, 0.5, 0.75, 0.9):
        labels, thr = S.threshold_labels(M, ict_cache.adjacency, t)
        deforming = labels >= 0
        assert np.array_equal(deforming, M > thr)
        assert (~deforming).sum() >= math.floor(n * t) + 1  # at least the values up to D[⌊n·t⌋]
        assert (M < thr).sum() <= math.floor(n * t)
        # regions are the connected components: no mesh edge joins two different regions
        r, c = ict_cache.adjacency.nonzero()
        both = deforming[r] & deforming[c]
        assert np.all(labels[r[both]] == labels[c[both]])


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
    assert counts == level_targets(counts[0])  # default: halve per level
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


def test_brows_and_mouth_in_different_regions_background_is_the_skull(ict_rig, ict_cache, ict_seg, landmarks):
    lab = ict_seg.levels[0].core_labels(ict_rig.n_vertices)
    maps = ict_cache.maps()
    names = ict_rig.shape_names
    mouth = {int(lab[landmarks[i]]) for i in MOUTH_CORNERS}
    assert -1 not in mouth
    for side in ("L", "R"):
        # a brow vertex: on the face skin, where that side's brow shapes bend the skin most
        ks = [names.index(f"{s}_{side}") for s in ("browInnerUp", "browOuterUp", "browDown")]
        brow = int(np.argmax(maps.per_shape[:ICT_FACE, ks].sum(axis=1)))
        assert (ict_rig.neutral[brow, 0] > 0) == (side == "L")
        assert ict_rig.neutral[brow, 1] > ict_rig.neutral[landmarks[27], 1]  # above the nose bridge
        assert lab[brow] >= 0 and lab[brow] not in mouth
    x = ict_rig.neutral
    top, back, neck = int(np.argmax(x[:, 1])), int(np.argmin(x[:, 2])), int(np.argmin(x[:, 1]))
    assert x[back, 2] < -8 and x[top, 1] > 14 and x[neck, 1] < -18
    for v in (top, back, neck):
        assert lab[v] == -1
    bg = set(ict_seg.levels[0].background.tolist())
    skull = np.flatnonzero(x[:, 1] > 10)  # the crown of the head
    assert np.mean([v in bg for v in skull]) > 0.99


def test_region_statistics_name_the_right_shapes(ict_rig, ict_cache, ict_seg, landmarks):
    stats = region_statistics(ict_seg, ict_cache.maps(), ict_rig.shape_names)
    lab = ict_seg.levels[0].core_labels(ict_rig.n_vertices)
    mouth = stats[int(lab[landmarks[MOUTH_CORNERS[0]]])]
    assert all(name.startswith(("jaw", "mouth")) for name, _ in mouth["shapes"][:3])
    assert mouth["core_vertices"] == ict_seg.levels[0].regions[mouth["region"]].core.size
    assert mouth["vertices"] > mouth["core_vertices"]
    shares = [s for _, s in mouth["shapes"]]
    assert shares == sorted(shares, reverse=True) and 0 < sum(shares) <= 1


def test_cache_reuses_maps_and_rethresholds(ict_rig, ict_cache, ict_seg):
    maps = ict_cache.maps()
    seg = run(ict_rig, ict_cache, t=0.5)
    assert ict_cache.maps() is maps
    assert seg.seconds["maps"] < 0.05
    assert seg.threshold_value < ict_seg.threshold_value
    other = SegmentationCache()
    copy = ict_rig.copy()
    copy.deltas = copy.deltas[:3]
    run(copy, other)
    assert other.maps().per_shape.shape[1] == 3


def test_displacement_map_segmentation(ict_rig, ict_cache):
    seg = run(ict_rig, ict_cache, map_kind="displacement")
    D = ict_cache.maps().displacement
    assert seg.threshold_value == np.sort(D)[math.floor(D.size * 0.75)]
    assert seg.levels[-1].n_regions == 1
    check_partition(seg, ict_rig.n_vertices)


def test_segment_json_format(ict_rig, ict_seg):
    doc = segmentation_to_json(ict_seg)
    assert set(doc) == {"threshold", "levels", "seconds"}
    assert doc["threshold"] == 0.75
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
    assert seg.levels[0].n_regions == 5
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
    M = cache.maps().combined
    assert seg.threshold_value == np.sort(M)[math.floor(V * 0.75)]
    # the region statistics cover every level-0 region and name real shapes
    stats = region_statistics(seg, cache.maps(), sample_rig.shape_names)
    assert len(stats) == counts[0]
    assert all(name in sample_rig.shape_names for st in stats for name, _ in st["shapes"])
    assert all(share >= 0.005 for st in stats for _, share in st["shapes"][1:])   # no "0%" entries


def test_sample_rig_regions_are_sensible(sample_rig):
    """At the sample's own threshold its brows, eyes and mouth fall in different regions, cores disjoint."""
    from resources.sample_rig import SAMPLE_SEGMENTATION_T
    r = sample_rig
    cache = SegmentationCache()
    seg = segment_rig(r.neutral, r.face_counts, r.face_indices, r.deltas, SegmentationSettings(t=SAMPLE_SEGMENTATION_T),
                      cache=cache)
    labels = seg.levels[0].core_labels()
    per_shape = cache.maps().per_shape

    def strongest(name):  # where the shape deforms the surface most (largest ‖L d_k‖)
        return int(np.argmax(per_shape[:, r.shape_index(name)]))
    brow_l, brow_r = strongest("browInnerUp_L"), strongest("browInnerUp_R")
    mouth_l, mouth_r = strongest("mouthSmile_L"), strongest("mouthSmile_R")
    eye_l, nose = strongest("eyeBlink_L"), strongest("noseSneer_L")
    for v in (brow_l, brow_r, mouth_l, mouth_r, eye_l, nose):
        assert labels[v] >= 0, "the strongest point of a shape must be in a region, not the background"
    assert labels[brow_l] != labels[mouth_l] and labels[brow_r] != labels[mouth_r]
    assert len({labels[brow_l], labels[eye_l], labels[nose], labels[mouth_l]}) == 4
    assert 4 <= seg.levels[0].n_regions <= 40 and seg.levels[-1].n_regions == 1
