"""The Shapes panel's rows for a studio rig (issue 20's 228 and 700 shapes): how long the window is held while the
panel makes and lays out one row per shape (``ShapesPanel.set_shapes``, as opening a rig calls it, then the turns of
the event loop in which it makes the rest), measured as the longest gap between the ticks of a 2 ms timer, and how
long until every row is made. Before the rows were shown inside a hidden host (``widgets.shapes_panel._layout_held``)
each shown row laid the host out again: 0.51 s for 228 shapes and 2.62 s for 700 (2026-12-03, the same machine);
made in one go after that, 228 rows held the window 0.26-0.33 s and 700 rows 0.72-1.05 s (2026-12-04). A studio
list's rows are now made 32 a turn after the first 32, those in view first (``ROWS_AT_ONCE``).

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_shapes_panel.py --benchmark-only -s
"""
from __future__ import annotations

import time

import numpy as np
import pytest
from PySide6 import QtCore


@pytest.mark.parametrize("n_shapes", [228, 700])
def test_bench_shapes_panel_rows(benchmark, qtbot, tmp_path, n_shapes):
    from tests.gui_helpers import shapes_panel_alone
    panel = shapes_panel_alone(qtbot, tmp_path, (420, 900))
    names = [f"shape{i:03d}_{'L' if i % 2 else 'R'}" for i in range(n_shapes)]
    ticks: list[float] = []
    timer = QtCore.QTimer()
    timer.setInterval(2)
    timer.timeout.connect(lambda: ticks.append(time.perf_counter()))
    timer.start()
    freezes, made = [], []

    def fill():
        ticks.clear()
        t0 = time.perf_counter()
        panel.set_shapes(names)
        qtbot.waitUntil(lambda: all(r.built for r in panel.rows), timeout=60000)
        made.append(time.perf_counter() - t0)
        qtbot.wait(50)                       # the layout and paint events the last rows posted
        t = np.array([t0] + [x for x in ticks if x >= t0])
        freezes.append(float(np.diff(t).max()))

    def empty():
        panel.set_shapes([])
        qtbot.wait(50)
        return (), {}

    benchmark.pedantic(fill, setup=empty, rounds=3, iterations=1)
    timer.stop()
    assert len(panel.rows) == n_shapes and all(r.isVisibleTo(panel) and r.built for r in panel.rows)
    benchmark.extra_info.update(shapes=n_shapes, longest_freeze_s=min(freezes), all_made_s=min(made))
    print(f"\nShapes panel, {n_shapes} rows: the window's longest freeze {min(freezes):.2f} s (best of "
          f"{len(freezes)}; runs {', '.join(f'{f:.2f}' for f in freezes)}), every row made and shown after "
          f"{min(made):.2f} s")
