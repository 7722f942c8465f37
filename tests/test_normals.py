"""Vertex normals of a moving surface (solvers.normals.VertexNormals): the compiled one-pass kernel the viewport
uses every frame gives the numpy path's bits, and both are the area-weighted normals (Max 1999)."""
from __future__ import annotations

import numpy as np

from solvers import take_kernel
from solvers.normals import VertexNormals, vertex_normals


def test_the_compiled_normals_are_the_numpy_normals_bit_for_bit_on_posed_ict(ict_rig):
    assert take_kernel.kernel().__name__ == "_take_kernel_aot"      # built here: the kernel path is taken
    normals = VertexNormals(ict_rig.face_counts, ict_rig.face_indices, ict_rig.n_vertices)
    rng = np.random.default_rng(1)
    for _ in range(3):
        points = ict_rig.neutral + np.tensordot(rng.random(ict_rig.n_shapes), ict_rig.deltas, 1)
        fast, ref = normals(points), normals.numpy(points)
        assert fast.dtype == np.float32 and fast.shape == (ict_rig.n_vertices, 3)
        np.testing.assert_array_equal(fast, ref)
        # and they are the area-weighted unit normals (float64 reference, to float32's precision)
        np.testing.assert_allclose(fast, vertex_normals(points, normals.tris), atol=2e-4)


def test_isolated_and_degenerate_vertices_keep_the_numpy_paths_answer():
    # a quad, a triangle with two equal corners (zero area) and a vertex no face uses
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [5, 5, 5]], dtype=np.float64)
    counts = np.array([4, 3])
    faces = np.array([0, 1, 2, 3, 1, 4, 4])
    normals = VertexNormals(counts, faces, len(points))
    fast, ref = normals(points), normals.numpy(points)
    np.testing.assert_array_equal(fast, ref)
    np.testing.assert_array_equal(fast[5], [0, 0, 0])              # in no face
    np.testing.assert_allclose(fast[:4], [[0, 0, 1]] * 4)
