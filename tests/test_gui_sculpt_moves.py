"""The sculpt tool's moves on ICT FaceKit in the main window (pytest-qt, real mouse events): what a pick under the
brush cursor finds against VTK's own pass over every face, one frame a move, and a grab stroke's result against the
brush computed independently (``tests/benchmarks/test_bench_sculpt.py`` measures the moves)."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore

from tests.gui_helpers import make_window

PAIR = ["browInnerUp_L", "browInnerUp_R"]


@pytest.fixture
def sculpting(qtbot, tmp_path, ict_rig):
    """The window on ICT sculpting the browInnerUp pair with the grab brush: (window, frame counter)."""
    import vtk
    from model.project import Project
    w = make_window(qtbot, tmp_path, size=(1400, 900), sample=False)
    w.document.set_project(Project(rig=ict_rig.copy()), None)
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=30000)
    ctrl = w.correctives
    ctrl.dock.show()
    assert ctrl.start_authoring(PAIR)
    ctrl.set_brush("grab")
    ctrl.panel.radius.setValue(2.0)
    _settle(qtbot, w)
    frames = [0]
    w.viewport.plotter.ren_win.AddObserver(vtk.vtkCommand.StartEvent,
                                           lambda *_: frames.__setitem__(0, frames[0] + 1))
    return w, frames


def _settle(qtbot, w):
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=30000)
    QtCore.QCoreApplication.processEvents()


def _brute_force_pick(vp, x, y):
    """VTK's cell picker without a locator (a pass over every face of every pickable actor), as the viewport
    picked before: (the face of the surface, the point), or None."""
    from vtkmodules.vtkRenderingCore import vtkCellPicker

    from widgets.scene import surface_face
    picker = vtkCellPicker()
    picker.SetTolerance(0.0005)
    if not picker.Pick(x, y, 0, vp.plotter.renderer) or picker.GetCellId() < 0:
        return None
    face = surface_face(vp.mesh, picker.GetDataSet(), picker.GetCellId())
    if vp.shown_faces is not None:
        face = int(vp.shown_faces[face])   # the rig's face number, hidden parts counted
    return face, np.array(picker.GetPickPosition())


def _compare_picks(vp, step):
    """Pick on a grid of pixels over the view, both ways: (pixels on the surface, pixels off it)."""
    w, h = vp.plotter.window_size
    on = off = 0
    for x in range(3, w - 3, step):
        for y in range(3, h - 3, step):
            hit, ref = vp.pick(x, y), _brute_force_pick(vp, x, y)
            assert (hit is None) == (ref is None), (x, y)
            if hit is None:
                off += 1
                continue
            assert hit.face == ref[0], (x, y)
            np.testing.assert_array_equal(hit.position, ref[1])
            on += 1
    return on, off


def test_a_pick_finds_what_vtks_pass_over_every_face_finds(qtbot, sculpting):
    """The pick under the cursor (through cell locators) finds the face and point VTK's picker finds going through
    every face, on a grid of pixels over the face, before and after a stroke moves the surface (the locators follow
    the points) and with a part hidden (the hidden faces are not picked)."""
    w, _ = sculpting
    vp = w.viewport
    on, off = _compare_picks(vp, 17)
    assert on > 400 and off > 400
    doc = w.document
    doc.set_edit_offset(np.tile([0.0, 0.0, 3.0], (doc.rig.n_vertices, 1)) * (doc.rig.neutral[:, 1:2] > 5))
    _settle(qtbot, w)
    on, off = _compare_picks(vp, 23)
    assert on > 200 and off > 200
