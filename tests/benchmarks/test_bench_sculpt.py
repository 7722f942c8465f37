"""The sculpt tool's grab brush and its cursor in the main window on ICT FaceKit (26,719 vertices), at the window's
default size (1400x900) under Xvfb, software OpenGL: real mouse events on the viewport in sculpt mode (the
browInnerUp pair being authored, symmetric strokes).

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_sculpt.py --benchmark-only -s

- ``test_bench_sculpt_grab_move``: a press on the forehead, then moves with the button held, each timed from the
  event to the rendered frame (the stroke, the document's edit offset, the cursor, the window's coalesced render).
- ``test_bench_sculpt_hover_move``: moves with no button over the face, the brush cursor following (a pick, the
  cursor, a render).
- ``test_bench_studio_sculpt_grab_move``: the grab stroke on the 228-shape studio rigs (ICT subdivided to 106k and
  422k vertices), the two shapes that overlap most authored; the proxy (``widgets.lod``) draws the stroke's frames.
Printed: the min / median wall and CPU time a move, and the frames drawn a move.

Before (the code as it was, 2026-12-05, 2-core shared VM, llvmpipe; min / median): a grab move 44-56 / 45-74 ms,
CPU 65-94 ms (two frames a move: the cursor's render, then the window's redraw of the pulled surface; the
Correctives panel restyled at each offset change; ``sculpt.grab`` on the whole surface each move; each frame with
the translucent cursor through VTK's order-independent translucency, ~9 ms), a hover move 25-30 / 27-43 ms, CPU
37-50 ms (VTK's cell picker intersecting every one of the surface's 26k faces, ~15 ms, then the render).
After (the same, three runs alternated with the code before, 2026-12-06): a grab move 16-24 / 21-36 ms, CPU 24-35
ms (one frame); a hover move 17-25 / 21-34 ms, CPU 24-34 ms (the pick ~1 ms: ``widgets.picking``). What is left is
VTK's render of the surface (13-20 ms by the minute on this VM) and the normals (~2 ms).
"""
from __future__ import annotations

import time

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from tests.gui_helpers import mouse, sculpting_on_ict

PAIR = ["browInnerUp_L", "browInnerUp_R"]


@pytest.fixture
def sculpting(qtbot, tmp_path, ict_rig):
    """The main window at its default size on ICT, segmented, sculpting the browInnerUp pair with the grab brush:
    (window, the canvas, the Qt position of a forehead vertex, a frame counter)."""
    import vtk
    w = sculpting_on_ict(qtbot, tmp_path, ict_rig, PAIR)
    qtbot.wait(300)
    rig, vp = w.document.rig, w.viewport
    surface = w.document.surface()
    a, b = (np.linalg.norm(rig.deltas[rig.shape_index(n)], axis=1) for n in PAIR)
    both = np.flatnonzero((a > 0.2 * a.max()) & (b > 0.2 * b.max()))
    v = int(both[np.argmax(surface[both, 2] - 0.5 * np.abs(surface[both, 0]))])
    xd, yd, _ = vp.world_to_display(surface[v])[0]
    frames = [0]
    vp.plotter.ren_win.AddObserver(vtk.vtkCommand.StartEvent, lambda *_: frames.__setitem__(0, frames[0] + 1))
    print(f"\nviewport {vp.plotter.window_size} pixels in a {w.width()}x{w.height()} window")
    return w, vp.canvas, vp.display_to_qt(xd, yd), frames


def _until_drawn(w) -> None:
    """Run the event loop until the render the move asked for is done (the viewport's one coalesced render, on the
    loop's next turn), without qtbot.waitUntil's 10 ms sleeps between its looks."""
    deadline = time.perf_counter() + 5.0
    while w.redraw_pending:
        QtWidgets.QApplication.processEvents()
        assert time.perf_counter() < deadline, "the move's render never came"


def _timed_moves(qtbot, w, widget, positions, frames, buttons):
    wall, cpu, drawn = [], [], []
    for pos in positions:
        n0, t0, c0 = frames[0], time.perf_counter(), time.process_time()
        mouse(widget, "move", pos, buttons=buttons)   # sends the move, then runs the event loop once
        _until_drawn(w)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
        drawn.append(frames[0] - n0)
    return np.array(wall) * 1000, np.array(cpu) * 1000, drawn


def _report(benchmark, what, wall, cpu, drawn):
    benchmark.extra_info.update(wall_ms_median=round(float(np.median(wall)), 1),
                                cpu_ms_median=round(float(np.median(cpu)), 1))
    print(f"{what} on ICT: wall {wall.min():.1f} / {np.median(wall):.1f} ms a move (min / median), "
          f"CPU {cpu.min():.1f} / {np.median(cpu):.1f} ms; frames a move {sorted(set(drawn))}")


