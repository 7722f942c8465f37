"""The thin-plate surface warp (solvers.surface_warp, Botsch & Sorkine 2008) against an independent reference:
the same energy written from its definition (per-triangle cotangents in a loop, dense matrices, least squares
by numpy) on a small curved sheet; and the behaviour a marker warp relies on: a translation of every handle moves
the whole surface (a Gaussian RBF decays to zero between and beyond its centres and fails this), the handles
are met, the field is the same in any unit, and ℓ sets how far a handle carries."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.rbf import RBFResidual
from solvers.surface_warp import biharmonic_warp


def _sheet(n=13, size=10.0):
    u = np.linspace(0.0, size, n)
    X, Y = np.meshgrid(u, u, indexing="ij")
    V = np.column_stack([X.ravel(), Y.ravel(), 0.04 * (X.ravel() - 5.0) ** 2 + 0.02 * X.ravel() * Y.ravel()])
    q = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    T = np.concatenate([np.column_stack([q, q + n, q + 1]), np.column_stack([q + 1, q + n, q + n + 1])])
    return V, T


def _handles(V, idx):
    return sp.csr_matrix((np.ones(len(idx)), (np.arange(len(idx)), idx)), shape=(len(idx), len(V)))


def _reference(V, T, idx, d, length, stiffness=1e3):
    """E(u) from its definition: K_vu = ½(cot α + cot β) off the diagonal, rows summing to zero; A_v a third of
    the areas around v; minimise ‖A^-½ K u‖² + ℓ⁻⁴‖A^½ u‖² + w‖u[idx] − d‖² by dense least squares."""
    n = len(V)
    K = np.zeros((n, n))
    A = np.zeros(n)
    for tri in T:
        for k in range(3):
            i, j, o = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            a, b = V[i] - V[o], V[j] - V[o]
            cot = a @ b / np.linalg.norm(np.cross(a, b))
            K[i, j] += cot / 2
            K[j, i] += cot / 2
        A[tri] += np.linalg.norm(np.cross(V[tri[1]] - V[tri[0]], V[tri[2]] - V[tri[0]])) / 6
    K -= np.diag(K.sum(axis=1))
    w = stiffness * np.mean(np.diag(K @ np.diag(1 / A) @ K))
    S = np.zeros((len(idx), n))
    S[np.arange(len(idx)), idx] = 1.0
    M = np.vstack([K / np.sqrt(A)[:, None], np.diag(np.sqrt(A)) / length ** 2, np.sqrt(w) * S])
    rhs = np.vstack([np.zeros((n, 3)), np.zeros((n, 3)), np.sqrt(w) * d])
    return np.linalg.lstsq(M, rhs, rcond=None)[0]


def test_the_warp_is_the_minimiser_of_its_energy_written_independently():
    V, T = _sheet()
    idx = np.array([20, 45, 84, 100, 130])
    d = np.random.default_rng(5).normal(scale=0.3, size=(5, 3))
    for length in (3.0, 20.0):
        u = biharmonic_warp(V, T, _handles(V, idx), d, length=length)
        ref = _reference(V, T, idx, d, length)
        assert np.abs(u - ref).max() < 1e-6 * np.abs(ref).max()


def test_a_translation_of_the_handles_moves_the_whole_surface_and_units_do_not_matter():
    V, T = _sheet(n=31)
    idx = np.array([300, 480, 500, 620])
    shift = np.tile([0.2, -0.1, 0.3], (4, 1))
    u = biharmonic_warp(V, T, _handles(V, idx), shift, length=1e3)
    assert np.abs(u - shift[0]).max() < 1e-3 * 0.3                    # corners too, far outside the handles
    rbf = RBFResidual(V[idx], points=V, kernel="gaussian", scale=3.0, lam=1e-3)
    assert np.abs(rbf.evaluate(rbf.coefficients(shift)) - shift[0]).max() > 0.1    # the nearest wrong answer
    d = np.array([[0.0, 0.0, 0.5], [0.1, 0.0, -0.2], [0.0, 0.3, 0.1], [-0.2, 0.1, 0.0]])
    u_cm = biharmonic_warp(V, T, _handles(V, idx), d, length=4.0)
    assert np.abs(u_cm[idx] - d).max() < 1e-2 * np.abs(d).max()      # the handles are met
    u_mm = biharmonic_warp(10.0 * V, T, _handles(V, idx), 10.0 * d, length=40.0)
    assert np.allclose(u_mm, 10.0 * u_cm, atol=1e-6 * np.abs(u_mm).max())
    far = int(np.argmax(np.linalg.norm(V - V[idx].mean(axis=0), axis=1)))
    short = biharmonic_warp(V, T, _handles(V, idx), d, length=1.0)   # ℓ: how far a handle carries
    assert np.linalg.norm(short[far]) < 0.5 * np.linalg.norm(u_cm[far])
