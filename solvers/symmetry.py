"""Left/right symmetry of a face mesh across x = 0: the vertex mirror map, how far the mesh is from
symmetric, and mirror images of per-vertex fields and of segmentation regions. Pure numpy / scipy.

The mirror map is the nearest neutral vertex to each reflected vertex (scipy cKDTree), the usual way of
Maya's and Blender's position-based symmetry when the topology is not known to be symmetric.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

REFLECT_X = np.array([-1.0, 1.0, 1.0])  # M = diag(−1, 1, 1), the reflection across x = 0


def mirror_map(neutral, tolerance: float | None = None) -> np.ndarray:
    """(V,) index of each vertex's mirror image across x = 0: the nearest neutral vertex to (−x, y, z).

    With ``tolerance``, vertices whose reflection is farther than that from any vertex map to themselves.
    """
    p = np.asarray(neutral, dtype=np.float64)
    dist, idx = cKDTree(p).query(p * REFLECT_X)
    idx = idx.astype(np.int64)
    if tolerance is not None:
        idx[dist > tolerance] = np.flatnonzero(dist > tolerance)
    return idx


def mirror_error(neutral, mirror) -> np.ndarray:
    """(V,) distance from each vertex to the reflection of its mirror vertex, ‖M p(m(v)) − p(v)‖: 0 on an
    exactly symmetric mesh, large where the mesh has no mirror image."""
    p = np.asarray(neutral, dtype=np.float64)
    return np.linalg.norm(p[np.asarray(mirror, dtype=np.int64)] * REFLECT_X - p, axis=1)


def mirror_delta(delta, mirror) -> np.ndarray:
    """(V, 3) the other side's version of a corrective: e'(v) = M e(m(v)), M = diag(−1, 1, 1), the reflection
    across x = 0, with m the vertex mirror map (``mirror_map``); the mirror of a shape, as
    Maya's Mirror Target and Blender's Mirror Shape Key make it."""
    e = np.asarray(delta, dtype=np.float64)[np.asarray(mirror, dtype=np.int64)]
    e[:, 0] *= -1.0
    return e


def mirror_regions(blend, mirror) -> tuple[np.ndarray, np.ndarray]:
    """Which region of a segmentation level is the mirror image of which: (R,) partner index and (R,) match.

    ``blend`` (V, R) is the level's partition of unity φ_r (sparse or dense), ``mirror`` the vertex mirror map.
    Region r's mirror image is the r' whose φ_r' best matches φ_r∘m, by the cosine of the two columns; its
    match is that cosine (1 for an exactly mirrored region). A region on the midline is its own partner.
    """
    B = sp.csc_matrix(blend, dtype=np.float64)
    flipped = B[np.asarray(mirror, dtype=np.int64)]            # φ_r(m(v)) column by column
    dots = np.asarray((B.T @ flipped).todense())               # (R', R): ⟨φ_r', φ_r∘m⟩
    norms = np.sqrt(np.asarray(B.multiply(B).sum(axis=0))).ravel()
    fnorms = np.sqrt(np.asarray(flipped.multiply(flipped).sum(axis=0))).ravel()
    cos = dots / np.maximum(np.outer(norms, fnorms), 1e-300)
    partner = np.argmax(cos, axis=0)
    return partner, cos[partner, np.arange(cos.shape[1])]
