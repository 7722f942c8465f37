"""Nudging a region's vertices, to author a new shape (ALGORITHMS.md §11; Acosta 2015)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError
from .mesh import fan_triangulate

from .normals import vertex_normals


def polygon_normals(positions: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray) -> np.ndarray:
    """(V, 3) unit vertex normals of a polygon mesh: the sum of the area vectors of the (fanned) polygons
    around each vertex (``solvers.normals.vertex_normals``); vertices in no polygon get a zero normal."""
    return vertex_normals(positions, fan_triangulate(face_counts, face_indices))


def nudge_region(positions: np.ndarray, vertices: np.ndarray, amount: float, *,
                 direction="out", weights: np.ndarray | None = None,
                 face_counts: np.ndarray | None = None, face_indices: np.ndarray | None = None,
                 normals: np.ndarray | None = None) -> np.ndarray:
    """(V, 3) positions with a region nudged (Acosta 2015, segment mode; ALGORITHMS.md §11).

    ``x'(v) = x(v) + amount · φ(v) · u(v)`` for v in ``vertices`` (everything else unchanged), where φ are
    the region's blend weights (a soft edge; 1 if ``weights`` is None) and u is the unit vertex normal
    (``direction`` 'out'), its opposite ('in'), or a given 3-vector (a view-space direction already
    expressed in rig coordinates, normalised here). Normals are computed from the polygons unless given.
    """
    X = np.asarray(positions, dtype=np.float64)
    idx = np.asarray(vertices, dtype=np.int64).ravel()
    if idx.size and (idx.min() < 0 or idx.max() >= X.shape[0]):
        raise RigInputError("The region refers to a vertex that does not exist.")
    w = np.ones(idx.size) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    if w.size != idx.size:
        raise RigInputError(f"The region has {idx.size} vertices but {w.size} blend weights.")
    if isinstance(direction, str):
        if direction not in ("out", "in"):
            raise RigInputError(f"Unknown nudge direction '{direction}': use 'in', 'out' or a 3D vector.")
        if normals is None:
            if face_counts is None or face_indices is None:
                raise RigInputError("Nudging along the normal needs the rig's faces to compute normals.")
            normals = polygon_normals(X, face_counts, face_indices)
        u = np.asarray(normals, dtype=np.float64)[idx] * (1.0 if direction == "out" else -1.0)
    else:
        d = np.asarray(direction, dtype=np.float64).ravel()
        if d.size != 3 or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise RigInputError("The nudge direction must be a non-zero 3D vector.")
        u = np.broadcast_to(d / np.linalg.norm(d), (idx.size, 3))
    out = X.copy()
    out[idx] += float(amount) * w[:, None] * u
    return out


def ring_falloff(adjacency: sp.spmatrix, core: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """(len(vertices),) nudge weights of a region: 1 on its ``core``, falling smoothly over the overlap rings
    (the rest of ``vertices``) to 0 just outside the region, so a nudge moves the region, not a cliff.

    A vertex ``d`` rings from the core (graph distance in ``adjacency`` (V, V), walking inside the region) of a
    region ``n`` rings wide gets ``s(1 − d / (n + 1))``, s the smoothstep ``3x² − 2x³`` (zero slope at both ends).
    A region vertex the core cannot reach inside the region gets 0.
    """
    A = sp.csr_matrix(adjacency)
    idx = np.asarray(vertices, dtype=np.int64).ravel()
    core = np.asarray(core, dtype=np.int64).ravel()
    inside = np.zeros(A.shape[0], dtype=bool)
    inside[idx] = True
    if not inside[core].all():
        raise RigInputError("The region's core must lie among its vertices.")
    dist = np.full(A.shape[0], -1, dtype=np.int64)
    dist[core] = 0
    frontier, d = core, 0
    while frontier.size:
        d += 1
        nb = np.unique(A[frontier].indices)
        nb = nb[inside[nb] & (dist[nb] < 0)]
        dist[nb] = d
        frontier = nb
    rings = dist[idx]
    width = max(int(rings.max(initial=0)), 0) + 1
    x = np.where(rings >= 0, 1.0 - rings / width, 0.0)
    return x * x * (3.0 - 2.0 * x)
