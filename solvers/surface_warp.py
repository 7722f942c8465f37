"""A smooth deformation of a surface that carries a few bound points to where they were measured
(Botsch & Sorkine 2008, "On linear variational surface deformation methods", §3: the thin-plate energy
discretised by the cotangent Laplacian; Jacobson et al. 2010 for the mixed, mass-weighted bilaplacian).

The displacement field ``u`` (V × 3) of the surface minimises

    E(u) = Σ_axes  uᵀ K M⁻¹ K u  +  ℓ⁻⁴ uᵀ M u  +  w ‖B u − d‖²

* ``K`` the cotangent stiffness matrix (Pinkall & Polthier 1993; ``solvers.laplacian.cotangent_weights``
  minus their row sums), ``M`` the lumped vertex areas (Meyer et al. 2003): ``uᵀ K M⁻¹ K u`` is the discrete
  ∫‖Δu‖² dA, the bending of the displacement, so the field is as smooth as the handles allow and follows the
  surface (a lower lip's marker does not drag the upper lip across the mouth, as a Euclidean RBF would).
* ``ℓ⁻⁴ uᵀ M u`` keeps the field finite on parts no handle reaches (eyeballs, teeth) and sets how far a
  handle's displacement carries: ``ℓ`` is a length (the same warp in cm or mm with ``ℓ`` converted).
* ``w ‖B u − d‖²`` the handles: ``B`` (M × V) binds each measured point to the surface (one vertex or
  barycentric weights), ``d`` (M × 3) their displacements; ``w`` is ``stiffness`` times the bending matrix's
  mean diagonal, so the handles are met to within their noise whatever the units and the mesh density.

One sparse factorisation (SuperLU) and three back-substitutions: ~0.35 s on ICT's 26,719 vertices.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from .laplacian import cotangent_weights, vertex_areas


def biharmonic_warp(vertices: np.ndarray, triangles: np.ndarray, binding, displacement: np.ndarray, *,
                    length: float, stiffness: float = 1e3) -> np.ndarray:
    """(V, 3) displacement minimising the module's energy E(u): ``binding`` (M, V) sparse, ``displacement``
    (M, 3) of the bound points, ``length`` ℓ in the vertices' units."""
    X = np.asarray(vertices, dtype=np.float64)
    T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    B = sp.csr_matrix(binding, dtype=np.float64)
    d = np.asarray(displacement, dtype=np.float64).reshape(-1, 3)
    if B.shape != (d.shape[0], X.shape[0]):
        raise ValueError(f"binding {B.shape} does not match {d.shape[0]} displacements of {X.shape[0]} vertices")
    W = cotangent_weights(X, T)
    K = sp.csr_matrix(W - sp.diags(np.asarray(W.sum(axis=1)).ravel()))
    area = vertex_areas(X, T)
    floor = area[area > 0].min() if (area > 0).any() else 1.0
    area = np.maximum(area, floor)                   # vertices in no triangle: a small mass, no bending
    bend = K @ sp.diags(1.0 / area) @ K
    w = stiffness * float(bend.diagonal().mean())
    system = sp.csc_matrix(bend + sp.diags(area / float(length) ** 4) + w * (B.T @ B))
    solve = sla.factorized(system)
    rhs = w * (B.T @ d)
    return np.column_stack([solve(np.ascontiguousarray(rhs[:, a])) for a in range(3)])
