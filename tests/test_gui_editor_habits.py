"""The editor as riggers use it, with real input events (issue 18): the Shapes panel and opening files."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from tests.gui_helpers import make_window

pytestmark = pytest.mark.gui


def _focus(qtbot, widget):
    """Give ``widget`` the keyboard focus as a click would (its window active first, as under a window manager)."""
    window = widget.window()
    window.activateWindow()
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is window, timeout=5000)
    widget.setFocus(QtCore.Qt.MouseFocusReason)
    inside = {widget, *widget.findChildren(QtWidgets.QWidget)}
    qtbot.waitUntil(lambda: QtWidgets.QApplication.focusWidget() in inside, timeout=5000)


def _type_weight(qtbot, box, text):
    _focus(qtbot, box)
    qtbot.keyClick(box.lineEdit(), QtCore.Qt.Key_A, QtCore.Qt.ControlModifier)
    qtbot.keyClicks(box.lineEdit(), text)
    qtbot.keyClick(box.lineEdit(), QtCore.Qt.Key_Return)


def test_active_shows_only_the_shapes_in_use(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    panel = w.shapes_panel
    _type_weight(qtbot, panel.row("jawOpen").box, "0.5")
    qtbot.mouseClick(panel.active_only, QtCore.Qt.LeftButton)
    assert panel.active_only.isChecked()
    visible = [r.name for r in panel.rows if r.isVisibleTo(panel)]
    assert visible == ["jawOpen"]
    qtbot.mouseClick(panel.active_only, QtCore.Qt.LeftButton)
    assert all(r.isVisibleTo(panel) for r in panel.rows)


def test_many_rows_shown_at_once_keep_the_keyboard_focus_where_it_was(qtbot, tmp_path):
    """When many rows appear or disappear at once (a new rig, a filter, Active with a new pose), the panel lays
    them out once instead of once per row (quadratic: 2 s for 700 shapes) by holding its rows' host hidden
    meanwhile; the number box being typed in keeps the keyboard focus, and every row ends as it should be."""
    from tests.gui_helpers import shapes_panel_alone
    panel = shapes_panel_alone(qtbot, tmp_path)
    names = [f"shape{i:03d}" for i in range(120)]
    panel.set_shapes(names)
    QtWidgets.QApplication.processEvents()
    assert all(r.isVisibleTo(panel) for r in panel.rows)
    w = np.zeros(len(names))
    w[0] = 0.5
    panel.set_weights(w)
    qtbot.mouseClick(panel.active_only, QtCore.Qt.LeftButton)
    assert [r.name for r in panel.rows if r.isVisibleTo(panel)] == ["shape000"]
    box = panel.rows[0].box
    _focus(qtbot, box)
    w[1:61] = 0.25                                     # 60 rows appear at once
    panel.set_weights(w)
    QtWidgets.QApplication.processEvents()
    assert [r.name for r in panel.rows if r.isVisibleTo(panel)] == names[:61]
    assert QtWidgets.QApplication.focusWidget() in (box, box.lineEdit())
    qtbot.mouseClick(panel.active_only, QtCore.Qt.LeftButton)
    assert all(r.isVisibleTo(panel) for r in panel.rows)


def _wheel(widget, notches=-3) -> bool:
    """A wheel event over ``widget``; returns whether the widget kept it (accepted) or left it to its parents."""
    pos = QtCore.QPointF(widget.width() / 2, widget.height() / 2)
    glob = QtCore.QPointF(widget.mapToGlobal(pos.toPoint()))
    ev = QtGui.QWheelEvent(pos, glob, QtCore.QPoint(0, 0), QtCore.QPoint(0, 120 * notches), QtCore.Qt.NoButton,
                           QtCore.Qt.NoModifier, QtCore.Qt.NoScrollPhase, False)
    QtWidgets.QApplication.sendEvent(widget, ev)
    return ev.isAccepted()


def test_the_wheel_over_the_list_changes_no_weight(qtbot, tmp_path):
    """A wheel notch over a row's slider or number box is left to the list (Qt passes an event the widget does
    not accept to its parents: the scroll area scrolls); only a control the user clicked first takes it."""
    w = make_window(qtbot, tmp_path, size=(1200, 600))
    panel = w.shapes_panel
    steps = w.document.undo_stack.count()
    row = panel.rows[2]
    w.viewport.setFocus()
    for widget in (row.slider, row.box):
        assert not _wheel(widget)
    QtWidgets.QApplication.processEvents()
    assert np.all(w.document.weights == 0) and w.document.undo_stack.count() == steps
    bar = panel.scroll.verticalScrollBar()
    assert bar.maximum() > 0
    _wheel(panel.scroll.viewport())
    assert bar.value() > 0                      # where the slider left it, the list scrolls
    _focus(qtbot, row.slider)
    assert _wheel(row.slider, notches=1)
    assert w.document.weights[row.index] > 0


def test_ctrl_z_undoes_while_a_number_box_has_focus(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    box = w.shapes_panel.row("jawOpen").box
    _type_weight(qtbot, box, "0.6")
    i = w.document.rig.shape_index("jawOpen")
    assert w.document.weights[i] == pytest.approx(0.6)
    focus = QtWidgets.QApplication.focusWidget()
    assert focus in (box, box.lineEdit())
    qtbot.keyClick(focus, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)
    assert w.document.weights[i] == 0.0 and box.value() == 0.0
    qtbot.keyClick(focus, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    assert w.document.weights[i] == pytest.approx(0.6)


def test_no_opening_dialog_stays_up_after_an_open(qtbot, tmp_path, ict_rig):
    """The 'Opening…' dialog must go when the open ends: it came back (window-modal, no Cancel) after every
    project open and after an error box."""
    from model.project import Project, save_project
    from tests.gui_helpers import open_and_wait
    w = make_window(qtbot, tmp_path)
    path = tmp_path / "ict.bsproj"
    save_project(Project(rig=ict_rig), path)

    def shown():
        return [d.labelText() for d in QtWidgets.QApplication.topLevelWidgets()
                if isinstance(d, QtWidgets.QProgressDialog) and d.isVisible()]
    for target in (path, path, tmp_path / "missing.bsproj"):
        open_and_wait(qtbot, w, target)
        qtbot.wait(1500)                       # well past the dialog's own 300 ms show delay
        assert shown() == [], target
