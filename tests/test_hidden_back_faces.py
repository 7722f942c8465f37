"""solvers.mesh.hidden_back_faces: which polygons a renderer may cull when they face away (the viewport's culling)."""
from __future__ import annotations

import numpy as np

from solvers.mesh import hidden_back_faces

CUBE = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
# six quads wound counter-clockwise seen from outside (normals outward)
CUBE_FACES = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]


def _mesh(*parts):
    """(points, counts, indices) of several parts given as (points, faces), the faces renumbered."""
    pts, counts, idx, base = [], [], [], 0
    for p, faces in parts:
        pts.append(p)
        counts += [len(f) for f in faces]
        idx += [base + i for f in faces for i in f]
        base += len(p)
    return np.concatenate(pts), np.array(counts), np.array(idx)


def _sphere(n=24):
    """A closed UV sphere wound outward: quads between rings, triangle fans at the poles."""
    rings = [(np.sin(t), np.cos(t)) for t in np.linspace(0, np.pi, n + 1)[1:-1]]
    pts = [[0.0, 0.0, 1.0]] + [[s * np.cos(a), s * np.sin(a), c] for s, c in rings
                               for a in np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)] + [[0.0, 0.0, -1.0]]
    m = 2 * n
    ring = lambda r, k: 1 + r * m + k % m   # noqa: E731
    faces = [[0, ring(0, k), ring(0, k + 1)] for k in range(m)]
    faces += [[ring(r, k), ring(r + 1, k), ring(r + 1, k + 1), ring(r, k + 1)] for r in range(n - 2) for k in range(m)]
    last = len(pts) - 1
    faces += [[last, ring(n - 2, k + 1), ring(n - 2, k)] for k in range(m)]
    return np.array(pts), faces


def test_a_closed_outward_part_may_be_culled_and_an_open_sheet_may_not():
    sheet = (np.array([[3.0, 0, 0], [4, 0, 0], [4, 1, 0], [3, 1, 0]]), [[0, 1, 2, 3]])
    pts, counts, idx = _mesh((CUBE, CUBE_FACES), sheet)
    assert hidden_back_faces(pts, counts, idx).tolist() == [True] * 6 + [False]


def test_inward_or_inconsistent_winding_keeps_both_sides():
    inward = [f[::-1] for f in CUBE_FACES]
    assert not hidden_back_faces(CUBE, np.full(6, 4), np.ravel(inward)).any()
    one_flipped = [CUBE_FACES[0][::-1]] + CUBE_FACES[1:]
    assert not hidden_back_faces(CUBE, np.full(6, 4), np.ravel(one_flipped)).any()


def test_a_small_opening_is_allowed_a_large_one_is_not():
    pts, faces = _sphere()
    counts = np.array([len(f) for f in faces])
    assert hidden_back_faces(pts, counts, np.concatenate(faces)).all()
    # one quad missing: 4 of ~2,300 edges on the opening (a head's cut at the neck): still hidden from outside
    holed = faces[:100] + faces[101:]
    assert hidden_back_faces(pts, np.array([len(f) for f in holed]), np.concatenate(holed)).all()
    # the cube without its top: a box open on 4 of its 12 edges shows its inside
    open_box = CUBE_FACES[:5]
    assert not hidden_back_faces(CUBE, np.full(5, 4), np.ravel(open_box)).any()


def test_bounds_and_extent_are_numpys_own_numbers_column_by_column(ict_rig):
    """``solvers.mesh.bounds`` (the rig-change path's bounding boxes, a column at a time) gives exactly numpy's
    ``min``/``max`` along the first axis, ``extent`` the norm of ``ptp``; on ICT's neutral and on points whose
    columns have their extremes in different rows."""
    import pytest
    from solvers.mesh import bounds, extent
    rng = np.random.default_rng(3)
    for p in (ict_rig.neutral, rng.normal(size=(1001, 3)) * [1.0, -20.0, 3e5], np.float32(ict_rig.neutral[:7])):
        lo, hi = bounds(p)
        assert np.array_equal(lo, p.min(axis=0)) and np.array_equal(hi, p.max(axis=0))
        assert extent(p) == float(np.linalg.norm(np.ptp(p, axis=0)))
    for p in (rng.normal(size=(50, 2)), rng.normal(size=(50, 1)), rng.normal(size=(50, 4)).astype(np.float32)):
        lo, hi = bounds(p)          # any number of columns (the glTF writer's UVs, times, colours)
        assert np.array_equal(lo, p.min(axis=0)) and np.array_equal(hi, p.max(axis=0)) and lo.dtype == p.dtype
    p = np.array([[0.0, 5.0, -1.0], [2.0, -3.0, 4.0]])
    assert bounds(p)[0].tolist() == [0.0, -3.0, -1.0] and bounds(p)[1].tolist() == [2.0, 5.0, 4.0]
    with pytest.raises(ValueError):
        bounds(np.zeros((0, 3)))


def test_the_viewports_cells_are_the_rigs_polygons_and_their_reversed_backs(ict_rig):
    """The viewport's mesh holds exactly the rig's polygons as cells, in order, and nothing else (a pyvista mesh
    made from points alone would also hold a vertex cell for each point, which picking would count); the backs'
    cells are the chosen polygons reversed with their first corner kept (``solvers.mesh.reversed_faces``), whose
    fans are the originals' triangles facing the other way. Checked against the polygons as ``Rig.polygons``
    lists them, on ICT (quads and triangles) and on a mesh of 3- to 6-gons."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    from solvers.mesh import cell_layout, fan_triangulate, reversed_faces
    from widgets.scene import polygon_cells, rig_mesh
    polys = [np.array([0, 1, 2]), np.array([2, 3, 4, 5]), np.array([5, 6, 7, 8, 9]), np.array([9, 0, 4, 7, 1, 3])]
    meshes = [(ict_rig.face_counts, ict_rig.face_indices, ict_rig.polygons()),
              (np.array([len(p) for p in polys]), np.concatenate(polys), polys)]
    for counts, indices, listed in meshes:
        offsets, connectivity = cell_layout(counts, indices)
        assert [connectivity[a:b].tolist() for a, b in zip(offsets[:-1], offsets[1:])] == [p.tolist() for p in listed]
        n_points = int(indices.max()) + 1
        mesh = rig_mesh(np.zeros((n_points, 3)), counts, indices)
        assert mesh.n_cells == len(counts) and mesh.GetNumberOfVerts() == 0 and mesh.n_points == n_points
        cells = mesh.GetPolys()
        assert np.array_equal(vtk_to_numpy(cells.GetOffsetsArray()), offsets)
        assert np.array_equal(vtk_to_numpy(cells.GetConnectivityArray()), connectivity)
        assert polygon_cells(counts, indices, (offsets, connectivity)).GetNumberOfCells() == len(counts)
        chosen = np.arange(len(counts))[::3]
        r_offsets, r_ids = reversed_faces(counts, indices, chosen)
        for j, f in enumerate(chosen):
            p = listed[f]
            assert r_ids[r_offsets[j]:r_offsets[j + 1]].tolist() == [p[0], *p[1:][::-1]]
        tri = fan_triangulate(counts[chosen], np.concatenate([listed[f] for f in chosen]))
        tri_back = fan_triangulate(np.diff(r_offsets), r_ids)

        def wound(t):   # each triangle turned to start at its smallest corner, its winding kept
            return {tuple(np.roll(x, -int(np.argmin(x)))) for x in t.tolist()}
        assert wound(tri_back[:, ::-1]) == wound(tri) and wound(tri_back).isdisjoint(wound(tri))
