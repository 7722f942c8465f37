"""Foundation speed on ICT FaceKit: load the OBJ folder, evaluate a pose, save and reopen a project.

Run: python -m pytest tests/benchmarks --benchmark-only
Targets (issue 2): load < 2 s, evaluate < 2 ms, save < 0.5 s, reopen < 0.5 s.
BLAS runs with one thread, as in the app (``app.runtime.limit_blas_threads``, called by tests/conftest.py).
"""
from __future__ import annotations

import numpy as np

from app.runtime import blas_threads
from model.pose import PoseEvaluator
from model.project import Project, load_project, save_project
from model.readers import load_rig


def test_load_ict_folder(benchmark, ict_dir):
    rig = benchmark.pedantic(load_rig, args=(ict_dir,), rounds=3, iterations=1)
    assert rig.n_vertices == 26719


def test_evaluate_pose_all_shapes(benchmark, ict_rig):
    """Warm: the window's evaluator, built once per rig, evaluating one pose after another."""
    # BLAS runs single-threaded here as in the app (tests/conftest.py): a threaded gemv measured 12 ms, not 0.5
    threads = blas_threads()
    assert threads and set(threads.values()) == {1}, threads
    benchmark.extra_info["blas_threads"] = threads
    ev = PoseEvaluator(ict_rig)
    w = np.random.default_rng(0).uniform(0, 1, ict_rig.n_shapes)
    out = np.empty((ict_rig.n_vertices, 3), np.float32)
    x = benchmark(ev.evaluate, w, out)
    assert x.shape == (26719, 3)
    assert set(blas_threads().values()) == {1}


def test_evaluate_pose_all_shapes_cold(benchmark, ict_rig):
    """Cold: a fresh evaluator for one pose, as ``export`` and ``render`` on the command line pose a rig."""
    w = np.random.default_rng(0).uniform(0, 1, ict_rig.n_shapes)
    x = benchmark(lambda: PoseEvaluator(ict_rig).evaluate(w))
    assert x.shape == (26719, 3)


def test_save_project(benchmark, ict_rig, tmp_path):
    project = Project(rig=ict_rig)
    benchmark.pedantic(save_project, args=(project, tmp_path / "ict.bsproj"), rounds=5, iterations=1)


def test_reopen_project(benchmark, ict_rig, tmp_path):
    path = tmp_path / "ict.bsproj"
    save_project(Project(rig=ict_rig), path)
    p = benchmark.pedantic(load_project, args=(path,), rounds=5, iterations=1)
    assert p.rig.n_shapes == 57
