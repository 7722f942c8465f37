"""Polygon-mesh helpers shared by the solvers (no model objects: counts and flat indices)."""
from __future__ import annotations

import numpy as np


def bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): the smallest and largest value of each column of (n, k) values, (V, 3) points or any other
    (``points.min(axis=0)``, ``points.max(axis=0)``, the same numbers; points given flat are read as (V, 3)), column
    by column: numpy reduces a (V, 3) array along its first axis in a loop over the short inner axis, 12 ms a
    reduction at 422k vertices against 0.2 ms for a column."""
    p = np.asarray(points)
    if p.ndim != 2:
        p = p.reshape(-1, 3)
    if not len(p):
        raise ValueError("bounds of no points")
    columns = range(p.shape[1])
    return np.array([p[:, i].min() for i in columns]), np.array([p[:, i].max() for i in columns])


def extent(points: np.ndarray) -> float:
    """The length of the bounding box's diagonal (``‖ptp(points, axis=0)‖``)."""
    lo, hi = bounds(points)
    return float(np.linalg.norm(hi - lo))


def fan_triangulate(face_counts: np.ndarray, face_indices: np.ndarray) -> np.ndarray:
    """(T, 3) triangles of polygons given as counts + flat indices (fan from each first vertex)."""
    counts = np.asarray(face_counts, dtype=np.int64)
    idx = np.asarray(face_indices)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    ntri = np.maximum(counts - 2, 0)
    face_of_tri = np.repeat(np.arange(counts.size), ntri)
    k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)  # triangle number in face
    s = starts[face_of_tri]
    return np.stack([idx[s], idx[s + k + 1], idx[s + k + 2]], axis=1).astype(np.int32)


def cell_layout(face_counts: np.ndarray, face_indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(offsets, connectivity), int64: the polygons in VTK's cell array layout (``vtkCellArray.SetData``), polygon
    ``f``'s corners being ``connectivity[offsets[f]:offsets[f + 1]]``."""
    counts = np.asarray(face_counts, dtype=np.int64)
    offsets = np.zeros(counts.size + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets, np.ascontiguousarray(face_indices, dtype=np.int64)


def reversed_faces(face_counts: np.ndarray, face_indices: np.ndarray,
                   faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``cell_layout`` of the polygons ``faces`` (indices, in order), each reversed with its first corner kept:
    (i0, ik, ..., i1), so that a fan splits it into the same triangles, facing the other way."""
    counts = np.asarray(face_counts, dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    n = counts[faces]
    offsets = np.concatenate(([0], np.cumsum(n)))
    k = np.arange(offsets[-1]) - np.repeat(offsets[:-1], n)            # corner number in its face
    corner = np.where(k == 0, 0, np.repeat(n, n) - k)
    return offsets, np.asarray(face_indices, dtype=np.int64)[np.repeat(starts[faces], n) + corner]


HIDDEN_BACK_OPENING = 0.01   # a part counts as closed when at most this share of its edges lie on openings


def hidden_back_faces(points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray) -> np.ndarray:
    """(F,) bool: the polygons whose back side cannot be seen from outside the mesh, so a renderer may cull
    them when they face away from the camera.

    A polygon qualifies when its connected part (polygons sharing vertices) is a closed surface wound
    consistently outward: every edge is used by exactly two of its polygons, once in each direction, apart
    from a small opening (at most ``HIDDEN_BACK_OPENING`` of its edges lie on an edge used once: a head's cut
    at the neck, 54 of ICT FaceKit's 56k skin edges), and its signed volume about its centroid is positive
    (normals outward). A ray from outside meets such a surface on its front first, except through the
    opening. Open sheets (eyelashes, a face mask, a mouth bag seen from inside) and parts wound inward or
    inconsistently do not qualify: their back sides show.
    """
    counts = np.asarray(face_counts, dtype=np.int64)
    idx = np.asarray(face_indices, dtype=np.int64)
    n_faces = counts.size
    if n_faces == 0:
        return np.zeros(0, dtype=bool)
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    p = np.asarray(points, dtype=np.float64)
    n_points = p.shape[0]
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    face_of_corner = np.repeat(np.arange(n_faces), counts)
    incidence = sp.csr_matrix((np.ones(idx.size, dtype=np.int8), (face_of_corner, idx)), shape=(n_faces, n_points))
    n_parts, vertex_part = connected_components(incidence.T @ incidence, directed=False)
    part = vertex_part[idx[starts]]                              # (F,) each polygon's part
    # directed edges corner -> next corner of the same polygon
    nxt = np.arange(idx.size) + 1
    nxt[np.cumsum(counts) - 1] = starts
    a, b = idx, idx[nxt]
    edge_part = part[face_of_corner]
    undirected = np.minimum(a, b) * n_points + np.maximum(a, b)
    order = np.argsort(undirected, kind="stable")
    key = undirected[order]
    first = np.concatenate(([True], key[1:] != key[:-1]))
    run = np.diff(np.concatenate((np.flatnonzero(first), [key.size])))   # uses of each undirected edge
    run_part = edge_part[order][first]
    edges = np.bincount(run_part, minlength=n_parts)
    openings = np.bincount(run_part, weights=run == 1, minlength=n_parts)
    non_manifold = np.bincount(run_part, weights=run > 2, minlength=n_parts)
    directed = a * n_points + b
    by_directed = np.argsort(directed, kind="stable")
    directed = directed[by_directed]
    repeated = directed[1:] == directed[:-1]                     # an edge twice in one direction: flipped faces
    twice = np.bincount(edge_part[by_directed][1:][repeated], minlength=n_parts)
    # signed volume of each part about its centroid (fan triangles: v0 . (v1 x v2) / 6)
    tris = fan_triangulate(counts, idx).astype(np.int64)
    tri_part = np.repeat(part, np.maximum(counts - 2, 0))
    centroid = np.stack([np.bincount(vertex_part, weights=p[:, c], minlength=n_parts) for c in range(3)], axis=1)
    centroid /= np.maximum(np.bincount(vertex_part, minlength=n_parts), 1)[:, None]
    q = p[tris] - centroid[tri_part][:, None, :]
    volume = np.bincount(tri_part, weights=np.einsum("ij,ij->i", q[:, 0], np.cross(q[:, 1], q[:, 2])),
                         minlength=n_parts)
    closed = (non_manifold == 0) & (twice == 0) & (openings <= HIDDEN_BACK_OPENING * edges) & (volume > 0)
    return closed[part]
