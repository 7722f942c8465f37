"""Antagonist pairs (solvers.antagonists, ALGORITHMS.md §13) against a plain loop over the pairs, each pair's
shared support, cosine and overlap computed on its own from the rule's words; both ways the pairs are summed:
the compiled kernel (vertex by vertex, solvers.shape_kernels_jit) and the matrix products where it is not built."""
from __future__ import annotations

import numpy as np
import pytest

from solvers import take_kernel
from solvers.antagonists import antagonist_pairs


@pytest.fixture(params=["compiled", "matrix products"])
def summed(request, monkeypatch):
    """Which way ``antagonist_pairs`` sums the pairs in the test: (name, calls of the compiled kernel), so that a
    test of the compiled way fails if the matrix products ran instead."""
    calls = []
    if request.param == "compiled":
        take_kernel.kernel()            # the ahead-of-time build, where this machine has none yet (once, ~20 s)
        module = take_kernel.built()
        if module is None:
            pytest.skip("the kernel cannot be compiled ahead of time here (no C compiler)")
        kernel = module.antagonist_sums
        monkeypatch.setattr(module, "antagonist_sums", lambda *args: calls.append(1) or kernel(*args))
    else:
        monkeypatch.setattr(take_kernel, "built", lambda: None)
    return request.param, calls


def _check_the_way(summed):
    name, calls = summed
    assert bool(calls) == (name == "compiled"), f"summed by the {'matrix products' if not calls else 'kernel'}"


def _by_loop(D, cosine=-0.5, support=0.1, overlap=0.5):
    K = D.shape[0]
    norms = [np.linalg.norm(D[k], axis=1) for k in range(K)]
    acts = [norms[k] > support * norms[k].max() for k in range(K)]
    out = []
    for i in range(K):
        for j in range(i + 1, K):
            if norms[i].max() == 0 or norms[j].max() == 0:
                continue
            both = acts[i] & acts[j]
            if both.sum() < max(1, overlap * min(acts[i].sum(), acts[j].sum())):
                continue
            di, dj = D[i][both], D[j][both]
            c = float((di * dj).sum() / np.sqrt((di * di).sum() * (dj * dj).sum()))
            if c < cosine:
                out.append((i, j, c))
    return sorted(out, key=lambda p: p[2])


def _assert_same(got, expected):
    assert [p[:2] for p in got] == [p[:2] for p in expected]
    assert np.allclose([p[2] for p in got], [p[2] for p in expected], rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_pairs_of_local_random_shapes_match_the_loop(seed, summed):
    # shapes acting on bumps of a strip of vertices; some made as the negative of another (plus noise and a
    # shift of their bump), some still, so that every branch of the rule (too little overlap, cosine above
    # the limit, a shape that moves nothing) is taken
    # (local as a face's shapes are: a few act at each vertex, so the compiled way is the one taken)
    rng = np.random.default_rng(seed)
    V, K = 1500, 16
    x = np.arange(V)
    D = np.zeros((K, V, 3))
    for k in range(K):
        centre, width = rng.integers(0, V), rng.integers(8, 40)
        D[k] = np.exp(-0.5 * ((x - centre) / width) ** 2)[:, None] * rng.normal(size=3)
    for k in range(0, K - 1, 3):
        shift = int(rng.integers(-10, 11))
        D[k + 1] = -np.roll(D[k], shift, axis=0) + 0.2 * rng.normal(size=(V, 3)) * (np.abs(D[k]) > 0.05)
    D[K - 1] = 0.0
    expected = _by_loop(D)
    assert expected, "no pair found: the test lost its point"
    _assert_same(antagonist_pairs(D), expected)
    _assert_same(antagonist_pairs(D, cosine=-0.2, overlap=0.3), _by_loop(D, cosine=-0.2, overlap=0.3))
    _check_the_way(summed)


def test_ict_pairs_match_the_loop(ict_rig, summed):
    expected = _by_loop(ict_rig.deltas)
    assert len(expected) > 10
    _assert_same(antagonist_pairs(ict_rig.deltas), expected)
    _check_the_way(summed)


def test_broad_shapes_are_summed_by_the_matrix_products(summed):
    # every shape acting at every vertex (a rig of global shapes): the per-vertex pairs would be all the pairs, so
    # the vectorised matrix products are taken either way, with the same answer as the loop
    rng = np.random.default_rng(7)
    D = rng.normal(size=(10, 300, 3))
    D[1] = -D[0] + 0.3 * rng.normal(size=(300, 3))
    expected = _by_loop(D)
    assert expected
    _assert_same(antagonist_pairs(D), expected)
    assert summed[1] == []
