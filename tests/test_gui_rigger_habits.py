"""Issue 18's "What riggers expect" (the editor's part), driven with real input events: keys of one shape, the
Graph Editor, next/previous key, frame selected / frame all, files dropped on the window, image export at a
size, the first start, Marker mode's button, status messages in the user's words."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from tests.gui_helpers import make_window, open_and_wait
from tests.test_gui_editor_habits import _focus

pytestmark = pytest.mark.gui


def _key(qtbot, widget, key, modifier=QtCore.Qt.NoModifier):
    _focus(qtbot, widget)
    qtbot.keyClick(widget, key, modifier)
    QtWidgets.QApplication.processEvents()


def _pose(w, **weights) -> np.ndarray:
    rig = w.document.rig
    p = np.zeros(rig.n_shapes)
    for name, v in weights.items():
        p[rig.shape_index(name)] = v
    w.set_pose(p, "pose")
    return p


def _context_menu(qtbot, widget) -> QtWidgets.QMenu:
    """Right-click ``widget`` (the context-menu event a right click sends) and return the menu it opens."""
    pos = QtCore.QPoint(widget.width() // 2, widget.height() // 2)
    ev = QtGui.QContextMenuEvent(QtGui.QContextMenuEvent.Mouse, pos, widget.mapToGlobal(pos))
    QtWidgets.QApplication.sendEvent(widget, ev)
    menu = widget.parent().context_menu
    qtbot.waitUntil(menu.isVisible, timeout=3000)
    return menu


def _choose(qtbot, menu: QtWidgets.QMenu, text: str) -> None:
    """Pick ``text`` in an open menu with the keyboard (Down until it is the active action, then Return)."""
    for _ in range(len(menu.actions()) + 1):
        qtbot.keyClick(menu, QtCore.Qt.Key_Down)
        if menu.activeAction() is not None and menu.activeAction().text() == text:
            break
    assert menu.activeAction().text() == text
    qtbot.keyClick(menu, QtCore.Qt.Key_Return)
    QtWidgets.QApplication.processEvents()


# --- keys of one shape ----------------------------------------------------------------------------------------------
def test_key_one_shape_from_its_slider_menu(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    kf, rig = w.keyframes, w.document.rig
    jaw, smile = rig.shape_index("jawOpen"), rig.shape_index("mouthSmile_L")
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S)          # the neutral pose keyed at 0 s
    kf.scrub(1.0)
    _pose(w, jawOpen=0.8, mouthSmile_L=0.6)
    steps = w.document.undo_stack.count()
    menu = _context_menu(qtbot, w.shapes_panel.row("jawOpen").slider)
    _choose(qtbot, menu, "Key jawOpen")
    assert w.document.undo_stack.count() == steps + 1
    assert [k.time for k in kf.timeline.keys] == [0.0, 1.0]
    key = kf.timeline.keys[1]
    assert key.keys_shape(jaw) and not key.keys_shape(smile)
    at_1 = kf.timeline.evaluate(1.0)
    assert at_1[jaw] == pytest.approx(0.8) and at_1[smile] == 0.0    # the smile was not keyed
    assert kf.timeline.evaluate(0.5)[jaw] == pytest.approx(0.4, abs=0.15)
    # saved and reopened, the key still keys jawOpen alone
    path = tmp_path / "keys.bsproj"
    assert w.save_to(path)
    open_and_wait(qtbot, w, path)
    key = w.keyframes.timeline.keys[1]
    assert key.keys_shape(jaw) and not key.keys_shape(smile)
    w.keyframes.set_shape_key(smile)      # the same time: the key now keys both, jawOpen unchanged
    assert w.keyframes.timeline.keys[1].keys_shape(smile)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)
    assert not w.keyframes.timeline.keys[1].keys_shape(smile)


def test_s_keys_only_the_shapes_selected_in_the_graph_editor(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    kf, rig = w.keyframes, w.document.rig
    jaw, smile = rig.shape_index("jawOpen"), rig.shape_index("mouthSmile_L")
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_G, QtCore.Qt.ControlModifier)   # Animation ▸ Graph Editor
    qtbot.waitUntil(kf.graph.isVisible, timeout=3000)
    item = kf.graph.list.item(jaw)
    kf.graph.list.scrollToItem(item)
    qtbot.mouseClick(kf.graph.list.viewport(), QtCore.Qt.LeftButton, pos=kf.graph.list.visualItemRect(item).center())
    assert kf.selected_shapes() == [jaw]
    kf.scrub(1.0)
    _pose(w, jawOpen=1.0, mouthSmile_L=1.0)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S)
    key = kf.timeline.key_at(1.0)
    assert key.keys_shape(jaw) and not key.keys_shape(smile)
    assert kf.graph.plot.shapes == [jaw] and [t for t, _ in kf.graph.plot.keys[jaw]] == [0.0, 1.0]


def _key_pos(plot, t, v) -> QtCore.QPoint:
    return plot.key_point(t, v).toPoint()


def test_graph_editor_moves_and_deletes_a_key_undoably_and_the_viewport_follows(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    kf, rig = w.keyframes, w.document.rig
    jaw = rig.shape_index("jawOpen")
    kf.set_key(0.0)
    kf.scrub(1.0)
    _pose(w, jawOpen=0.5)
    kf.set_key(1.0)
    kf.scrub(2.0)
    _pose(w)
    kf.set_key(2.0)
    kf.show_graph_editor()
    kf.graph_dock.resize(1200, 320)
    qtbot.waitUntil(lambda: kf.graph.plot.isVisible() and kf.graph.plot.height() > 120, timeout=3000)
    kf.graph.select_shapes([jaw])
    kf.scrub(1.0)
    plot = kf.graph.plot
    assert plot.shapes == [jaw] and plot.keys[jaw] == [(0.0, 0.0), (1.0, 0.5), (2.0, 0.0)]
    steps = w.document.undo_stack.count()
    # drag the middle key half a second later and up to about 0.9
    start = _key_pos(plot, 1.0, 0.5)
    end = _key_pos(plot, 1.5, 0.9)
    qtbot.mousePress(plot, QtCore.Qt.LeftButton, pos=start)
    for f in np.linspace(0, 1, 6)[1:]:
        qtbot.mouseMove(plot, QtCore.QPoint(int(start.x() + f * (end.x() - start.x())),
                                            int(start.y() + f * (end.y() - start.y()))))
    qtbot.mouseRelease(plot, QtCore.Qt.LeftButton, pos=end)
    assert w.document.undo_stack.count() == steps + 1
    times = [k.time for k in kf.timeline.shape_keys(jaw)]
    assert times == [0.0, pytest.approx(1.5), 2.0]
    moved = kf.timeline.key_at(1.5).weights[jaw]
    assert moved == pytest.approx(0.9, abs=0.03)
    # the timeline's key ticks and the viewport follow: at 1.5 s the face shows the moved key
    assert kf.panel.ruler.keys == [0.0, 1.0, pytest.approx(1.5), 2.0]   # 1.0 still keys the other shapes
    kf.scrub(1.5)
    assert w.document.weights[jaw] == pytest.approx(moved)
    # undo puts it back, and the pose shown at the current time follows
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)
    assert [k.time for k in kf.timeline.shape_keys(jaw)] == [0.0, 1.0, 2.0]
    assert w.document.weights[jaw] == pytest.approx(kf.timeline.evaluate(1.5)[jaw])
    # select the middle key with a click, Delete removes it (undoably)
    qtbot.mouseClick(plot, QtCore.Qt.LeftButton, pos=_key_pos(plot, 1.0, 0.5))
    assert plot.selected_key == (jaw, 1.0)
    qtbot.keyClick(plot, QtCore.Qt.Key_Delete)
    assert [k.time for k in kf.timeline.shape_keys(jaw)] == [0.0, 2.0]
    assert w.document.weights[jaw] == pytest.approx(0.0)
    assert plot.keys[jaw] == [(0.0, 0.0), (2.0, 0.0)]
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)
    assert [k.time for k in kf.timeline.shape_keys(jaw)] == [0.0, 1.0, 2.0]
    assert kf.time == 1.5 and w.document.weights[jaw] == pytest.approx(0.3125)   # smooth between 0.5 and 0


def test_period_and_comma_go_to_the_next_and_previous_key(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    kf = w.keyframes
    for t in (0.0, 0.5, 1.25):
        kf.set_key(t)
    kf.scrub(0.0)
    steps = w.document.undo_stack.count()
    canvas = w.viewport.canvas
    _key(qtbot, canvas, QtCore.Qt.Key_Period)
    assert kf.time == 0.5
    _key(qtbot, canvas, QtCore.Qt.Key_Period)
    assert kf.time == 1.25
    _key(qtbot, canvas, QtCore.Qt.Key_Period)       # no key after the last: stays
    assert kf.time == 1.25
    _key(qtbot, canvas, QtCore.Qt.Key_Comma)
    assert kf.time == 0.5
    assert w.document.undo_stack.count() == steps     # navigation, not an edit
