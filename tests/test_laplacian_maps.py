"""Mesh Laplacian and deformation maps (ALGORITHMS.md §2) on the real ICT FaceKit rig."""
from __future__ import annotations

import numpy as np
import pytest

from model.errors import RigInputError
from solvers.deformation_maps import (deformation_maps, displacement_map, laplacian_magnitudes,
                                      laplacian_vectors, vector_colors)
from solvers.laplacian import (adjacency_matrix, cotangent_laplacian, mesh_adjacency, mesh_laplacian,
                               polygon_edges, uniform_laplacian)


@pytest.fixture(scope="module")
def ict_graph(ict_rig):
    A = mesh_adjacency(ict_rig.n_vertices, ict_rig.face_counts, ict_rig.face_indices)
    return A, uniform_laplacian(A)


@pytest.fixture(scope="module")
def ict_maps(ict_rig, ict_graph):
    return deformation_maps(ict_graph[1], ict_rig.deltas)


def test_polygon_edges_match_the_rig_edges(ict_rig):
    assert np.array_equal(polygon_edges(ict_rig.face_counts, ict_rig.face_indices), ict_rig.edges())


def _one_ring_by_sets(n, counts, indices):
    """An independent reading: each polygon's consecutive corners (closed) as Python sets of neighbours."""
    ring = [set() for _ in range(n)]
    at = 0
    for c in counts:
        poly = [int(v) for v in indices[at:at + c]]
        at += c
        for a, b in zip(poly, poly[1:] + poly[:1]):
            if a != b:
                ring[a].add(b)
                ring[b].add(a)
    return ring


@pytest.mark.parametrize("seed", range(12))
def test_edges_and_adjacency_of_messy_polygons_against_sets(seed):
    # triangles to hexagons over few vertices: repeated corners, edges shared by many polygons in both
    # directions, unused vertices (the sparse-matrix deduplication against a plain set reading)
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 40))
    counts = rng.integers(3, 7, int(rng.integers(1, 80)))
    indices = rng.integers(0, n - 2, int(counts.sum()))
    ring = _one_ring_by_sets(n, counts, indices)
    expected = sorted((a, b) for a in range(n) for b in ring[a] if a < b)
    edges = polygon_edges(counts, indices)
    assert edges.dtype == np.int64 and edges.tolist() == [list(e) for e in expected]
    A = mesh_adjacency(n, counts, indices)
    assert A.has_canonical_format
    assert all(A.indices[A.indptr[v]:A.indptr[v + 1]].tolist() == sorted(ring[v]) for v in range(n))
    assert (A.data == 1.0).all()
    # the general path (edges in any order, repeated, reversed) builds the same matrix
    messy = np.concatenate([edges[::-1], edges[:, ::-1], edges])
    B = adjacency_matrix(n, messy)
    assert np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices)


def test_adjacency_is_the_symmetric_one_ring(ict_rig, ict_graph):
    A, _ = ict_graph
    assert (A != A.T).nnz == 0
    assert A.diagonal().sum() == 0
    e = ict_rig.edges()
    assert A.nnz == 2 * len(e)
    assert A[e[0, 0], e[0, 1]] == 1.0


def test_uniform_laplacian_is_the_umbrella_operator(ict_rig, ict_graph):
    A, L = ict_graph
    x = ict_rig.neutral
    v = 1234
    nbrs = A[v].indices
    expected = (x[nbrs] - x[v]).mean(axis=0)
    assert np.allclose((L @ x)[v], expected, atol=1e-12)
    # rows of connected vertices sum to zero
    assert np.allclose(np.asarray(L.sum(axis=1)).ravel(), 0.0, atol=1e-12)


def test_laplacian_of_a_rigidly_translated_shape_is_zero(ict_rig, ict_graph):
    _, L = ict_graph
    V = ict_rig.n_vertices
    translated = np.broadcast_to(np.array([0.3, -1.2, 2.5]), (1, V, 3))
    assert np.abs(laplacian_magnitudes(L, translated)).max() < 1e-12
    Lc = mesh_laplacian(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, "cotangent")
    assert np.abs(laplacian_magnitudes(Lc, translated)).max() < 1e-12
    # while a real shape is not zero
    assert laplacian_magnitudes(L, ict_rig.deltas[:1]).max() > 1e-3


