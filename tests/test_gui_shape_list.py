"""The Shapes list as a rigger uses it (issue 18): select, rename in place (F2), duplicate (Ctrl+D), delete with
its correctives (Delete) and undo, move (Alt+Up/Down), sort, groups that fold, mute and solo buttons, slider
ranges and in-betweens -- with real mouse and key events, the posed surface checked after each."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

from model.correctives import Corrective, set_correctives
from model.pose import PoseEvaluator
from tests.gui_helpers import click_shape_name as _click_name, make_window


def _key(window, key, modifier=QtCore.Qt.NoModifier):
    target = QtWidgets.QApplication.focusWidget() or window.shapes_panel.scroll
    QTest.keyClick(target, key, modifier)
    QtWidgets.QApplication.processEvents()


def _surface(window):
    window.redraw_now()
    return window.document.evaluate_state(window.document.pose_state(), dtype=np.float64)


pytestmark = pytest.mark.gui


@pytest.fixture()
def window(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.activateWindow()     # as under a window manager: the keys go to the focused widget of the active window
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is w, timeout=5000)
    return w


def test_f2_renames_in_place_and_the_correctives_follow(qtbot, window):
    doc = window.document
    rig = doc.rig
    set_correctives(rig, [Corrective(drivers=["browInnerUp_L", "browInnerUp_R"], delta=rig.deltas[0] * 0.1)])
    doc.rig_edited()
    evaluator, evaluator64, reach = doc.evaluator, doc.evaluator64(), doc.shape_reach()
    _click_name(qtbot, window, "browInnerUp_L")
    assert window.shapes_panel.selected == ["browInnerUp_L"]
    _key(window, QtCore.Qt.Key_F2)
    editor = window.shapes_panel.row("browInnerUp_L").editor
    assert editor is not None and editor.hasFocus()
    editor.selectAll()
    QTest.keyClicks(editor, "browRaiser_L")
    QTest.keyClick(editor, QtCore.Qt.Key_Return)
    QtWidgets.QApplication.processEvents()
    assert "browRaiser_L" in doc.rig.shape_names and "browInnerUp_L" not in doc.rig.shape_names
    assert doc.rig.correctives[0].drivers == ["browRaiser_L", "browInnerUp_R"]
    assert doc.rig.correctives[0].name == "browRaiser_L+browInnerUp_R"
    assert window.shapes_panel.row("browRaiser_L").label.text() == "browRaiser_L"
    # a rename replaces no array: the evaluator's matrices and the shapes' reach are kept, not made again (1-2 s on
    # a studio rig), and the corrective still acts under its driver's new name
    assert doc.evaluator.shares_matrices(evaluator) and doc.shape_reach() is reach
    assert doc.evaluator64().shares_matrices(evaluator64)
    w = np.zeros(rig.n_shapes)
    w[[rig.shape_index("browRaiser_L"), rig.shape_index("browInnerUp_R")]] = 1.0
    window.set_pose(w, "pose")
    window.redraw_now()
    np.testing.assert_allclose(window.viewport.points(), PoseEvaluator(doc.rig).evaluate(w), atol=1e-5)
    window.undo_action.trigger()                       # the pose
    window.undo_action.trigger()                       # the rename
    assert doc.rig.shape_names[6] == "browInnerUp_L"
    assert doc.rig.correctives[0].name == "browInnerUp_L+browInnerUp_R"
    assert window.shapes_panel.rows[6].name == "browInnerUp_L"


def test_delete_key_removes_the_shape_and_its_corrective_and_undo_brings_all_back(qtbot, window):
    doc = window.document
    rig = doc.rig
    k = rig.shape_index("jawOpen")
    set_correctives(rig, [Corrective(drivers=["jawOpen", "mouthFunnel"], delta=np.roll(rig.deltas[k], 1, 1) * 0.2),
                          Corrective(drivers=["eyeBlink_L", "eyeBlink_R"], delta=rig.deltas[0] * 0.1)])
    doc.rig_edited()
    w = np.zeros(rig.n_shapes)
    w[[k, rig.shape_index("mouthFunnel"), 0]] = [0.8, 0.6, 0.3]
    window.set_pose(w, "pose")
    before_deltas, before_surface = doc.rig.deltas.copy(), _surface(window)
    before_corr = [(c.name, c.delta.copy()) for c in doc.rig.correctives]
    _click_name(qtbot, window, "jawOpen")
    _key(window, QtCore.Qt.Key_Delete)
    assert "jawOpen" not in doc.rig.shape_names and doc.rig.n_shapes == 33
    assert [c.name for c in doc.rig.correctives] == ["eyeBlink_L+eyeBlink_R"]
    assert len(window.shapes_panel.rows) == 33
    # the face lost the jaw and its fix, nothing else
    expected = PoseEvaluator(doc.rig, dtype=np.float64).evaluate(np.delete(w, k))
    assert np.array_equal(_surface(window), expected)
    np.testing.assert_allclose(window.viewport.points(), expected, atol=1e-4)   # the drawn one (rows copied)
    window.undo_action.trigger()
    assert np.array_equal(doc.rig.deltas, before_deltas)
    assert [(c.name) for c in doc.rig.correctives] == [n for n, _ in before_corr]
    assert all(np.array_equal(c.delta, d) for c, (_, d) in zip(doc.rig.correctives, before_corr))
    assert np.array_equal(doc.weights, w)
    assert np.array_equal(_surface(window), before_surface)
    assert window.shapes_panel.rows[k].name == "jawOpen"
    assert window.shapes_panel.rows[k].box.value() == pytest.approx(0.8)


def test_ctrl_d_duplicates_after_the_shape_and_alt_arrows_move_it(qtbot, window):
    doc = window.document
    _click_name(qtbot, window, "mouthSmile_L")
    k = doc.rig.shape_index("mouthSmile_L")
    _key(window, QtCore.Qt.Key_D, QtCore.Qt.ControlModifier)
    assert doc.rig.shape_names[k + 1] == "mouthSmile_L_copy"
    assert np.array_equal(doc.rig.deltas[k + 1], doc.rig.deltas[k])
    assert window.shapes_panel.selected == ["mouthSmile_L_copy"]
    _key(window, QtCore.Qt.Key_Up, QtCore.Qt.AltModifier)
    assert doc.rig.shape_names[k:k + 2] == ["mouthSmile_L_copy", "mouthSmile_L"]
    assert [r.name for r in window.shapes_panel.rows][k:k + 2] == ["mouthSmile_L_copy", "mouthSmile_L"]
    # the moved shape's slider poses the moved shape
    row = window.shapes_panel.row("mouthSmile_L")
    row.box.setValue(0.5)
    assert doc.weights[doc.rig.shape_index("mouthSmile_L")] == 0.5
    window.undo_action.trigger()   # the weight
    window.undo_action.trigger()   # the move
    assert doc.rig.shape_names[k:k + 2] == ["mouthSmile_L", "mouthSmile_L_copy"]
    window.undo_action.trigger()   # the duplicate
    assert "mouthSmile_L_copy" not in doc.rig.shape_names and len(window.shapes_panel.rows) == 34


def test_groups_fold_and_sort_by_name_reorders_the_rig(qtbot, window):
    panel = window.shapes_panel
    panel.grouping.setCurrentIndex(panel.grouping.findData("prefix"))
    QtWidgets.QApplication.processEvents()
    assert set(panel.headers) == {"eye", "brow", "cheek", "nose", "jaw", "mouth"}
    assert panel.headers["mouth"].text() == "mouth (15)"
    QTest.mouseClick(panel.headers["brow"], QtCore.Qt.LeftButton)
    QtWidgets.QApplication.processEvents()
    assert panel.row("browDown_L").isHidden() and not panel.row("eyeBlink_L").isHidden()
    QTest.mouseClick(panel.headers["brow"], QtCore.Qt.LeftButton)
    assert not panel.row("browDown_L").isHidden()
    names = list(window.document.rig.shape_names)
    panel.sort_actions["name"].trigger()
    assert window.document.rig.shape_names == sorted(names, key=str.lower)
    assert [r.name for r in panel.rows] == window.document.rig.shape_names
    window.undo_action.trigger()
    assert window.document.rig.shape_names == names


def test_mute_and_solo_buttons_change_the_face(qtbot, window):
    doc = window.document
    rig = doc.rig
    a, b = rig.shape_index("jawOpen"), rig.shape_index("mouthSmile_L")
    w = np.zeros(rig.n_shapes)
    w[[a, b]] = [0.7, 0.9]
    window.set_pose(w, "pose")
    only_b, only_a = w.copy(), w.copy()
    only_b[a] = 0
    only_a[b] = 0
    ev = PoseEvaluator(rig, dtype=np.float64)
    QTest.mouseClick(window.shapes_panel.row("jawOpen").mute, QtCore.Qt.LeftButton)
    assert doc.rig.muted == ["jawOpen"]
    assert np.array_equal(_surface(window), ev.evaluate(only_b))
    assert doc.weights[a] == 0.7          # the weight stays; only its contribution goes
    window.undo_action.trigger()
    assert doc.rig.muted == [] and not window.shapes_panel.row("jawOpen").mute.isChecked()
    QTest.mouseClick(window.shapes_panel.row("jawOpen").solo, QtCore.Qt.LeftButton)
    assert doc.rig.solo == ["jawOpen"]
    assert np.array_equal(_surface(window), ev.evaluate(only_a))


def test_a_range_lets_the_slider_overdrive(qtbot, window):
    doc = window.document
    window.shape_list.set_range("jawOpen", -0.5, 1.5)
    row = window.shapes_panel.row("jawOpen")
    assert (row.box.minimum(), row.box.maximum()) == (-0.5, 1.5)
    row.slider.setFocus()
    QTest.keyClick(row.slider, QtCore.Qt.Key_End)
    k = doc.rig.shape_index("jawOpen")
    assert doc.weights[k] == 1.5
    d = doc.rig.deltas[k]
    assert np.allclose(_surface(window), doc.rig.neutral + 1.5 * d, atol=1e-12)


def test_an_inbetween_from_the_current_pose_keeps_the_face_and_bends_the_curve(qtbot, window):
    doc = window.document
    rig = doc.rig
    k = rig.shape_index("jawOpen")
    d = rig.deltas[k].copy()
    w = np.zeros(rig.n_shapes)
    w[k] = 0.5
    window.set_pose(w, "half open")
    offset = np.zeros_like(rig.neutral)
    offset[d.any(axis=1)] = [0.0, 0.0, 0.3]      # a sculpt on the moving vertices, pending
    doc.set_edit_offset(offset)
    shown = doc.surface().astype(np.float64)
    window.shape_list.add_inbetween_from_pose("jawOpen", 0.5)
    assert doc.edit_offset is None
    assert "◆" in window.shapes_panel.row("jawOpen").label.text()
    np.testing.assert_allclose(doc.surface(), shown, atol=1e-5)   # the face does not jump
    D = 0.5 * d + offset
    for x in (0.25, 0.75):
        w[k] = x
        window.set_pose(w, "pose")
        expected = D * (x / 0.5) if x <= 0.5 else D + (x - 0.5) / 0.5 * (d - D)
        np.testing.assert_allclose(_surface(window), rig.neutral + expected, atol=1e-12)
    window.undo_action.trigger()   # the 0.75
    window.undo_action.trigger()   # the 0.25
    window.undo_action.trigger()   # the in-between: the sculpt is pending again
    assert doc.rig.inbetweens == {} and np.array_equal(doc.edit_offset, offset)


def test_the_context_menu_lists_the_shape_actions_and_the_shortcuts_are_in_help(qtbot, window):
    panel = window.shapes_panel
    menu = panel.shape_menu(panel.row("jawOpen"))
    texts = [a.text().split("\t")[0] for a in menu.actions() if a.text()]
    for t in ("Rename", "Duplicate", "Delete", "Move Up", "Move Down", "Set Range…",
              "Add In-between from Current Pose…", "Add In-between from OBJ…", "Mirror to the Other Side"):
        assert t in texts
    assert all(a.toolTip() for a in menu.actions() if a.text())
    rows = {(name, keys) for _where, name, keys in window.shortcut_rows()}
    for name, keys in (("Rename Shape", "F2"), ("Duplicate Shape", "Ctrl+D"), ("Move Shape Up", "Alt+Up")):
        assert (name, keys) in rows


def test_dragging_a_name_moves_the_shape_and_undo_puts_it_back(qtbot, window):
    from tests.gui_helpers import mouse
    doc, panel = window.document, window.shapes_panel
    names = list(doc.rig.shape_names)
    w = np.zeros(doc.rig.n_shapes)
    w[doc.rig.shape_index("jawOpen")] = 0.6
    window.set_pose(w, "pose")
    surface = _surface(window)
    src = panel.row("jawOpen")
    panel.scroll.ensureWidgetVisible(panel.rows[0])
    QtWidgets.QApplication.processEvents()
    target = panel.row("eyeWide_L")                   # third in the list
    start = src.label.rect().center()

    def at_target(dy):
        return src.label.mapFromGlobal(target.mapToGlobal(QtCore.QPoint(target.width() // 2, dy)))
    mouse(src.label, "press", start)
    mouse(src.label, "move", start + QtCore.QPoint(0, -30))
    mouse(src.label, "move", at_target(2))            # the upper half of eyeWide_L: before it
    assert panel.dragging
    mouse(src.label, "release", at_target(2))
    assert not panel.dragging
    assert doc.rig.shape_names[:4] == ["eyeBlink_L", "eyeBlink_R", "jawOpen", "eyeWide_L"]
    assert [r.name for r in panel.rows[:4]] == doc.rig.shape_names[:4]
    assert panel.rows[2].box.value() == pytest.approx(0.6)          # its weight went with it
    assert np.array_equal(_surface(window), surface)                # the face did not change
    window.undo_action.trigger()
    assert doc.rig.shape_names == names


def _menu_action(window, name, text):
    menu = window.shapes_panel.shape_menu(window.shapes_panel.row(name))
    act = next(a for a in menu.actions() if a.text().split("\t")[0] == text)
    act.trigger()
    QtWidgets.QApplication.processEvents()


def test_set_range_from_the_menu_asks_and_applies(qtbot, window):
    _menu_action(window, "jawOpen", "Set Range…")
    dialog = window.shape_list.dialog
    assert dialog.isVisible()
    dialog.lo.setValue(-0.5)
    dialog.hi.setValue(2.0)
    QTest.mouseClick(dialog.findChild(QtWidgets.QDialogButtonBox).button(QtWidgets.QDialogButtonBox.Ok),
                     QtCore.Qt.LeftButton)
    assert window.document.rig.ranges == {"jawOpen": (-0.5, 2.0)}
    row = window.shapes_panel.row("jawOpen")
    assert (row.box.minimum(), row.box.maximum()) == (-0.5, 2.0)
    window.undo_action.trigger()
    assert window.document.rig.ranges == {} and row.box.maximum() == 1.0


def test_inbetween_from_the_menu_asks_for_the_weight(qtbot, window, tmp_path):
    from model.obj_io import write_obj
    doc = window.document
    rig = doc.rig
    k = rig.shape_index("mouthFunnel")
    w = np.zeros(rig.n_shapes)
    w[k] = 0.4
    window.set_pose(w, "pose")
    _menu_action(window, "mouthFunnel", "Add In-between from Current Pose…")
    dialog = window.shape_list.dialog
    assert dialog.doubleValue() == pytest.approx(0.4)     # the shape's weight now, suggested
    dialog.setDoubleValue(0.5)
    dialog.accept()
    QtWidgets.QApplication.processEvents()
    ib = rig.inbetweens["mouthFunnel"]
    assert [i.weight for i in ib] == [0.5]
    np.testing.assert_allclose(ib[0].delta, 0.4 * rig.deltas[k], atol=1e-12)
    # from an OBJ in the neutral's vertex order: a second in-between at 0.25
    target = rig.neutral + 0.1 * rig.deltas[k]
    write_obj(tmp_path / "quarter.obj", target, rig.face_counts, rig.face_indices)
    window.shape_list.add_inbetween_from_obj("mouthFunnel", 0.25, tmp_path / "quarter.obj")
    assert [i.weight for i in rig.inbetweens["mouthFunnel"]] == [0.25, 0.5]
    w[k] = 0.25
    window.set_pose(w, "quarter")
    np.testing.assert_allclose(_surface(window), target, atol=1e-5)     # the OBJ's six decimals
    # one with the wrong vertex count is refused in one sentence naming the file; nothing changes
    write_obj(tmp_path / "few.obj", rig.neutral[:100], np.array([3]), np.array([0, 1, 2]))
    window.shape_list._guarded(window.shape_list.add_inbetween_from_obj, "mouthFunnel", 0.75, tmp_path / "few.obj")
    assert "few.obj" in window.last_error and "vertices" in window.last_error
    assert [i.weight for i in rig.inbetweens["mouthFunnel"]] == [0.25, 0.5]


def test_a_live_link_take_keeps_posing_the_right_shapes_after_a_move(qtbot, window, llf_csv):
    """A weight take lines up with the shape list: moving or renaming shapes re-maps it by name."""
    doc, mc = window.document, window.mocap
    assert mc.load_take(llf_csv)
    mc.set_frame(40)
    QtWidgets.QApplication.processEvents()
    before = dict(zip(doc.rig.shape_names, doc.weights))
    assert before["jawOpen"] > 0.01 and before["eyeBlink_L"] != before["jawOpen"]
    window.shape_list.move_to(["jawOpen"], 0)
    window.shape_list.rename("eyeBlink_L", "blinkLeft")
    mc.set_frame(40)
    QtWidgets.QApplication.processEvents()
    after = dict(zip(doc.rig.shape_names, doc.weights))
    assert doc.rig.shape_names[0] == "jawOpen" and after["jawOpen"] == before["jawOpen"]
    assert after["eyeWide_L"] == before["eyeWide_L"]
    assert after["blinkLeft"] == 0.0    # the take names eyeBlink_L, which the rig no longer has


def test_a_muted_shape_does_not_follow_a_marker_drag(qtbot, window):
    from resources.sample_rig import sample_geometry
    geometry = sample_geometry()
    qtbot.waitUntil(lambda: window.segmentation.segmentation is not None, timeout=30000)
    c, doc = window.markers, window.document
    corner = int(geometry.mouth.upper[0])
    assert c.add_marker_at(corner), c.last_message

    def drag():
        c.begin_drag(0)
        c.drag_by(np.array([0.0, 0.6, 0.0]))
        c.end_drag()
        s = doc.pose_state()
        return s.region_weights if s.is_regional else s.weights[None]
    W = drag()
    top = int(np.argmax(np.abs(W).max(axis=0)))
    name = doc.rig.shape_names[top]
    assert np.abs(W[:, top]).max() > 0.05
    doc.undo_stack.undo()
    window.shape_list.set_mute(name, True)
    W = drag()
    assert np.abs(W[:, top]).max() == 0.0, name
    assert np.abs(W).max() > 0.05          # other shapes follow the marker instead
    # a regional pose keeps its regions through a delete and its undo, bit for bit
    state = doc.pose_state()
    assert state.is_regional
    window.shape_list.delete(["mouthSmile_R"])
    k = state.weights.size
    assert doc.pose_state().is_regional and doc.pose_state().region_weights.shape == (state.region_weights.shape[0], k - 1)
    window.undo_action.trigger()
    after = doc.pose_state()
    assert after.is_regional and np.array_equal(after.region_weights, state.region_weights)
    assert after.blend is state.blend and np.array_equal(after.weights, state.weights)


def test_a_rename_keeps_the_segmentation_and_remove_inbetweens_undoes(qtbot, window):
    qtbot.waitUntil(lambda: window.segmentation.segmentation is not None, timeout=30000)
    seg = window.segmentation.segmentation
    window.shape_list.rename("jawOpen", "jawDrop")
    QtWidgets.QApplication.processEvents()
    assert window.segmentation.segmentation is seg          # not re-segmented: the same shapes, renamed
    panel_names = [window.segmentation_panel.shape.itemText(i) for i in range(window.segmentation_panel.shape.count())]
    assert "jawDrop" in panel_names and "jawOpen" not in panel_names
    doc = window.document
    d = doc.rig.deltas[doc.rig.shape_index("jawDrop")]
    from model import shape_edits as se
    from app.commands import SetShapeSettingsCommand
    doc.undo_stack.push(SetShapeSettingsCommand(doc, se.ShapeSettings.of(doc.rig),
                                                se.with_inbetween(doc.rig, "jawDrop", 0.5, 0.7 * d), "ib"))
    _menu_action(window, "jawDrop", "Remove In-betweens")
    assert doc.rig.inbetweens == {} and "◆" not in window.shapes_panel.row("jawDrop").label.text()
    window.undo_action.trigger()
    assert [i.weight for i in doc.rig.inbetweens["jawDrop"]] == [0.5]
    # Ctrl+click on S solos only that shape
    QTest.mouseClick(window.shapes_panel.row("mouthClose").solo, QtCore.Qt.LeftButton)
    QTest.mouseClick(window.shapes_panel.row("mouthFunnel").solo, QtCore.Qt.LeftButton)
    assert sorted(doc.rig.solo) == ["mouthClose", "mouthFunnel"]
    QTest.mouseClick(window.shapes_panel.row("jawDrop").solo, QtCore.Qt.LeftButton, QtCore.Qt.ControlModifier)
    assert doc.rig.solo == ["jawDrop"]
    assert [r.name for r in window.shapes_panel.rows if r.solo.isChecked()] == ["jawDrop"]


def test_a_move_copies_the_shapes_off_the_gui_thread_while_the_window_goes_on(qtbot, window, monkeypatch):
    """Alt+Down on a shape: the reorder and its copies (``Document.edit_rig``) run on a worker thread while the
    GUI thread goes on: a timer on it fires while the edit waits for it (on the GUI thread the edit would wait in
    vain and fail). The moved rig, the drawn face and Ctrl+Z (off the GUI thread too) are what an edit in place
    makes, bit for bit, on the same Rig object."""
    import threading

    import model.shape_edits as se
    doc = window.document
    real, on_gui_thread = se.reorder_shapes, []
    ticked = threading.Event()

    def reorder_waiting_for_the_gui_thread(project, order):
        on_gui_thread.append(threading.current_thread() is threading.main_thread())
        assert ticked.wait(10), "the GUI thread's timer did not fire while the edit ran"
        ticked.clear()
        return real(project, order)

    monkeypatch.setattr(se, "reorder_shapes", reorder_waiting_for_the_gui_thread)
    rig, names, deltas = doc.rig, list(doc.rig.shape_names), doc.rig.deltas.copy()
    _click_name(qtbot, window, "jawOpen")
    k = names.index("jawOpen")
    row = window.shapes_panel.row("jawOpen")
    row.box.setValue(0.8)                           # the face opens its jaw: the move must keep drawing it
    drawn = _surface(window)
    QtCore.QTimer.singleShot(50, ticked.set)
    _key(window, QtCore.Qt.Key_Down, QtCore.Qt.AltModifier)
    assert on_gui_thread == [False]
    order = list(range(len(names)))
    order[k], order[k + 1] = order[k + 1], order[k]
    assert doc.rig is rig and rig.shape_names == [names[i] for i in order]
    assert np.array_equal(rig.deltas, deltas[order]) and doc.weights[k + 1] == 0.8
    assert [r.name for r in window.shapes_panel.rows][k:k + 2] == [names[k + 1], "jawOpen"]
    np.testing.assert_allclose(_surface(window), drawn, rtol=0, atol=1e-6)   # float32 display rows, moved
    np.testing.assert_allclose(window.viewport.points(), PoseEvaluator(rig).evaluate(doc.weights), rtol=0, atol=1e-5)
    QtCore.QTimer.singleShot(50, ticked.set)
    window.undo_action.trigger()                    # the move back
    assert on_gui_thread == [False, False]
    assert rig.shape_names == names and np.array_equal(rig.deltas, deltas) and doc.weights[k] == 0.8


def test_new_deltas_for_a_shape_are_made_off_the_gui_thread_with_the_shapes_reach(qtbot, window, monkeypatch):
    """One shape's new deltas (as Mirror Shape pushes them): the copy of the deltas, the evaluator's rows and the
    shapes' reach (where the camera frames, how a marker drag is damped) are made on the worker thread, and the
    reach the views then use is that of the edited rig; undo puts the deltas and the reach back."""
    import threading

    from app.commands import SetShapeDeltaCommand
    from model import rig_prep
    doc = window.document
    real, threads = rig_prep.shape_reach, []

    def recorded(rig):
        threads.append(threading.current_thread() is threading.main_thread())
        return real(rig)

    monkeypatch.setattr(rig_prep, "shape_reach", recorded)
    k = doc.rig.shape_index("jawOpen")
    before, reach_before = doc.rig.deltas.copy(), doc.shape_reach().copy()
    doc.undo_stack.push(SetShapeDeltaCommand(doc, "jawOpen", 3.0 * before[k], "Triple the jaw"))
    reach = doc.shape_reach()
    assert threads == [False] and reach.max() > reach_before.max()
    assert np.array_equal(reach, real(doc.rig)) and np.array_equal(doc.rig.deltas[k], 3.0 * before[k])
    window.undo_action.trigger()
    assert threads == [False, False] and np.array_equal(doc.rig.deltas, before)
    assert np.array_equal(doc.shape_reach(), reach_before)


def test_an_inbetween_copies_the_evaluators_rows_off_the_gui_thread_and_poses_as_a_fresh_evaluator(qtbot, window,
                                                                                                   monkeypatch):
    """An in-between (as Add In-between pushes it): the display evaluator's new rows are copied on the worker
    thread (``PoseEvaluator._rows_for``), and the face then poses through the in-between as an evaluator made
    from scratch does; undo takes it out."""
    import threading

    import model.shape_edits as se
    from app.commands import SetShapeSettingsCommand
    doc = window.document
    real, threads = PoseEvaluator._rows_for, []

    def recorded(self, *args):
        threads.append(threading.current_thread() is threading.main_thread())
        return real(self, *args)

    monkeypatch.setattr(PoseEvaluator, "_rows_for", recorded)
    k = doc.rig.shape_index("jawOpen")
    bent = 0.5 * doc.rig.deltas[k] + 0.3 * np.roll(doc.rig.deltas[k], 1, axis=1)
    old = se.ShapeSettings.of(doc.rig)
    doc.undo_stack.push(SetShapeSettingsCommand(doc, old, se.with_inbetween(doc.rig, "jawOpen", 0.5, bent), "In-between"))
    assert threads == [False] and list(doc.rig.inbetweens) == ["jawOpen"]
    w = np.zeros(doc.rig.n_shapes)
    w[k] = 0.5
    doc.set_weights(w)
    fresh = PoseEvaluator(doc.rig)
    np.testing.assert_allclose(_surface(window), fresh.evaluate(w), rtol=0, atol=1e-5)
    np.testing.assert_allclose(_surface(window), doc.rig.neutral + bent, rtol=0, atol=1e-5)   # on the in-between
    assert doc.undo_stack.count() == 1
    doc.undo_stack.undo()
    assert doc.rig.inbetweens == {} and threads == [False, False]
    np.testing.assert_allclose(_surface(window), doc.rig.neutral + 0.5 * doc.rig.deltas[k], rtol=0, atol=1e-5)


def test_after_a_slow_edit_shows_its_busy_dialog_the_next_key_goes_to_the_shapes_list(qtbot, window, monkeypatch):
    """On a studio rig Ctrl+D runs long enough for its busy dialog to show; the dialog takes the keyboard. When it
    closes, the window is active again with the focus where it was, so Alt+Up then moves the copy as on a small rig
    (without a window manager, closing the dialog had left no window active: the key went nowhere)."""
    import time

    import model.shape_edits as se
    doc = window.document
    real = se.duplicate_shape

    def slow_duplicate(*args, **kwargs):            # as long as a studio rig's copies take: the dialog shows
        time.sleep(0.5)
        return real(*args, **kwargs)

    monkeypatch.setattr(se, "duplicate_shape", slow_duplicate)
    _click_name(qtbot, window, "mouthSmile_L")
    k = doc.rig.shape_index("mouthSmile_L")
    focus = QtWidgets.QApplication.focusWidget()
    assert focus is not None and window.shapes_panel.isAncestorOf(focus)
    shown = []
    QtCore.QTimer.singleShot(350, lambda: shown.extend(w for w in QtWidgets.QApplication.topLevelWidgets()
                                                       if isinstance(w, QtWidgets.QProgressDialog) and w.isVisible()))
    QTest.keyClick(focus, QtCore.Qt.Key_D, QtCore.Qt.ControlModifier)
    QtWidgets.QApplication.processEvents()
    assert shown, "the busy dialog did not show"
    assert doc.rig.shape_names[k + 1] == "mouthSmile_L_copy"
    assert QtWidgets.QApplication.activeWindow() is window
    assert QtWidgets.QApplication.focusWidget() is focus
    QTest.keyClick(QtWidgets.QApplication.focusWidget(), QtCore.Qt.Key_Up, QtCore.Qt.AltModifier)
    QtWidgets.QApplication.processEvents()
    assert doc.rig.shape_names[k:k + 2] == ["mouthSmile_L_copy", "mouthSmile_L"]


def test_the_grouping_chosen_comes_back_in_the_next_session(qtbot, window, tmp_path):
    """The Shapes list's grouping (By face part, By side) is a way of working, like the brush or the finder's
    measure: it came back as No groups in every new window."""
    panel = window.shapes_panel
    panel.grouping.setCurrentIndex(panel.grouping.findData("side"))
    QtWidgets.QApplication.processEvents()
    assert panel.headers and not next(iter(panel.headers.values())).isHidden()
    window.close()
    w2 = make_window(qtbot, tmp_path)
    panel2 = w2.shapes_panel
    assert panel2.grouping.currentData() == "side"
    assert set(panel2.headers) == set(panel.headers) and all(not h.isHidden() for h in panel2.headers.values())
