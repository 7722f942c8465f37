"""Segmentation from scratch as the rig grows: ICT FaceKit (26,719 vertices) and the studio rigs made from it
by midpoint subdivision (about 106k and 422k vertices, 57 shapes; tests/benchmarks/studio_rig.py, cached in
the temporary folder). The studio-scale issue's targets: ICT under 0.1 s, the 422k rig under 3 s, time
growing at most as V^1.2 (the fitted exponent is printed and kept in the benchmark's extra info).

Run: python -m pytest tests/benchmarks/test_bench_segmentation_scale.py --benchmark-only -s
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from model.segmentation import segment_rig
from tests.benchmarks.studio_rig import studio_rig

_TIMES: dict[int, float] = {}


@pytest.fixture(scope="module", autouse=True)
def _ict_present(ict_dir):
    return ict_dir


def test_subdivided_rig_keeps_ict_and_its_shapes(ict_rig):
    x, counts, idx, d = studio_rig(1)
    V = ict_rig.n_vertices
    assert np.array_equal(x[:V], ict_rig.neutral)                      # the original vertices come first
    assert np.allclose(d[:, :V], ict_rig.deltas, atol=1e-6)           # float32 cache
    assert (counts == 4).all() and idx.max() == x.shape[0] - 1
    assert 100_000 < x.shape[0] < 110_000
    # an edge midpoint sits halfway between its ends, in the neutral and in every shape
    e0 = idx[1]   # corner 0's next-edge midpoint of the first quad
    a, b = ict_rig.face_indices[0], ict_rig.face_indices[1]
    assert np.allclose(x[e0], 0.5 * (x[a] + x[b]))
    assert np.allclose(d[:, e0], 0.5 * (d[:, a] + d[:, b]), atol=1e-6)


@pytest.mark.parametrize("levels", [0, 1, 2])
def test_segmentation_from_scratch_by_size(benchmark, levels):
    x, counts, idx, d = studio_rig(levels)
    rig = (x, counts, idx, d.astype(np.float64))   # float64 deltas, as a Rig holds them (the cache keeps float32)
    segment_rig(*studio_rig(0))  # imports and first-call costs out of the timing

    def run():
        t0 = time.perf_counter()
        seg = segment_rig(*rig)
        _TIMES[rig[0].shape[0]] = min(_TIMES.get(rig[0].shape[0], np.inf), time.perf_counter() - t0)
        return seg
    seg = benchmark.pedantic(run, rounds=3 if levels < 2 else 1, iterations=1)
    assert seg.levels[-1].n_regions == 1
    benchmark.extra_info["vertices"] = int(rig[0].shape[0])
    if len(_TIMES) >= 2:
        v, t = np.log(list(_TIMES)), np.log(list(_TIMES.values()))
        exponent = float(np.polyfit(v, t, 1)[0])
        benchmark.extra_info["exponent"] = exponent
        print(f"\nsegmentation from scratch: {dict((k, round(s, 3)) for k, s in _TIMES.items())} s, "
              f"time ~ V^{exponent:.2f}")