def test_bench_sculpt_grab_move(benchmark, qtbot, sculpting):
    w, widget, start, frames = sculpting
    doc = w.document
    steps = doc.undo_stack.count()
    mouse(widget, "press", start)
    path = [start + QtCore.QPointF(0.5 * (i % 40), -(i % 40)) for i in range(1, 61)]
    out = []

    def stroke():
        out.append(_timed_moves(qtbot, w, widget, path, frames, QtCore.Qt.LeftButton))

    benchmark.pedantic(stroke, rounds=1, iterations=1)
    mouse(widget, "release", path[-1])
    assert doc.undo_stack.count() == steps + 1 and np.abs(doc.edit_offset).max() > 0.1
    wall, cpu, drawn = out[0]
    _report(benchmark, "grab stroke move", wall[3:], cpu[3:], drawn)


def test_bench_sculpt_hover_move(benchmark, qtbot, sculpting):
    w, widget, start, frames = sculpting
    path = [start + QtCore.QPointF(2 * (i % 30) - 30, (i % 20) - 10) for i in range(60)]
    out = []

    def hover():
        out.append(_timed_moves(qtbot, w, widget, path, frames, QtCore.Qt.NoButton))

    benchmark.pedantic(hover, rounds=1, iterations=1)
    assert w.correctives.sculpt._cursor[1].visibility
    wall, cpu, drawn = out[0]
    _report(benchmark, "hover move", wall[3:], cpu[3:], drawn)


@pytest.mark.parametrize("levels", [1, 2])
def test_bench_studio_sculpt_grab_move(benchmark, qtbot, tmp_path, levels):
    import vtk

    from model.project import load_project
    from tests.benchmarks.test_bench_studio_memory import studio_project
    from tests.gui_helpers import make_window
    project = load_project(studio_project(levels))
    rig = project.rig
    reach = np.linalg.norm(rig.deltas[:24], axis=2)            # (24, V): the first shapes' displacements
    moved = reach > 0.2 * reach.max(axis=1, keepdims=True)
    overlap = moved.astype(np.float32) @ moved.T.astype(np.float32)
    np.fill_diagonal(overlap, 0)
    i, j = np.unravel_index(int(np.argmax(overlap)), overlap.shape)
    w = make_window(qtbot, tmp_path, size=(1400, 900), sample=False)
    w.document.set_project(project, None)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=600000)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=600000)
    w.segmentation.wait()
    ctrl = w.correctives
    ctrl.dock.show()
    assert ctrl.start_authoring([rig.shape_names[i], rig.shape_names[j]])
    ctrl.set_brush("grab")
    ctrl.panel.radius.setValue(2.0)
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=60000)
    qtbot.wait(500)
    vp = w.viewport
    surface = w.document.surface()
    both = np.flatnonzero(moved[i] & moved[j])
    v = int(both[np.argmax(surface[both, 2])])                 # the one nearest the camera
    xd, yd, _ = vp.world_to_display(surface[v])[0]
    start = vp.display_to_qt(xd, yd)
    frames = [0]
    vp.plotter.ren_win.AddObserver(vtk.vtkCommand.StartEvent, lambda *_: frames.__setitem__(0, frames[0] + 1))
    steps = w.document.undo_stack.count()
    mouse(vp.canvas, "press", start)
    path = [start + QtCore.QPointF(0.5 * (k % 20), -(k % 20)) for k in range(1, 31)]
    out = []
    benchmark.pedantic(lambda: out.append(_timed_moves(qtbot, w, vp.canvas, path, frames, QtCore.Qt.LeftButton)),
                       rounds=1, iterations=1)
    mouse(vp.canvas, "release", path[-1])
    assert w.document.undo_stack.count() == steps + 1 and np.abs(w.document.edit_offset).max() > 0.01
    wall, cpu, drawn = out[0]
    benchmark.extra_info.update(vertices=rig.n_vertices, wall_ms_median=round(float(np.median(wall[3:])), 1))
    print(f"\ngrab stroke move on the {rig.n_vertices:,}-vertex rig ({rig.shape_names[i]} + {rig.shape_names[j]}): "
          f"wall {wall[3:].min():.1f} / {np.median(wall[3:]):.1f} ms a move (min / median), CPU "
          f"{np.median(cpu[3:]):.1f} ms; frames a move {sorted(set(drawn[3:]))}")