def test_laplacian_of_a_linear_field_is_zero_inside_a_flat_grid():
    n = 6
    g = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2).astype(float)
    pts = np.column_stack([g, np.zeros(len(g))])
    quads = np.array([[i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1]
                      for i in range(n - 1) for j in range(n - 1)])
    counts = np.full(len(quads), 4)
    field = np.column_stack([2 * pts[:, 0] + pts[:, 1], -pts[:, 1], 0.5 * pts[:, 0]])[None]
    interior = np.array([i * n + j for i in range(1, n - 1) for j in range(1, n - 1)])
    for kind in ("uniform", "cotangent"):
        L = mesh_laplacian(pts, counts, quads.ravel(), kind)
        assert np.abs(laplacian_vectors(L, field)[interior]).max() < 1e-12, kind
        # a bump is not linear: it shows
        bump = np.zeros((1, n * n, 3))
        bump[0, 14, 2] = 1.0
        assert laplacian_magnitudes(L, bump)[14, 0] > 0.5


def test_all_shapes_in_one_product_equal_shape_by_shape(ict_rig, ict_graph, ict_maps):
    _, L = ict_graph
    for k in (0, 30, 56):
        single = np.linalg.norm(L @ ict_rig.deltas[k], axis=1)
        assert np.allclose(ict_maps.per_shape[:, k], single, atol=1e-12)


def test_combined_map_argmax_and_vector(ict_rig, ict_graph, ict_maps):
    m = ict_maps
    V, K = m.per_shape.shape
    assert (V, K) == (ict_rig.n_vertices, ict_rig.n_shapes)
    assert np.array_equal(m.combined, m.per_shape.max(axis=1))
    rows = np.arange(V)
    assert np.array_equal(m.per_shape[rows, m.argmax_shape], m.combined)
    v = int(np.argmax(m.combined))
    k = int(m.argmax_shape[v])
    assert np.allclose(m.vector[v], (ict_graph[1] @ ict_rig.deltas[k])[v])
    assert np.allclose(np.linalg.norm(m.vector, axis=1), m.combined)
    # the strongest local deformation of ICT is in the mouth, from the jaw or a mouth shape
    assert ict_rig.shape_names[k].startswith(("jaw", "mouth"))
    rgb = vector_colors(m.vector)
    assert rgb.shape == (V, 3) and rgb.min() >= 0 and rgb.max() <= 1
    assert np.allclose(vector_colors(np.zeros((3, 3))), 0.5)


def test_displacement_map_is_the_largest_shape_displacement(ict_rig, ict_maps):
    d = ict_maps.displacement
    assert np.allclose(d, np.linalg.norm(ict_rig.deltas, axis=2).max(axis=0))
    assert np.array_equal(displacement_map(ict_rig.deltas), d)
    assert ict_maps.values("displacement") is d and ict_maps.values("laplacian") is ict_maps.combined
    with pytest.raises(RigInputError, match="Unknown map"):
        ict_maps.values("curvature")


def test_cotangent_laplacian_is_row_normalised(ict_rig):
    from model.rig import fan_triangulate
    Lc = cotangent_laplacian(ict_rig.neutral, fan_triangulate(ict_rig.face_counts, ict_rig.face_indices))
    assert np.allclose(np.asarray(Lc.sum(axis=1)).ravel(), 0.0, atol=1e-9)
    assert np.allclose(Lc.diagonal()[np.diff(Lc.indptr) > 1], -1.0)


def test_bad_input_messages(ict_rig, ict_graph):
    _, L = ict_graph
    with pytest.raises(RigInputError, match="no blendshapes"):
        deformation_maps(L, np.zeros((0, ict_rig.n_vertices, 3)))
    with pytest.raises(RigInputError, match=r"\(K, 26719, 3\)"):
        deformation_maps(L, np.zeros((2, 10, 3)))
    with pytest.raises(RigInputError, match="does not exist"):
        adjacency_matrix(3, np.array([[0, 5]]))
    with pytest.raises(RigInputError, match="Unknown Laplacian"):
        mesh_laplacian(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, "harmonic")


