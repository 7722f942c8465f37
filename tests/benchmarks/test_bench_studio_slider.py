"""A shape-slider drag on a studio rig in the window (issue 20's studio scale): the 228-shape projects of
``test_bench_studio_memory`` (ICT subdivided to 106k and 422k vertices) open in the main window at its default
size, segmented, then a shape slider's handle dragged with real mouse moves, each step timed from the move to the
rendered frame (as ``test_bench_slider`` on ICT). Measured twice in one window: drawn in full every frame
(``SurfaceDetail.full_only``, what the viewport did before), then with the level of detail (``widgets.lod``: the
decimated proxy, ~100k triangles over the rig's own vertices, drawn while the renders follow each other). Printed:
the median step of each, the proxy's triangles and the seconds its decimation took on its worker thread; then the
project opened again, its proxy read from the cache instead of decimated again (seconds from loaded to ready).

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_studio_slider.py --benchmark-only -s
"""
from __future__ import annotations

import time

import numpy as np
import pytest
from PySide6 import QtCore

from tests.benchmarks.test_bench_studio_memory import studio_project
from tests.gui_helpers import make_window, mouse, press_shape_slider


@pytest.mark.parametrize("levels", [1, 2])
def test_bench_studio_slider_drag_step(benchmark, qtbot, tmp_path, levels):
    import vtk
    path = studio_project(levels)
    w = make_window(qtbot, tmp_path, size=(1400, 900))   # the main window's default size
    opened = time.perf_counter()
    w.open_path(path)
    qtbot.waitUntil(lambda: not w.is_loading, timeout=600000)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=600000)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=600000)
    ready = time.perf_counter() - opened
    qtbot.wait(500)
    vp = w.viewport
    faces = []
    surface = vp.plotter.actors["surface"]
    vp.plotter.ren_win.AddObserver(vtk.vtkCommand.EndEvent,
                                   lambda *_: faces.append(surface.GetMapper().GetInput().GetNumberOfPolys()))
    panel = w.shapes_panel
    if not all(r.built for r in panel.rows):
        panel.finish_rows()
    row = panel.rows[5]     # s005 (the studio shapes are named s000-s227), which moves the mouth and jaw
    slider, start = press_shape_slider(qtbot, w, row)
    travel = slider.width() - 2 * start.x()
    there = list(range(start.x() + 2, start.x() + travel, 2))
    xs = there + there[-2:0:-1]
    step = [0]

    def drag_step():
        mouse(slider, "move", QtCore.QPoint(xs[step[0] % len(xs)], start.y()))
        step[0] += 1
        if w.redraw_pending:
            qtbot.waitUntil(lambda: not w.redraw_pending, timeout=60000)

    vp.detail.full_only = True                     # every frame in full, as before the level of detail
    full = []
    for _ in range(12):
        t0 = time.perf_counter()
        drag_step()
        full.append(time.perf_counter() - t0)
    full_faces = faces[-1]
    vp.detail.full_only = False
    lod = []

    def timed_step():
        t0 = time.perf_counter()
        drag_step()
        lod.append(time.perf_counter() - t0)

    benchmark.pedantic(timed_step, rounds=30, iterations=1, warmup_rounds=2)
    proxy_faces = faces[-1]
    mouse(slider, "release", QtCore.QPoint(xs[(step[0] - 1) % len(xs)], start.y()))
    qtbot.waitUntil(lambda: not vp.detail.proxy_shown, timeout=5000)
    assert proxy_faces < full_faces and faces[-1] == full_faces   # the proxy while dragging, the rig once still
    np.testing.assert_allclose(vp.points(), w.document.surface(), atol=1e-3)
    full_ms, lod_ms = np.median(full[2:]) * 1000, np.median(lod[2:]) * 1000
    # opened again: the proxy read from the cache (``widgets.lod.cache_folder``), not decimated again
    reopened = time.perf_counter()
    w.open_path(path)
    qtbot.waitUntil(lambda: not w.is_loading, timeout=600000)
    loaded = time.perf_counter() - reopened
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=600000)
    again = time.perf_counter() - reopened
    benchmark.extra_info.update(vertices=w.document.rig.n_vertices, full_ms=round(full_ms, 1), lod_ms=round(lod_ms, 1),
                                proxy_triangles=proxy_faces, ready_s=round(ready, 1), reopened_ready_s=round(again, 1))
    print(f"\nslider drag step on a {w.document.rig.n_vertices:,}-vertex rig: {full_ms:.0f} ms drawn in full "
          f"({1000 / full_ms:.0f} fps, {full_faces:,} faces), {lod_ms:.0f} ms with the level of detail "
          f"({1000 / lod_ms:.0f} fps, {proxy_faces:,} triangles); opened, segmented and the proxy made in "
          f"{ready:.1f} s; "
          f"opened again: loaded in {loaded:.1f} s, its proxy (from the cache) {again - loaded:.2f} s after")
