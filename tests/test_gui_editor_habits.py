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


def _row_state(r) -> tuple:
    """What a row shows: name label, weight on the slider and in the box, mute, solo, range, bold, selected."""
    return (r.label.text(), r.label.toolTip(), r.slider.value(), r.box.value(), r.box.minimum(), r.box.maximum(),
            r.box.toolTip(), r.mute.isChecked(), r.solo.isChecked(), r.label.isEnabled(), r.label.styleSheet(),
            r.label.foregroundRole(), r.slider.objectName(), r.mute.toolTip())


def _fill(panel, names):
    """A studio rig's list as opening it fills the panel: names, then weights, mute/solo/ranges, a selection."""
    panel.set_shapes(names)
    w = np.zeros(len(names))
    w[[3, 150, 290]] = [0.5, 0.25, 1.5]
    panel.set_weights(w)
    panel.set_shape_info(muted=[names[150]], solo=[names[40]], ranges={names[290]: (-1.0, 2.0)},
                         inbetweens={names[200]: [0.5]})
    panel.select(names[250])


def test_a_studio_rigs_rows_are_made_a_few_dozen_a_turn_those_in_view_first(qtbot, tmp_path, monkeypatch):
    """300 shapes: the first rows are made at once, the rest on the next turns of the event loop (those scrolled
    into view first), each empty row as tall as a made one so the list never jumps; every row ends showing its
    shape's weight, mute, solo, range, in-betweens and selection as a list made in one go does, and a row asked for
    (a test, a rename) is made on the spot."""
    from tests.gui_helpers import shapes_panel_alone
    from widgets import shapes_panel as sp
    names = [f"shape{i:03d}" for i in range(300)]
    panel = shapes_panel_alone(qtbot, tmp_path)
    _fill(panel, names)
    built = [r.built for r in panel.rows]
    assert built[:sp.ROWS_AT_ONCE] == [True] * sp.ROWS_AT_ONCE and not any(built[sp.ROWS_AT_ONCE:])
    QtWidgets.QApplication.sendPostedEvents()
    bottom = panel.rows[-1].geometry().bottom()
    bar = panel.scroll.verticalScrollBar()
    bar.setValue(bar.maximum())                     # scrolled to the end before the middle rows are made
    qtbot.waitUntil(lambda: panel.rows[-1].built, timeout=5000)
    assert not all(r.built for r in panel.rows), "the rows in view come before the rest"
    qtbot.waitUntil(lambda: all(r.built for r in panel.rows), timeout=10000)
    QtWidgets.QApplication.processEvents()
    assert panel.rows[-1].geometry().bottom() == bottom
    assert panel.row(names[290]).slider.value() == panel.row(names[290])._to_steps(1.5)

    monkeypatch.setattr(sp, "ALL_AT_ONCE", 1000)   # the same list made in one go
    whole = shapes_panel_alone(qtbot, tmp_path)
    _fill(whole, names)
    assert all(r.built for r in whole.rows)
    assert [_row_state(r) for r in panel.rows] == [_row_state(r) for r in whole.rows]
    assert _row_state(panel.rows[150]) != _row_state(panel.rows[151])     # muted and weighted: not a blank row
    assert "◆" in panel.row(names[200]).label.text() and panel.row(names[40]).solo.isChecked()

    monkeypatch.setattr(sp, "ALL_AT_ONCE", 64)
    late = shapes_panel_alone(qtbot, tmp_path)
    _fill(late, names)
    row = late.row(names[299])
    assert not row.built
    assert row.slider.maximum() == sp.SLIDER_STEPS and row.built   # made when asked for, with its state
    assert _row_state(row) == _row_state(whole.rows[299])


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


def test_the_preset_list_and_apply_are_enabled_only_with_presets(qtbot, tmp_path):
    """A rig without presets (ICT FaceKit) opened straight into a new window left the empty preset list and its
    Apply button enabled (Apply did nothing, silently): they follow the presets there are, from the first rig on."""
    from tests.gui_helpers import shapes_panel_alone
    panel = shapes_panel_alone(qtbot, tmp_path)
    panel.set_shapes(["jawOpen", "mouthSmile_L"], [])
    assert not panel.presets.isEnabled() and not panel.apply_preset.isEnabled()
    panel.set_shapes(["jawOpen", "mouthSmile_L"], ["happy"])
    assert panel.presets.isEnabled() and panel.apply_preset.isEnabled()
    panel.set_shapes(["jawOpen"], [])
    assert not panel.presets.isEnabled() and not panel.apply_preset.isEnabled()