def test_per_shape_displacement_and_moving_vertices(ict_rig, ict_maps):
    from solvers.deformation_maps import shape_moves
    D = ict_maps.per_shape_displacement
    assert D.shape == (ict_rig.n_vertices, ict_rig.n_shapes)
    assert np.allclose(D[:, 7], np.linalg.norm(ict_rig.deltas[7], axis=1))
    assert np.array_equal(ict_maps.displacement, D.max(axis=1))
    moves = shape_moves(D, 0.01)
    k = ict_rig.shape_index("browInnerUp_L")
    assert np.array_equal(moves[:, k], D[:, k] > 0.01 * D[:, k].max())
    assert 0 < moves[:, k].sum() < 0.5 * ict_rig.n_vertices   # a brow shape moves a part of the head
    still = np.zeros((5, 2))
    assert not shape_moves(still).any()


def test_per_shape_normalisation_over_the_moving_vertices(ict_rig, ict_maps):
    from solvers.deformation_maps import normalised_map, shape_moves, shape_scales
    P = ict_maps.per_shape
    moves = shape_moves(ict_maps.per_shape_displacement)
    s = shape_scales(P, moves, 0.99)
    for name in ("browInnerUp_L", "mouthSmile_R", "jawOpen"):
        k = ict_rig.shape_index(name)
        assert s[k] == np.quantile(P[moves[:, k], k], 0.99)
        assert s[k] > np.quantile(P[:, k], 0.99)  # not over the whole head, where most vertices are still
    N = normalised_map(P, s)
    assert np.allclose(N, (P / s).max(axis=1))
    # every shape has its say: on its own scale each shape reaches 1 on 1% of the vertices it moves
    for k in range(P.shape[1]):
        if moves[:, k].any():
            assert np.isclose(np.mean(P[moves[:, k], k] / s[k] > 1.0), 0.01, atol=0.002)
    # a shape that moves nothing keeps scale 1 (no division by zero)
    assert shape_scales(np.zeros((4, 1)), np.zeros((4, 1), dtype=bool))[0] == 1.0


def test_light_smoothing_of_a_map(ict_rig, ict_graph):
    from solvers.deformation_maps import smooth_map
    A, _ = ict_graph
    assert np.allclose(smooth_map(np.full(ict_rig.n_vertices, 2.5), A, 3), 2.5)
    x = np.zeros(ict_rig.n_vertices)
    x[1234] = 1.0
    y = smooth_map(x, A, 1)
    nbrs = A[1234].indices
    assert np.isclose(y[1234], 1.0 / (1 + nbrs.size))
    assert np.allclose(y[nbrs], 1.0 / (1 + np.diff(A.indptr)[nbrs]))
    assert np.count_nonzero(y) == 1 + nbrs.size
    assert np.array_equal(smooth_map(x, A, 0), x)


@pytest.mark.parametrize("kind", ["uniform", "cotangent"])
def test_compiled_maps_are_the_scipy_products_bit_for_bit(ict_rig, kind, monkeypatch):
    # solvers.shape_kernels_jit (one pass over each shape's (V, 3) deltas) against the three scipy sparse products
    # per shape it replaces: the same bits, so a segmentation does not depend on whether the kernel is built
    from solvers import deformation_maps as dm
    from solvers import take_kernel
    take_kernel.kernel()            # the ahead-of-time build, where this machine has none yet (once, ~20 s)
    if take_kernel.built() is None:
        pytest.skip("the kernel cannot be compiled ahead of time here (no C compiler): scipy's products are used")
    L = mesh_laplacian(ict_rig.neutral, ict_rig.face_counts, ict_rig.face_indices, kind)
    assert dm._compiled_shape_maps(L) is not None
    monkeypatch.setattr(dm, "KERNEL_ROWS", 5000)   # the rows in six calls a shape, the last one short
    # six shapes (one pass for four, then one each for the two left), one of them a rig's float32 deltas converted
    d = np.concatenate([ict_rig.deltas[[0, 20, 40, 50, 56]], ict_rig.deltas[[5]].astype(np.float32).astype(np.float64)])
    compiled, compiled_disp = dm._shape_maps(L, d)
    compiled_lap_only = dm.laplacian_magnitudes(L, d)
    monkeypatch.setattr(take_kernel, "built", lambda: None)
    scipy_maps, scipy_disp = dm._shape_maps(L, d)
    assert np.array_equal(compiled.view(np.int64), scipy_maps.view(np.int64))
    assert np.array_equal(compiled_disp.view(np.int64), scipy_disp.view(np.int64))
    assert np.array_equal(compiled_lap_only.T, scipy_maps)
    assert (compiled > 0).any(axis=1).all()
    assert not np.array_equal(compiled[1:5], compiled[:4])   # every shape its own row, none written twice
