"""Deformation maps (ALGORITHMS.md §2; Joshi et al. 2003, §2; Acosta 2015 for the displacement map).

Per-shape Laplacian magnitude ``m_k(v) = ‖L d_k(v)‖``, combined map ``M(v) = max_k m_k(v)``, the arg-max
shape and its Laplacian vector (the RGB view), and the plain displacement map ``max_k ‖d_k(v)‖``.
All K shapes go through the Laplacian as ONE sparse product.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError

MAP_KINDS = ("laplacian", "displacement")


@dataclass
class DeformationMaps:
    """Arrays of the deformation maps of one rig (V vertices, K shapes).

    per_shape     (V, K) ``m_k(v) = ‖L d_k(v)‖``.
    combined      (V,)   ``M(v) = max_k m_k(v)``.
    argmax_shape  (V,)   int, the k reaching the maximum (0 where every shape is still).
    vector        (V, 3) ``L d_k(v)`` of the arg-max shape (x, y, z → R, G, B in the vector view).
    displacement  (V,)   ``max_k ‖d_k(v)‖``.
    """

    per_shape: np.ndarray
    combined: np.ndarray
    argmax_shape: np.ndarray
    vector: np.ndarray
    displacement: np.ndarray

    def values(self, kind: str) -> np.ndarray:
        """The scalar map a segmentation thresholds: 'laplacian' (M) or 'displacement'."""
        if kind == "laplacian":
            return self.combined
        if kind == "displacement":
            return self.displacement
        raise RigInputError(f"Unknown map '{kind}': use 'laplacian' or 'displacement'.")


def _check_deltas(deltas: np.ndarray, n_vertices: int) -> np.ndarray:
    d = np.asarray(deltas, dtype=np.float64)
    if d.ndim != 3 or d.shape[1:] != (n_vertices, 3):
        raise RigInputError(
            f"The shape deltas must be a (K, {n_vertices}, 3) array; got shape {tuple(d.shape)}.")
    return d


def laplacian_vectors(laplacian: sp.spmatrix, deltas: np.ndarray) -> np.ndarray:
    """(V, K, 3) Laplacian vectors ``L d_k(v)`` of all K shapes as one sparse product (Joshi et al. 2003, §2).

    ``(L d_k)(v) = (1/|N(v)|) Σ_{u∈N(v)} (d_k(u) − d_k(v))`` for the umbrella operator.
    """
    L = sp.csr_matrix(laplacian)
    V = L.shape[0]
    d = _check_deltas(deltas, V)
    K = d.shape[0]
    X = np.ascontiguousarray(d.transpose(1, 0, 2)).reshape(V, 3 * K)  # (V, 3K): one product for all shapes
    return np.asarray(L @ X).reshape(V, K, 3)


def laplacian_magnitudes(laplacian: sp.spmatrix, deltas: np.ndarray) -> np.ndarray:
    """(V, K) per-shape deformation maps ``m_k(v) = ‖L d_k(v)‖`` (Joshi et al. 2003, §2)."""
    Y = laplacian_vectors(laplacian, deltas)
    return np.sqrt(np.einsum("vkc,vkc->vk", Y, Y))


def displacement_map(deltas: np.ndarray) -> np.ndarray:
    """(V,) plain displacement map ``max_k ‖d_k(v)‖`` (Acosta 2015; ALGORITHMS.md §2); zeros if K = 0."""
    d = np.asarray(deltas, dtype=np.float64)
    if d.shape[0] == 0:
        return np.zeros(d.shape[1])
    return np.sqrt(np.einsum("kvc,kvc->kv", d, d).max(axis=0))


def deformation_maps(laplacian: sp.spmatrix, deltas: np.ndarray) -> DeformationMaps:
    """All deformation maps of a rig (Joshi et al. 2003, §2: ``m_k = ‖L d_k‖``, ``M = max_k m_k``).

    ``laplacian`` (V, V) sparse, from ``solvers.laplacian``; ``deltas`` (K, V, 3) with K ≥ 1.
    """
    L = sp.csr_matrix(laplacian)
    V = L.shape[0]
    d = _check_deltas(deltas, V)
    if d.shape[0] == 0:
        raise RigInputError("The rig has no blendshapes, so there is no deformation map to compute.")
    Y = laplacian_vectors(L, d)
    per_shape = np.sqrt(np.einsum("vkc,vkc->vk", Y, Y))
    arg = per_shape.argmax(axis=1)
    rows = np.arange(V)
    combined = per_shape[rows, arg]
    vector = Y[rows, arg]
    return DeformationMaps(per_shape=per_shape, combined=combined, argmax_shape=arg, vector=vector,
                           displacement=displacement_map(d))


def vector_colors(vector: np.ndarray, scale: float | None = None) -> np.ndarray:
    """(V, 3) RGB in [0, 1] for the vector view: x, y, z → R, G, B, ``0.5 + 0.5·v/scale`` (Joshi §2, Fig. 2).

    ``scale`` defaults to the largest component magnitude, so zero maps to mid-grey.
    """
    v = np.asarray(vector, dtype=np.float64)
    s = float(np.abs(v).max()) if scale is None else float(scale)
    if s <= 0:
        return np.full(v.shape, 0.5)
    return np.clip(0.5 + 0.5 * v / s, 0.0, 1.0)
