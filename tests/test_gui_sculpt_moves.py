"""The sculpt tool's moves on ICT FaceKit in the main window (pytest-qt, real mouse events): what a pick under the
brush cursor finds against VTK's own pass over every face, one frame a move, and a grab stroke's result against the
brush computed independently (``tests/benchmarks/test_bench_sculpt.py`` measures the moves)."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore

from tests.gui_helpers import mouse, sculpting_on_ict

PAIR = ["browInnerUp_L", "browInnerUp_R"]


@pytest.fixture
def sculpting(qtbot, tmp_path, ict_rig):
    """The window on ICT sculpting the browInnerUp pair with the grab brush: (window, frame counter)."""
    import vtk
    w = sculpting_on_ict(qtbot, tmp_path, ict_rig, PAIR)
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


def _forehead(w):
    """The Qt position of a front-facing vertex between the brows that both drivers move, and the vertex."""
    rig, surface = w.document.rig, w.document.surface()
    a, b = (np.linalg.norm(rig.deltas[rig.shape_index(n)], axis=1) for n in PAIR)
    both = np.flatnonzero((a > 0.2 * a.max()) & (b > 0.2 * b.max()))
    v = int(both[np.argmax(surface[both, 2] - 0.5 * np.abs(surface[both, 0]))])
    xd, yd, _ = w.viewport.world_to_display(surface[v])[0]
    return w.viewport.display_to_qt(xd, yd)


def _moves(qtbot, w, widget, positions, frames, buttons):
    """Real mouse moves, each followed by its redraw: the frames each drew."""
    drawn = []
    for pos in positions:
        n0 = frames[0]
        mouse(widget, "move", pos, buttons=buttons)
        qtbot.waitUntil(lambda: not w.redraw_pending, timeout=5000)
        drawn.append(frames[0] - n0)
    return drawn


@pytest.mark.parametrize("symmetric", [True, False])
def test_a_grab_stroke_draws_one_frame_a_move_and_pulls_as_the_brush_says(qtbot, sculpting, symmetric):
    """Each move of a grab stroke (real mouse events on ICT) draws one frame (the brush cursor's render and the
    window's redraw of the pulled surface were two), and the stroke's offset is the grab brush's pull of the surface
    by the view-plane motion from the press, about the point picked under it: exactly ``solvers.sculpt.grab``'s
    (symmetric), and the brush's formula computed here (one-sided)."""
    from solvers import sculpt
    w, frames = sculpting
    ctrl, doc, vp = w.correctives, w.document, w.viewport
    ctrl.panel.symmetric.setChecked(symmetric)
    settings = ctrl.panel.brush_settings()
    base = doc.surface().astype(np.float64)
    start = _forehead(w)
    widget = vp.canvas
    press = vp.qt_to_display(start.x(), start.y())
    centre = _brute_force_pick(vp, *press)[1]
    steps = doc.undo_stack.count()
    mouse(widget, "press", start)
    path = [start + QtCore.QPointF(0.5 * i, -2.0 * i) for i in range(1, 16)]
    drawn = _moves(qtbot, w, widget, path, frames, QtCore.Qt.LeftButton)
    mouse(widget, "release", path[-1])
    assert drawn == [1] * len(path), drawn
    assert doc.undo_stack.count() == steps + 1
    end = vp.qt_to_display(path[-1].x(), path[-1].y())
    motion = vp.view_plane_point(*end, centre) - vp.view_plane_point(*press, centre)
    assert motion[1] > 0.5                                  # pulled up on screen: +y from the front camera
    if symmetric:
        pulled = sculpt.grab(base, centre, motion, settings["radius"], settings["falloff"], settings["strength"],
                             mesh=ctrl.sculpt.mesh, symmetric=True, reference=base)
        np.testing.assert_array_equal(doc.edit_offset, pulled - base)
    else:
        t = np.clip(np.linalg.norm(base - centre, axis=1) / settings["radius"], 0.0, 1.0)
        weight = settings["strength"] * (1.0 - t * t * (3.0 - 2.0 * t))     # the smooth falloff
        assert settings["falloff"] == "smooth"
        np.testing.assert_allclose(doc.edit_offset, weight[:, None] * motion, rtol=0, atol=1e-12)
        assert np.count_nonzero(weight) > 50 and np.all(doc.edit_offset[weight == 0] == 0)
    np.testing.assert_allclose(vp.points(), doc.surface(), atol=1e-6)


def test_a_hover_draws_one_frame_a_move_with_the_cursor_on_the_surface(qtbot, sculpting):
    """A move with no button held over the face draws one frame, the brush cursor centred on the point under it
    (the surface as the last stroke left it); off the face, the cursor goes."""
    w, frames = sculpting
    vp = w.viewport
    start = _forehead(w)
    widget = vp.canvas
    mouse(widget, "press", start)
    for i in range(1, 6):
        mouse(widget, "move", start + QtCore.QPointF(0, -3.0 * i))
    mouse(widget, "release", start + QtCore.QPointF(0, -15.0))
    _settle(qtbot, w)
    path = [start + QtCore.QPointF(3.0 * i - 12, 2.0 * i) for i in range(8)]
    drawn = _moves(qtbot, w, widget, path, frames, QtCore.Qt.NoButton)
    assert drawn == [1] * len(path), drawn
    sphere, actor, _ = w.correctives.sculpt._cursor
    assert actor.visibility
    last = vp.qt_to_display(path[-1].x(), path[-1].y())
    np.testing.assert_allclose(np.asarray(sphere.points, dtype=np.float64).mean(axis=0),
                               _brute_force_pick(vp, *last)[1], atol=1e-5)
    drawn = _moves(qtbot, w, widget, [QtCore.QPointF(4, 4)], frames, QtCore.Qt.NoButton)
    assert not actor.visibility and drawn == [1]


def test_the_brush_cursor_looks_as_with_vtks_order_independent_translucency(qtbot, sculpting):
    """The translucent brush cursor over the face is blended as drawn (``Viewport``: no order-independent
    translucency, ~9 ms a frame less on llvmpipe): the picture is VTK's order-independent one within 3 levels."""
    w, frames = sculpting
    vp = w.viewport
    _moves(qtbot, w, vp.canvas, [_forehead(w)], frames, QtCore.Qt.NoButton)
    assert w.correctives.sculpt._cursor[1].visibility
    ren = vp.plotter.renderer
    drawn = vp.picture().astype(int)
    oit = ren.GetUseOIT()
    ren.SetUseOIT(True)
    try:
        reference = vp.picture().astype(int)
    finally:
        ren.SetUseOIT(oit)
    w.correctives.sculpt._cursor[1].visibility = False
    bare = vp.picture().astype(int)
    assert (np.abs(reference - bare).max(axis=2) > 20).sum() > 200      # the cursor shows
    assert np.abs(drawn - reference).max() <= 3


@pytest.mark.parametrize("brush", ["smooth", "inflate"])
def test_a_dab_stroke_draws_one_frame_a_move(qtbot, sculpting, brush):
    """The smooth and inflate brushes dab under the cursor at each move (a pick of the surface the last dab left):
    one frame a move (the cursor's render and the window's redraw were two), one undo step for the stroke, the
    surface changed under the cursor's path only."""
    w, frames = sculpting
    ctrl, doc, vp = w.correctives, w.document, w.viewport
    ctrl.set_brush(brush)
    start = _forehead(w)
    steps = doc.undo_stack.count()
    mouse(vp.canvas, "press", start)
    path = [start + QtCore.QPointF(2.0 * i, 0.5 * i) for i in range(1, 9)]
    drawn = _moves(qtbot, w, vp.canvas, path, frames, QtCore.Qt.LeftButton)
    mouse(vp.canvas, "release", path[-1])
    assert drawn == [1] * len(path), drawn
    assert doc.undo_stack.count() == steps + 1
    moved = np.linalg.norm(doc.edit_offset, axis=1)
    assert 0 < np.count_nonzero(moved) < doc.rig.n_vertices // 20
    np.testing.assert_allclose(vp.points(), doc.surface(), atol=1e-6)