def test_an_arkit_named_rig_offers_the_emotion_presets(qtbot, tmp_path, ict_dir):
    """ICT FaceKit (ARKit's shape names with _L/_R, no presets.json) opened with an empty, disabled preset list,
    though the README promises the emotion presets: a rig gets those whose every shape it has (model.presets)."""
    from model.presets import EMOTIONS
    from tests.gui_helpers import open_and_wait
    w = make_window(qtbot, tmp_path, size=(1400, 900), sample=False)
    open_and_wait(qtbot, w, ict_dir)
    panel = w.shapes_panel
    assert [panel.presets.itemText(i) for i in range(panel.presets.count())] == sorted(EMOTIONS)
    assert panel.presets.isEnabled() and panel.apply_preset.isEnabled()
    panel.presets.setCurrentIndex(panel.presets.findText("surprised"))
    qtbot.mouseClick(panel.apply_preset, QtCore.Qt.LeftButton)
    rig = w.document.rig
    expected = np.zeros(rig.n_shapes)
    for name, value in EMOTIONS["surprised"].items():
        expected[rig.shape_index(name)] = value
    np.testing.assert_allclose(w.document.weights, expected)


def test_a_rigs_own_presets_are_its_whole_list_and_other_names_get_none(tmp_path, ict_dir):
    import json
    import shutil
    from model.readers import load_rig
    folder = tmp_path / "rig"
    folder.mkdir()
    for name in ("generic_neutral_mesh.obj", "jawOpen.obj", "mouthSmile_L.obj"):
        shutil.copy(ict_dir / name, folder / name)
    assert load_rig(folder).presets == {}          # no emotion preset has only these shapes
    (folder / "presets.json").write_text(json.dumps({"gape": {"jawOpen": 1.0}}))
    assert load_rig(folder).presets == {"gape": {"jawOpen": 1.0}}


def test_the_shapes_panels_controls_are_whole_at_its_narrowest(qtbot, tmp_path):
    """At the Shapes panel's minimum width (400 px, its dock's default) every control above the list gets at least
    its size hint: the grouping box sat at the end of the edit buttons' row and was cut to "No grc"."""
    from tests.gui_helpers import shapes_panel_alone
    panel = shapes_panel_alone(qtbot, tmp_path, size=(400, 300))
    panel.set_shapes(["browDown_L", "browDown_R", "jawOpen"], [])
    qtbot.waitUntil(lambda: panel.width() == 400)
    controls = [panel.grouping, panel.active_only, panel.apply_preset, panel.reset, *panel.buttons.values()]
    assert all(c.width() >= c.sizeHint().width() for c in controls), \
        [(type(c).__name__, c.width(), c.sizeHint().width()) for c in controls]


def test_the_preset_list_shows_no_preset_until_one_is_chosen(qtbot, tmp_path):
    """The preset list showed its first preset ("afraid") as chosen on a rig just opened, so choosing it was no
    change at all (no currentIndexChanged) and the list claimed a preset nobody had chosen: it says "Choose a preset…"
    until the user picks one. Apply with none chosen opens the list and changes nothing."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    panel, doc = w.shapes_panel, w.document
    box = panel.presets
    assert box.count() > 0 and box.isEnabled()
    assert box.currentIndex() == -1 and box.currentText() == "" and box.placeholderText() == "Choose a preset…"
    steps, before = doc.undo_stack.count(), doc.weights.copy()
    qtbot.mouseClick(panel.apply_preset, QtCore.Qt.LeftButton)      # nothing chosen: the list opens
    qtbot.waitUntil(lambda: box.view().isVisible(), timeout=3000)
    assert doc.undo_stack.count() == steps and np.array_equal(doc.weights, before)
    qtbot.keyClick(box.view(), QtCore.Qt.Key_Escape)
    qtbot.waitUntil(lambda: not box.view().isVisible(), timeout=3000)
    assert box.currentIndex() == -1
    first = box.itemText(0)
    box.setFocus()
    with qtbot.waitSignal(box.currentIndexChanged, timeout=3000) as sig:
        qtbot.keyClick(box, QtCore.Qt.Key_Down)                      # the first preset: a change
    assert sig.args == [0] and box.currentText() == first
    qtbot.mouseClick(panel.apply_preset, QtCore.Qt.LeftButton)
    rig = doc.rig
    expected = np.zeros(rig.n_shapes)
    for name, value in rig.presets[first].items():
        expected[rig.shape_index(name)] = value
    np.testing.assert_allclose(doc.weights, expected)
    assert doc.undo_stack.count() == steps + 1
    # the shape list changing (a rename) keeps the chosen preset
    panel.set_shapes(rig.shape_names, [box.itemText(i) for i in range(box.count())] + ["new one"])
    assert box.currentText() == first
