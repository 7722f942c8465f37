"""Corrective speed on ICT FaceKit (26,719 vertices, 57 shapes).

Run: python -m pytest tests/benchmarks/test_bench_correctives.py --benchmark-only
Targets: a global pose with 20 correctives < 10 ms; the interference finder over all 57² pairs < 1 s.
"""
from __future__ import annotations

import numpy as np
import pytest

from model.correctives import Corrective, set_correctives
from model.pose import PoseEvaluator
from solvers.correctives import driver_region, rank_interference, shape_overlap, shape_overshoot
from solvers.laplacian import vertex_areas
from solvers.sculpt import SculptMesh, grab

# 14 pairs, 4 three-way and 2 four-way correctives on overlapping shapes, all four rules.
SETS = [
    ["browInnerUp_L", "browInnerUp_R"], ["browInnerUp_L", "browOuterUp_L"], ["browInnerUp_R", "browOuterUp_R"],
    ["browOuterUp_L", "browOuterUp_R"], ["browDown_L", "browDown_R"], ["jawOpen", "mouthLowerDown_L"],
    ["jawOpen", "mouthLowerDown_R"], ["jawOpen", "mouthSmile_L"], ["jawOpen", "mouthSmile_R"],
    ["mouthSmile_L", "cheekSquint_L"], ["mouthSmile_R", "cheekSquint_R"], ["mouthFunnel", "mouthPucker"],
    ["eyeBlink_L", "eyeSquint_L"], ["eyeBlink_R", "eyeSquint_R"],
    ["browInnerUp_L", "browInnerUp_R", "browOuterUp_L"], ["browInnerUp_L", "browInnerUp_R", "browOuterUp_R"],
    ["jawOpen", "mouthSmile_L", "mouthSmile_R"], ["jawOpen", "mouthLowerDown_L", "mouthLowerDown_R"],
    ["browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R"],
    ["jawOpen", "mouthSmile_L", "mouthSmile_R", "mouthLowerDown_L"],
]
RULES = ["hierarchical", "product", "min", "smooth-min"]


@pytest.fixture(scope="module")
def rig20(ict_rig):
    rig = ict_rig.copy()
    rng = np.random.default_rng(0)
    cs = []
    for k, drivers in enumerate(SETS):
        idx = [rig.shape_index(d) for d in drivers]
        region = driver_region(rig.deltas[idx])
        delta = region[:, None] * (-0.3 * rig.deltas[idx].sum(axis=0) + rng.normal(scale=0.01, size=(rig.n_vertices, 3)))
        cs.append(Corrective(drivers=drivers, rule=RULES[k % 4], delta=delta))
    set_correctives(rig, cs)
    return rig


def test_evaluate_pose_with_20_correctives(benchmark, rig20):
    assert len(rig20.correctives) == 20
    ev = PoseEvaluator(rig20)
    w = np.random.default_rng(1).uniform(0, 1, rig20.n_shapes)
    out = np.empty((rig20.n_vertices, 3), np.float32)
    x = benchmark(ev.evaluate, w, out)
    assert np.all(ev.activations(w) > 0)
    assert x.shape == (26719, 3)


def test_evaluate_pose_with_20_correctives_cold(benchmark, rig20):
    """A fresh evaluator for one pose, as the command line's ``export`` and ``render`` pose a rig."""
    w = np.random.default_rng(1).uniform(0, 1, rig20.n_shapes)
    x = benchmark(lambda: PoseEvaluator(rig20).evaluate(w))
    assert x.shape == (26719, 3)


@pytest.fixture(scope="module")
def areas(ict_rig):
    """The neutral's vertex areas: the finder weights every measure by them, as the Correctives panel does."""
    return vertex_areas(ict_rig.neutral, ict_rig.triangles())


def test_interference_finder_all_pairs(benchmark, ict_rig, areas):
    top = benchmark.pedantic(lambda: rank_interference(ict_rig.deltas, 10, areas=areas), rounds=5, iterations=1)
    assert len(top) == 10


def test_interference_finder_directional(benchmark, ict_rig, areas):
    O = benchmark.pedantic(shape_overlap, args=(ict_rig.deltas, True, areas), rounds=3, iterations=1)
    assert O.shape == (57, 57)


def test_interference_finder_overshoot(benchmark, ict_rig, areas):
    O = benchmark.pedantic(shape_overshoot, args=(ict_rig.deltas,), kwargs={"areas": areas}, rounds=3, iterations=1)
    assert O.shape == (57, 57)


def test_grab_stroke_symmetric(benchmark, ict_rig):
    mesh = SculptMesh.build(ict_rig.neutral, ict_rig.triangles())
    c = ict_rig.neutral[6156]
    out = benchmark(grab, ict_rig.neutral, c, [0.1, 0.2, 0.3], 1.5, "smooth", 1.0, mesh, True)
    assert out.shape == (26719, 3)
