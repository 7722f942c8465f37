"""Global weights of a regional pose (solvers.surface_fit), against a dense bounded least squares on the
posed surface itself (scipy's BVLS), on the sample rig."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import lsq_linear

from solvers.surface_fit import global_weights_of_regional


def _blend(neutral, rng):
    """A smooth partition of unity over three regions: left, right and everything (the background)."""
    x = neutral[:, 0] / np.abs(neutral[:, 0]).max()
    left, right = np.clip(-x * 2, 0, 1), np.clip(x * 2, 0, 1)
    phi = np.stack([left, right, np.ones_like(x) * 0.2], axis=1)
    return sp.csr_matrix(phi / phi.sum(axis=1, keepdims=True))


def test_fit_matches_bvls_on_the_posed_surface(sample_rig):
    rng = np.random.default_rng(3)
    D = sample_rig.deltas
    K = D.shape[0]
    blend = _blend(sample_rig.neutral, rng)
    W = rng.uniform(0, 1, size=(4, 3, K)) * (rng.uniform(size=(4, 3, K)) < 0.3)
    got = global_weights_of_regional(D, blend, W)
    phi = blend.toarray()
    for f in range(W.shape[0]):
        per_vertex = phi @ W[f]                               # (V, K) blended weights
        target = np.einsum("vk,kvc->vc", per_vertex, D).reshape(-1)
        ref = lsq_linear(D.reshape(K, -1).T, target, bounds=(0, 1), method="bvls", tol=1e-14).x
        resid = lambda w: np.linalg.norm(D.reshape(K, -1).T @ w - target)
        assert resid(got[f]) <= resid(ref) * (1 + 1e-6) + 1e-9
        assert np.abs(got[f] - ref).max() < 1e-5


def test_a_pose_equal_in_every_region_comes_back_exactly(sample_rig):
    rng = np.random.default_rng(4)
    K = sample_rig.n_shapes
    w = rng.uniform(0, 1, K) * (rng.uniform(size=K) < 0.4)
    blend = _blend(sample_rig.neutral, rng)
    D = sample_rig.deltas
    got = global_weights_of_regional(D, blend, np.repeat(w[None], 3, axis=0))
    # the same surface (the weights themselves need not be unique: shapes can be linearly dependent)
    surface = lambda v: np.tensordot(v, D, axes=1)
    assert np.abs(surface(got) - surface(w)).max() < 1e-6 * np.abs(D).max()


def test_the_nearest_wrong_answer_the_background_row_alone_is_worse(sample_rig):
    """Exporting only the background row (what a per-region CSV read as global weights amounts to) fits the
    surface worse than the fit does."""
    rng = np.random.default_rng(5)
    D = sample_rig.deltas
    K = D.shape[0]
    blend = _blend(sample_rig.neutral, rng)
    W = np.zeros((3, K))
    W[:2, sample_rig.shape_index("mouthSmile_L")] = 1.0     # smile in both side regions, not the background
    fit = global_weights_of_regional(D, blend, W)
    target = np.einsum("vk,kvc->vc", blend.toarray() @ W, D).reshape(-1)
    err = lambda w: np.linalg.norm(D.reshape(K, -1).T @ w - target)
    assert err(W[-1]) > 0 and err(fit) < 0.5 * err(W[-1])
