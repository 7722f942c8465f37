"""Segmentation speed on ICT FaceKit (26,719 vertices, 57 shapes).

Run: python -m pytest tests/benchmarks/test_bench_segmentation.py --benchmark-only
Targets (segmentation issue): all 57 maps < 0.3 s; re-threshold (maps cached, level 0) < 50 ms;
whole hierarchy (maps cached, everything else included) < 0.5 s.
"""
from __future__ import annotations

from model.segmentation import SegmentationCache, SegmentationSettings, segment_rig
from solvers.deformation_maps import deformation_maps
from solvers.laplacian import mesh_adjacency, uniform_laplacian


def _args(rig):
    return rig.neutral, rig.face_counts, rig.face_indices, rig.deltas


def test_laplacian_build(benchmark, ict_rig):
    L = benchmark(lambda: uniform_laplacian(mesh_adjacency(ict_rig.n_vertices, ict_rig.face_counts,
                                                           ict_rig.face_indices)))
    assert L.shape == (26719, 26719)


def test_maps_57_shapes(benchmark, ict_rig):
    L = uniform_laplacian(mesh_adjacency(ict_rig.n_vertices, ict_rig.face_counts, ict_rig.face_indices))
    maps = benchmark.pedantic(deformation_maps, args=(L, ict_rig.deltas), rounds=5, iterations=1)
    assert maps.per_shape.shape == (26719, 57)


def test_rethreshold_cached(benchmark, ict_rig):
    cache = SegmentationCache()
    segment_rig(*_args(ict_rig), cache=cache)
    ts = iter([0.45, 0.5, 0.55] * 100)  # around the default t
    seg = benchmark(lambda: segment_rig(*_args(ict_rig), SegmentationSettings(t=next(ts)), cache=cache,
                                        finest_only=True))
    assert len(seg.levels) == 1 and seg.levels[0].n_regions > 1


def test_whole_hierarchy_cached(benchmark, ict_rig):
    cache = SegmentationCache()
    segment_rig(*_args(ict_rig), cache=cache)
    seg = benchmark(lambda: segment_rig(*_args(ict_rig), cache=cache))
    assert seg.levels[-1].n_regions == 1


def test_whole_segmentation_from_scratch(benchmark, ict_rig):
    seg = benchmark.pedantic(lambda: segment_rig(*_args(ict_rig)), rounds=3, iterations=1)
    assert seg.levels[-1].n_regions == 1
