"""Segmentation from scratch as the rig grows: ICT FaceKit (26,719 vertices) and the studio rigs made from it
by midpoint subdivision (about 106k and 422k vertices, 57 shapes; tests/benchmarks/studio_rig.py, cached in
the temporary folder). The studio-scale issue's targets: ICT under 0.1 s, the 422k rig under 3 s, time
growing at most as V^1.2 (the fitted exponent is printed and kept in the benchmark's extra info). And what the window
runs when the 228-shape studio projects open (106k / 422k vertices): the segmentation and every level's region
statistics, with the peak memory they add (no target; the figures are in the README).

Run: python -m pytest tests/benchmarks/test_bench_segmentation_scale.py --benchmark-only -s
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from model.segmentation import segment_rig
from tests.benchmarks.studio_rig import MEMORY_PROBE, studio_rig

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
    seg = benchmark.pedantic(run, rounds=3, iterations=1)   # the exponent from every size's best of three
    assert seg.levels[-1].n_regions == 1
    benchmark.extra_info["vertices"] = int(rig[0].shape[0])
    if len(_TIMES) >= 2:
        v, t = np.log(list(_TIMES)), np.log(list(_TIMES.values()))
        exponent = float(np.polyfit(v, t, 1)[0])
        benchmark.extra_info["exponent"] = exponent
        print(f"\nsegmentation from scratch: {dict((k, round(s, 3)) for k, s in _TIMES.items())} s, "
              f"time ~ V^{exponent:.2f}")


_STUDIO = MEMORY_PROBE + """
from app.runtime import limit_blas_threads
limit_blas_threads()                       # as the window and the command line run
from model.readers import load_rig
from model.segmentation import SegmentationCache, region_statistics, segment_rig
rig = load_rig(sys.argv[1])
before = reset_peak()
t0 = time.perf_counter()
cache = SegmentationCache()
seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, cache=cache)
t1 = time.perf_counter()
stats = [region_statistics(seg, cache.maps(), rig.shape_names, level=i) for i in range(len(seg.levels))]
t2 = time.perf_counter()
print(json.dumps({"segment_s": t1 - t0, "statistics_s": t2 - t1, "regions": [l.n_regions for l in seg.levels],
                  "growth": status("VmHWM") - before, "deltas": rig.deltas.nbytes, "vertices": rig.n_vertices,
                  "stages": seg.seconds}))
"""


@pytest.mark.parametrize("levels", [1, 2])
def test_bench_segmentation_of_the_228_shape_studio_rig(benchmark, levels):
    """What the window runs when a studio rig opens (``app.segmentation_controller``): the segmentation from scratch
    and every level's region statistics, on the 228-shape projects of ``test_bench_studio_memory`` (106k / 422k
    vertices), in a fresh process; its peak memory growth over the rig it segments is printed against the deltas."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    from tests.benchmarks.test_bench_studio_memory import studio_project
    path = studio_project(levels)
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))

    def run():
        out = subprocess.run([sys.executable, "-c", _STUDIO, str(path)], capture_output=True, text=True, env=env,
                             cwd=root, check=True, timeout=1800)
        return json.loads(out.stdout.strip().splitlines()[-1])

    r = benchmark.pedantic(run, rounds=1, iterations=1)
    assert r["regions"][-1] == 1 and r["regions"][0] > 10
    growth = r["growth"] / r["deltas"]
    benchmark.extra_info.update(vertices=r["vertices"], segment_s=r["segment_s"], statistics_s=r["statistics_s"],
                                peak_growth_over_deltas=growth, stages=r["stages"])
    print(f"\n{r['vertices']:,} vertices, 228 shapes: segmented in {r['segment_s']:.2f} s "
          f"({', '.join(f'{k} {v:.2f}' for k, v in r['stages'].items() if k != 'total')}), region statistics of "
          f"{len(r['regions'])} levels {r['statistics_s']:.2f} s; peak memory +{r['growth'] / 2**30:.2f} GiB "
          f"({growth:.2f}x the deltas' {r['deltas'] / 2**30:.2f} GiB)")
