"""The Shapes panel's rows for a studio rig (issue 20's 228 and 700 shapes): how long the window is held while the
panel makes and lays out one row per shape (``ShapesPanel.set_shapes``, as opening a rig calls it, then the layout
and paint events it posted). Before the rows were shown inside a hidden host (``widgets.shapes_panel._layout_held``)
each shown row laid the host out again: 0.51 s for 228 shapes and 2.62 s for 700 (2026-12-03, the same machine).

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_shapes_panel.py --benchmark-only -s
"""
from __future__ import annotations

import time

import pytest
from PySide6 import QtWidgets


@pytest.mark.parametrize("n_shapes", [228, 700])
def test_bench_shapes_panel_rows(benchmark, qtbot, tmp_path, n_shapes):
    from tests.gui_helpers import shapes_panel_alone
    panel = shapes_panel_alone(qtbot, tmp_path, (420, 900))
    names = [f"shape{i:03d}_{'L' if i % 2 else 'R'}" for i in range(n_shapes)]
    times = []

    def fill():
        t0 = time.perf_counter()
        panel.set_shapes(names)
        QtWidgets.QApplication.processEvents()
        times.append(time.perf_counter() - t0)

    def empty():
        panel.set_shapes([])
        QtWidgets.QApplication.processEvents()
        return (), {}

    benchmark.pedantic(fill, setup=empty, rounds=3, iterations=1)
    assert len(panel.rows) == n_shapes and all(r.isVisibleTo(panel) for r in panel.rows)
    benchmark.extra_info.update(shapes=n_shapes, seconds=min(times))
    print(f"\nShapes panel, {n_shapes} rows made and laid out: {min(times):.2f} s (best of {len(times)})")
