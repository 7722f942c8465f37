"""Actors who are not the rig, in the window (issue 15), with real input events: File ▸ Personalize to Actor… writes
and opens the actor's project and shows each shape's change as a heat map; Edit ▸ Antagonist Pairs… edits the
pairs the solves keep apart (undoable, saved); "Use This Frame as Neutral" on the take; the marker map shown on the
rig, a map point dragged to correct it."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

from model.obj_io import write_obj
from model.project import Project, load_project, save_project
from tests.gui_helpers import make_window, mouse, open_and_wait


def _click(widget, pos=None, button=QtCore.Qt.LeftButton):
    QTest.mouseClick(widget, button, QtCore.Qt.NoModifier, pos if pos is not None else widget.rect().center())
    QtWidgets.QApplication.processEvents()


def _click_item(tree: QtWidgets.QTreeWidget, item, modifier=QtCore.Qt.NoModifier):
    rect = tree.visualItemRect(item)
    QTest.mouseClick(tree.viewport(), QtCore.Qt.LeftButton, modifier, rect.center())
    QtWidgets.QApplication.processEvents()


def _type(widget, text: str):
    widget.setFocus()
    QTest.keyClick(widget, QtCore.Qt.Key_A, QtCore.Qt.ControlModifier)
    QTest.keyClicks(widget, text)
    QtWidgets.QApplication.processEvents()


def _key(qtbot, widget, key, modifiers=QtCore.Qt.NoModifier):
    """A key pressed in ``widget``'s window with it active (as under a window manager) and the focus in it."""
    window = widget.window()
    window.activateWindow()
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is window, timeout=5000)
    target = QtWidgets.QApplication.focusWidget() or widget
    QTest.keyClick(target, key, modifiers)
    QtWidgets.QApplication.processEvents()


def _undo(qtbot, widget):
    _key(qtbot, widget, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)


def _redo(qtbot, widget):
    _key(qtbot, widget, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)


def _close_error_box(message: str):
    """The error box says ``message``; close it as the user would (its OK button)."""
    box = next(b for b in QtWidgets.QApplication.topLevelWidgets()
               if isinstance(b, QtWidgets.QMessageBox) and b.isVisible())
    assert box.text() == message
    _click(box.button(QtWidgets.QMessageBox.Ok))
    assert not any(isinstance(b, QtWidgets.QMessageBox) and b.isVisible()
                   for b in QtWidgets.QApplication.topLevelWidgets())


# --- antagonist pairs -------------------------------------------------------------------------------
def test_antagonist_pairs_are_edited_undone_saved_and_used_by_the_drag(qtbot, tmp_path):
    from model.antagonists import pair_indices, rig_antagonists
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    found = rig_antagonists(rig)
    assert ("mouthLeft", "mouthRight") in found
    ctl = w.actor.antagonists
    dlg = ctl.show_dialog()
    qtbot.waitExposed(dlg)
    assert dlg.pairs() == found and not dlg.reset_button.isEnabled()
    # remove mouthLeft/mouthRight: select its row with the mouse, click Remove Selected
    row = next(dlg.table.topLevelItem(i) for i in range(dlg.table.topLevelItemCount())
               if dlg.table.topLevelItem(i).text(0) == "mouthLeft" and dlg.table.topLevelItem(i).text(1) == "mouthRight")
    _click_item(dlg.table, row)
    assert dlg.remove_button.isEnabled()
    _click(dlg.remove_button)
    assert ("mouthLeft", "mouthRight") not in dlg.pairs() and len(dlg.pairs()) == len(found) - 1
    assert w.document.project.antagonists == [p for p in found if p != ("mouthLeft", "mouthRight")]
    assert w.document.undo_stack.undoText() == "Remove antagonist pair mouthLeft+mouthRight"
    # add jawOpen against mouthClose, typed into the two boxes
    _type(dlg.first.lineEdit(), "jawOpen")
    _type(dlg.second.lineEdit(), "mouthClose")
    _click(dlg.add_button)
    assert dlg.pairs()[-1] == ("jawOpen", "mouthClose") and dlg.table.topLevelItem(len(found) - 1).text(2) == "added"
    assert dlg.reset_button.isEnabled()
    # the drag solve keeps the project's pairs apart, not the rig's
    drag_pairs = set(w.markers._antagonists(rig))
    ij = pair_indices(rig, [("jawOpen", "mouthClose")])[0]
    assert ij in drag_pairs and pair_indices(rig, [("mouthLeft", "mouthRight")])[0] not in drag_pairs
    # undo the add (Ctrl+Z), redo it (Ctrl+Shift+Z)
    _undo(qtbot, dlg)
    assert ("jawOpen", "mouthClose") not in dlg.pairs() and ij not in set(w.markers._antagonists(rig))
    _redo(qtbot, dlg)
    assert dlg.pairs()[-1] == ("jawOpen", "mouthClose")
    # a shape the rig does not have is refused with one sentence, nothing changes
    before = list(w.document.project.antagonists)
    _type(dlg.second.lineEdit(), "noSuchShape")
    _click(dlg.add_button)
    assert "noSuchShape" in w.last_error and w.document.project.antagonists == before
    _close_error_box(w.last_error)
    # saved in the project and read back
    path = tmp_path / "pairs.bsproj"
    assert w.save_to(path)
    assert load_project(path).antagonists == before
    w.open_path(path)
    qtbot.waitUntil(lambda: not w.is_loading, timeout=60000)
    assert w.document.project.antagonists == before
    # back to the rig's own pairs, one undo step
    dlg = ctl.show_dialog()
    _click(dlg.reset_button)
    assert w.document.project.antagonists is None and dlg.pairs() == found
    _undo(qtbot, dlg)
    assert w.document.project.antagonists == before


# --- personalisation and the heat map ---------------------------------------------------------------
def _actor_scans(rig, folder, n=3, seed=0):
    """An actor 6 % larger than the rig, its neutral and n pose scans (OBJ, the rig's topology)."""
    rng = np.random.default_rng(seed)
    folder.mkdir()
    neutral = rig.neutral * 1.06
    write_obj(folder / "neutral.obj", neutral, rig.face_counts, rig.face_indices)
    poses = folder / "poses"
    poses.mkdir()
    for i in range(n):
        w = np.zeros(rig.n_shapes)
        w[rng.choice(rig.n_shapes, 4, replace=False)] = rng.uniform(0.4, 1.0, 4)
        write_obj(poses / f"pose_{i}.obj", neutral + np.einsum("k,kvc->vc", w, rig.deltas * 1.1),
                  rig.face_counts, rig.face_indices)
    return folder / "neutral.obj", poses


def test_personalize_in_the_window_writes_and_opens_the_actor_and_shows_the_change(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    template = tmp_path / "face.bsproj"
    assert w.save_to(template)
    original = template.read_bytes()
    rig = w.document.rig.copy()
    neutral, poses = _actor_scans(rig, tmp_path / "actor")
    _key(qtbot, w, QtCore.Qt.Key_P, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    dlg = w.actor.dialog
    assert dlg is not None and dlg.output_edit.text() == str(tmp_path / "face_actor.bsproj")
    _type(dlg.neutral_edit, str(neutral))
    dlg.add_scans([str(poses)])          # what Add Folder… adds (a native file dialog cannot be driven)
    with qtbot.waitSignal(w.actor.personalized, timeout=180000):
        _click(dlg.ok_button)
        assert w.actor.busy                    # control came back at once: the work is in the background
        assert w.actor.progress is not None and w.actor.progress.isVisible()
        assert w.actor.job.running             # in its own process (started off the GUI thread); Cancel stops it
    out = tmp_path / "face_actor.bsproj"
    qtbot.waitUntil(lambda: w.document.path == out and not w.is_loading, timeout=60000)
    qtbot.waitUntil(lambda: w.actor.heat_action.isChecked(), timeout=5000)
    assert template.read_bytes() == original                      # the template's file is untouched
    actor = w.document.rig
    assert actor.shape_names == rig.shape_names and actor.presets == rig.presets
    assert np.allclose(actor.neutral, rig.neutral * 1.06, atol=1e-4)
    # the heat map shows the most changed shape, in mm, personalised minus template
    panel = w.actor.panel
    top = panel.table.topLevelItem(0).text(0)
    assert w.actor.heat_shape == top
    k = rig.shape_index(top)
    expected = np.linalg.norm(actor.deltas[k] - rig.deltas[k], axis=1) * 10.0     # cm -> mm
    cmap = w.viewport.colormap
    assert cmap is not None and "mm" in cmap.title and top in cmap.title
    assert np.allclose(cmap.scalars, expected, atol=1e-3 * max(expected.max(), 1e-6))
    assert cmap.clim[1] == pytest.approx(expected.max(), rel=1e-3)
    # another shape picked in the Actor Change panel
    other = panel.table.topLevelItem(3)
    _click_item(panel.table, other)
    k = rig.shape_index(other.text(0))
    assert w.actor.heat_shape == other.text(0)
    assert np.allclose(w.viewport.colormap.scalars, np.linalg.norm(actor.deltas[k] - rig.deltas[k], axis=1) * 10,
                       atol=1e-3)
    # it follows the Shapes panel: a click on jawOpen's slider
    slider = w.shapes_panel.row("jawOpen").slider
    w.shapes_dock.raise_()
    w.shapes_panel.scroll.ensureWidgetVisible(slider)
    QtWidgets.QApplication.processEvents()
    _click(slider)
    assert w.actor.heat_shape == "jawOpen" and "jawOpen" in w.viewport.colormap.title
    # picking a view in the Segmentation panel turns it off
    w.segmentation_panel.set_view("deformation")
    assert not w.actor.heat_action.isChecked()
    # undo has nothing to lose: the template is still there to open
    assert load_project(template).rig.shape_names == rig.shape_names


def test_cancel_stops_the_personalisation_and_writes_nothing(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    neutral, poses = _actor_scans(rig, tmp_path / "actor", n=6)
    out = tmp_path / "never.bsproj"
    assert w.actor.personalize({"neutral_scan": str(neutral), "scans": [str(poses)], "output": str(out)})
    dlg, job = w.actor.progress, w.actor.job
    qtbot.waitExposed(dlg)
    cancel = next(b for b in dlg.findChildren(QtWidgets.QPushButton) if b.text() == "Cancel")
    with qtbot.waitSignal(w.actor.cancelled, timeout=30000):
        _click(cancel)
    assert not job.process.is_alive() and not w.actor.busy and w.actor.action.isEnabled()
    assert not out.exists() and not list(tmp_path.glob("never*"))
    assert w.document.rig is rig
    # and it can start again
    assert w.actor.personalize({"neutral_scan": str(neutral), "scans": [], "output": str(out)})
    with qtbot.waitSignal(w.actor.personalized, timeout=180000):
        pass
    assert out.exists()


def test_personalize_refuses_bad_scans_with_one_sentence_and_keeps_the_rig(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    before = rig.neutral.copy()
    bad = tmp_path / "nan.obj"
    pts = rig.neutral.copy()
    pts[5] = np.nan
    write_obj(bad, pts, rig.face_counts, rig.face_indices)
    other = tmp_path / "other.obj"
    write_obj(other, rig.neutral[:100], np.array([3]), np.array([0, 1, 2]))
    for scan, words in ((bad, ("NaN",)), (other, ("100 vertices", f"{rig.n_vertices}"))):
        with qtbot.waitSignal(w.actor.failed, timeout=60000) as sig:
            assert w.actor.personalize({"neutral_scan": str(scan), "scans": [], "output": str(tmp_path / "o.bsproj")})
        message = sig.args[0]
        assert str(scan) in message and "\n" not in message and all(x in message for x in words), message
        assert w.last_error == message
        _close_error_box(message)
        assert w.document.rig is rig and np.array_equal(rig.neutral, before)
        assert not (tmp_path / "o.bsproj").exists()
    # no measurement at all: refused before any work
    assert not w.actor.personalize({"neutral_scan": None, "scans": [], "output": str(tmp_path / "o.bsproj")})
    assert "neutral scan, pose scans or a marker take" in w.last_error


def test_personalize_refuses_an_output_it_would_lose_before_any_work(qtbot, tmp_path, monkeypatch):
    """The actor's project may not go over a file the window has open: only the open project itself was guarded, so
    after File ▸ Save As the project the rig was opened from (the rig's file, which every export refuses) was written
    over; nor where it cannot be written (a folder of that name, a read-only folder), which the job found out only
    after the whole solve. Each is one sentence in a dialog before any work, nothing starts, every file as it was."""
    w = make_window(qtbot, tmp_path)
    first = tmp_path / "first.bsproj"
    save_project(Project(rig=w.document.rig.copy()), first)
    open_and_wait(qtbot, w, first)
    w.document.save(tmp_path / "second.bsproj")          # Save As: the rig still comes from first.bsproj
    rig = w.document.rig
    scan = tmp_path / "scan.obj"
    write_obj(scan, rig.neutral, rig.face_counts, rig.face_indices)
    (tmp_path / "folder.bsproj").mkdir()
    (tmp_path / "ro").mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if os.path.abspath(p) == str(tmp_path / "ro") and
                        mode & os.W_OK else real_access(p, mode, **kw))   # as root, a folder's mode stops no write
    before = {p: p.read_bytes() for p in tmp_path.glob("*.bsproj") if p.is_file()}
    for out, sentence in (
            (first, f"{first}: is the rig itself, which the window has open; write the actor's project to another "
                    "file."),
            (tmp_path / "folder.bsproj", f"{tmp_path / 'folder.bsproj'}: is a folder, not a file."),
            (tmp_path / "ro" / "actor", f"{tmp_path / 'ro' / 'actor.bsproj'}: cannot be written: {tmp_path / 'ro'} "
                                        "is a folder you may not write in; nothing was written.")):
        assert not w.actor.personalize({"neutral_scan": str(scan), "scans": [], "output": str(out)})
        assert w.last_error == sentence and not w.actor.busy and w.actor.job is None
        _close_error_box(sentence)
    assert {p: p.read_bytes() for p in tmp_path.glob("*.bsproj") if p.is_file()} == before
    assert not any((tmp_path / "ro").iterdir())


# --- the heat map's picture ---------------------------------------------------------------------------
# the nearest wrong pictures: another shape's change, a shape that did not change (a pale face), no heat map
HEAT_UNLIKE = {"window_heat_map_smile": ["window_heat_map_jaw", "window_heat_map_unchanged", "window_viewport_neutral"],
               "window_heat_map_jaw": ["window_heat_map_smile", "window_heat_map_unchanged", "window_viewport_neutral"],
               "window_heat_map_unchanged": ["window_heat_map_smile", "window_viewport_neutral"]}


def _heat_map_shot(qtbot, tmp_path, shape):
    """The sample face personalised to a made-up actor whose mouthSmile_L is 40 % stronger and whose jawOpen is
    30 % weaker (a known change, independent of the solver), the heat map of ``shape`` (None: off) in the window."""
    from model.actor_project import record_change
    w = make_window(qtbot, tmp_path, size=(1000, 700))
    template = w.document.rig.copy()
    actor = template.copy()
    actor.deltas = actor.deltas.copy()
    actor.deltas[actor.shape_index("mouthSmile_L")] *= 1.4
    actor.deltas[actor.shape_index("jawOpen")] *= 0.7
    sections, arrays = {}, {}
    record_change(sections, arrays, template, actor, {"neutral": "scan"}, "sample")
    path = tmp_path / "actor.bsproj"
    save_project(Project(rig=actor, sections=sections, arrays=arrays), path)
    open_and_wait(qtbot, w, path)
    if shape is not None:
        w.actor.show_shape(shape)
    else:
        w.actor.heat_action.setChecked(False)
    w.redraw_now()
    img = w.viewport.picture((640, 480))
    return w, img


@pytest.mark.parametrize("shape, name", [("mouthSmile_L", "window_heat_map_smile"), ("jawOpen", "window_heat_map_jaw"),
                                         ("mouthSmile_R", "window_heat_map_unchanged")])
def test_heat_map_matches_its_reference(qtbot, tmp_path, shape, name):
    from tests.image_compare import assert_matches_reference
    w, img = _heat_map_shot(qtbot, tmp_path, shape)
    bar = w.viewport.plotter.scalar_bars
    assert any("change (mm)" in title and shape in title for title in bar.keys()), list(bar.keys())
    assert_matches_reference(img, name, tolerance=0.03, unlike=HEAT_UNLIKE[name])


@pytest.mark.parametrize("shape, name", [("jawOpen", "window_heat_map_smile"), (None, "window_heat_map_smile"),
                                         ("mouthSmile_L", "window_heat_map_jaw"), ("mouthSmile_R", "window_heat_map_smile")])
def test_a_wrong_heat_map_fails_the_comparison(qtbot, tmp_path, shape, name):
    """Another shape's change, a shape that did not change, or no heat map at all is not the smile's heat map."""
    from tests.image_compare import assert_wrong_picture_fails
    _, img = _heat_map_shot(qtbot, tmp_path, shape)
    assert_wrong_picture_fails(img, name, tolerance=0.03, unlike=HEAT_UNLIKE[name])


# --- the take: its neutral frame and its marker map on the rig ------------------------------------------
def _context_menu(widget):
    """A right-click's context menu event on ``widget`` (what the platform sends on a right-button press; QTest's
    synthetic presses do not produce one under Xvfb)."""
    from PySide6 import QtGui
    pos = widget.rect().center()
    ev = QtGui.QContextMenuEvent(QtGui.QContextMenuEvent.Mouse, pos, widget.mapToGlobal(pos))
    QtWidgets.QApplication.sendEvent(widget, ev)
    QtWidgets.QApplication.processEvents()


def _menu_click(menu: QtWidgets.QMenu, text_start: str):
    act = next(a for a in menu.actions() if a.text().startswith(text_start))
    QTest.mouseClick(menu, QtCore.Qt.LeftButton, QtCore.Qt.NoModifier, menu.actionGeometry(act).center())
    QtWidgets.QApplication.processEvents()


def _use_frame_as_neutral(qtbot, mc, frame: int) -> None:
    """The Mocap panel's slider at ``frame``, then right-click it ▸ Use This Frame as Neutral."""
    mc.dock.raise_()
    mc.panel.slider.setValue(frame)
    QtWidgets.QApplication.processEvents()
    _context_menu(mc.panel.slider)
    qtbot.waitUntil(lambda: getattr(mc.panel, "last_menu", None) is not None and mc.panel.last_menu.isVisible())
    _menu_click(mc.panel.last_menu, "Use This Frame as Neutral")


def test_use_this_frame_as_neutral_and_drag_a_map_point(qtbot, tmp_path, ict_dir, take_dir):
    import json
    w = make_window(qtbot, tmp_path, size=(1400, 1000))
    open_and_wait(qtbot, w, ict_dir)
    mc, rig = w.mocap, w.document.rig
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=180000):
        _click(mc.panel.solve_button)
    assert mc.workspace.report()["neutral_frames"] == [0, 29]
    # right-click the take's slider at frame 120: Use This Frame as Neutral
    _use_frame_as_neutral(qtbot, mc, 120)
    assert mc.panel.settings()["neutral_frames"] == "120:120"
    assert w.document.undo_stack.undoText() == "Use frame 120 as neutral"
    _undo(qtbot, w)
    assert mc.panel.settings()["neutral_frames"] is None
    _redo(qtbot, w)
    assert mc.panel.settings()["neutral_frames"] == "120:120"
    # the solve uses it, and its report and the panel say so
    with qtbot.waitSignal(mc.solved, timeout=180000):
        _click(mc.panel.solve_button)
    report = mc.workspace.report()
    assert report["neutral_frames"] == [120, 120] and report["neutral_frames_how"] == "as chosen"
    assert "neutral frames 120–120" in mc.panel.status_label.text()
    # Alt+N on the frame shown
    mc.set_frame(200)
    _key(qtbot, w, QtCore.Qt.Key_N, QtCore.Qt.AltModifier)
    assert mc.panel.settings()["neutral_frames"] == "200:200"
    # a frame outside the take: one sentence, nothing changes
    assert not mc.use_neutral_frames(400)
    assert "outside the take" in w.last_error and "0 to 357" in w.last_error
    assert mc.panel.settings()["neutral_frames"] == "200:200"
    _close_error_box(w.last_error)
    # typed neutral frames outside the take, stable markers the take does not have or fewer than 3: Solve says
    # why in one sentence and a box, the solve shown stays
    solution = mc.solution
    for edit, text, words in ((mc.panel.neutral_edit, "400:420", "outside the take"),
                              (mc.panel.stable_edit, "root-*", "not in the take"),
                              (mc.panel.stable_edit, "M00,M01", "at least 3 stable markers")):
        mc.panel.neutral_edit.clear()
        mc.panel.stable_edit.clear()
        _type(edit, text)
        with qtbot.waitSignal(mc.solve_failed, timeout=60000) as sig:
            _click(mc.panel.solve_button)
        assert words in sig.args[0] and "\n" not in sig.args[0] and w.last_error == sig.args[0]
        _close_error_box(sig.args[0])
        assert mc.solution is solution and mc.take is not None and mc.marker_map is not None
        assert w.document.rig is rig
    mc.panel.stable_edit.clear()
    _type(mc.panel.neutral_edit, "200:200")

    # the map on the rig: a point per mapped marker, the actor's neutral markers beside them
    _click(mc.panel.show_map_button)
    ed = mc.map_editor
    assert ed.shown and len(ed.point_positions()) == 60 and not w.markers.mode_action.isChecked()
    B = mc.marker_map.binding(rig, ed.labels)
    assert np.allclose(ed.point_positions(), B @ w.document.surface().astype(np.float64), atol=1e-4)
    # drag the first marker's point 8 mm to the character's left along the face
    i, label = 0, ed.labels[0]
    old_entry = mc.marker_map.markers[label]
    P = ed.point_positions()[i]
    d = w.viewport.world_to_display(np.vstack([P, P + [0.8, 0.0, 0.0]]))
    a, b = (w.viewport.display_to_qt(x, y) for x, y, _ in d)
    start, end = QtCore.QPoint(round(a.x()), round(a.y())), QtCore.QPoint(round(b.x()), round(b.y()))
    canvas = w.viewport.canvas
    mouse(canvas, "press", start)
    assert ed.drag is not None and ed.drag["label"] == label
    for k in range(1, 5):
        mouse(canvas, "move", start + (end - start) * k / 4)
    mouse(canvas, "release", end)
    new_entry = mc.marker_map.markers[label]
    assert new_entry != old_entry
    moved = mc.marker_map.binding(rig, [label]) @ rig.neutral
    was = B[i] @ rig.neutral
    assert 0.5 < np.linalg.norm(moved - was) < 1.2 and (moved - was)[0, 0] > 0.4   # ~8 mm along +x (cm)
    assert w.document.undo_stack.undoText() == f"Move marker {label} on the rig"
    assert mc.solution is None                          # the solve was of the old map
    _undo(qtbot, w)
    assert mc.marker_map.markers[label] == old_entry
    _redo(qtbot, w)
    assert mc.marker_map.markers[label] == new_entry
    # saved as a marker map (Save Map…) and with the project
    out = tmp_path / "corrected_map.json"
    assert mc.save_map(out)
    assert json.loads(out.read_text())["markers"][label] == new_entry
    project = tmp_path / "actor.bsproj"
    assert w.save_to(project)
    open_and_wait(qtbot, w, project)
    qtbot.waitUntil(lambda: w.mocap.marker_map is not None, timeout=30000)
    assert w.mocap.marker_map.markers[label] == new_entry
    assert w.mocap.panel.settings()["neutral_frames"] == "200:200"


def test_personalize_from_the_mocap_panels_marker_take(qtbot, tmp_path):
    """An actor without scans: the Mocap panel's take and map fill the dialog; the template is warped to the
    actor's neutral markers (here the rig 8 % larger) and its shapes carried onto it."""
    from model.take_csv import write_marker_csv
    from model.take_data import MarkerTake
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig.copy()
    moving = np.flatnonzero(np.abs(rig.deltas).max(axis=(0, 2)) > 0.05)
    verts = moving[np.linspace(0, len(moving) - 1, 40).astype(int)]
    labels = [f"M{i:02d}" for i in range(len(verts))]
    X = np.repeat((rig.neutral[verts] * 1.08)[None], 40, axis=0)
    take, mapping = tmp_path / "actor.csv", tmp_path / "map.json"
    write_marker_csv(take, MarkerTake(X * 10.0, labels, 30.0, units="mm"))
    mapping.write_text(json.dumps({"rig_units": "cm", "markers": dict(zip(labels, map(int, verts)))}))
    assert w.mocap.load_take(take) and w.mocap.load_map(mapping)
    _key(qtbot, w, QtCore.Qt.Key_P, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    dlg = w.actor.dialog
    assert dlg.take_edit.text() == str(take) and dlg.map_edit.text() == str(mapping)
    _type(dlg.output_edit, str(tmp_path / "from_take.bsproj"))
    with qtbot.waitSignal(w.actor.personalized, timeout=180000):
        _click(dlg.ok_button)
    qtbot.waitUntil(lambda: w.document.path == tmp_path / "from_take.bsproj" and not w.is_loading, timeout=60000)
    actor = w.document.rig
    assert w.actor.last_summary["neutral"] == "warped to the take's neutral markers"
    # the actor's markers are placed rigidly on the rig's (a take's frame says nothing of where the face is), so
    # the warped neutral is the rig 8 % larger about the markers' centre
    c = rig.neutral[verts].mean(axis=0)
    assert np.abs(actor.neutral[verts] - (c + 1.08 * (rig.neutral[verts] - c))).max() < 0.02   # cm, at the markers
    assert actor.shape_names == rig.shape_names
    # the take and its map came along with the project
    assert w.mocap.take is not None and w.mocap.marker_map is not None


def _overlapping_widgets(dialog: QtWidgets.QWidget) -> list:
    """Pairs of visible widgets laid out side by side in ``dialog`` (by any of its layouts, nested ones too) whose
    geometries overlap."""
    def widgets_of(layout):
        for i in range(layout.count()):
            item = layout.itemAt(i)
            if item.widget() is not None:
                yield item.widget()
            elif item.layout() is not None:
                yield from widgets_of(item.layout())
    bad = []
    for layout in [dialog.layout(), *dialog.findChildren(QtWidgets.QLayout)]:
        shown = [wd for wd in widgets_of(layout) if wd.isVisible()]
        for i, a in enumerate(shown):
            for b in shown[i + 1:]:
                if a.parentWidget() is b.parentWidget() and a.geometry().intersects(b.geometry()):
                    bad.append((type(a).__name__, getattr(a, "text", str)(), a.geometry().getRect(),
                                type(b).__name__, getattr(b, "text", str)(), b.geometry().getRect()))
    return bad


def test_the_personalize_dialog_opens_at_its_size_and_nothing_in_it_overlaps(qtbot, tmp_path):
    """File ▸ Personalize to Actor… opens at least at the dialog's preferred size (within the screen) and no widget
    sits on another: it opened at 560x453 (preferred 497x559), the Add Files…/Add Folder…/Remove buttons inside
    the Pose scans list and the next group over the Scans group's border. Made narrower by the user, the dialog
    stays tall enough for its wrapped introduction."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    w.actor.action.trigger()                 # File ▸ Personalize to Actor…
    dlg = w.actor.dialog
    assert dlg is not None
    qtbot.waitExposed(dlg)
    qtbot.wait(50)
    screen = dlg.screen().availableGeometry()
    hint = dlg.sizeHint()
    assert dlg.width() >= min(hint.width(), screen.width()) and dlg.height() >= min(hint.height(), screen.height())
    assert not _overlapping_widgets(dlg)
    for size in ((380, 300), (900, 400)):
        dlg.resize(*size)
        qtbot.wait(100)
        assert not _overlapping_widgets(dlg), (size, dlg.size().toTuple())
    dlg.reject()


def test_personalize_starts_its_process_off_the_gui_thread(qtbot, tmp_path, monkeypatch):
    """Pressing Personalize starts the child process (the rig pickled into a pipe the new interpreter reads once it is
    up: 0.3-0.45 s on ICT FaceKit) on another thread: it was started on the GUI thread, which held the window about
    half a second before the progress dialog showed. The result is written and opened as before."""
    import multiprocessing.context as mpc

    from tests.gui_helpers import calls_on_gui_thread
    threads = calls_on_gui_thread(monkeypatch, mpc.SpawnProcess, "start")
    w = make_window(qtbot, tmp_path)
    neutral, poses = _actor_scans(w.document.rig, tmp_path / "actor", n=3)
    out = tmp_path / "actor.bsproj"
    dlg = w.actor.show_dialog()
    dlg.neutral_edit.setText(str(neutral))
    dlg.add_scans([str(poses)])
    dlg.output_edit.setText(str(out))
    with qtbot.waitSignal(w.actor.personalized, timeout=180000):
        _click(dlg.ok_button)
    assert threads == [False]
    assert out.exists()


def test_the_personalize_dialog_takes_the_mocap_panels_calibration_length(qtbot, tmp_path, take_dir):
    """File ▸ Personalize to Actor… filled in the Mocap panel's take and map but always said 30 neutral frames at
    the take's start, whatever the panel's calibration length the take was solved with."""
    w = make_window(qtbot, tmp_path)
    assert w.mocap.load_take(take_dir / "take.c3d")
    box = w.mocap.panel.calibration_spin
    _type(box.lineEdit(), "12")
    QTest.keyClick(box, QtCore.Qt.Key_Return)
    assert w.mocap.panel.settings()["calibration_frames"] == 12
    _key(qtbot, w, QtCore.Qt.Key_P, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    dlg = w.actor.dialog
    assert dlg.take_edit.text() == str(take_dir / "take.c3d") and dlg.calibration_spin.value() == 12
    dlg.reject()


def test_personalize_from_a_take_uses_the_frame_chosen_as_neutral(qtbot, tmp_path, ict_dir):
    """The actor's neutral chosen on the take (right-click the slider ▸ Use This Frame as Neutral) is the neutral a
    personalisation from that take warps the template to: the dialog showed only the neutral frames at the take's
    start and the job read the first 30 frames, whatever frame the user had chosen."""
    from model.marker_map import load_marker_map
    from model.personalize import _marker_neutral
    from model.takes import load_take
    from tests.conftest import DATA, require_data
    take_dir = require_data(DATA / "mocap" / "actor_take")
    w = make_window(qtbot, tmp_path, size=(1400, 1000))
    open_and_wait(qtbot, w, ict_dir)
    template = w.document.rig.copy()
    mc = w.mocap
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=180000):
        _click(mc.panel.solve_button)
    _use_frame_as_neutral(qtbot, mc, 120)
    assert mc.panel.settings()["neutral_frames"] == "120:120"
    _key(qtbot, w, QtCore.Qt.Key_P, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    dlg = w.actor.dialog
    assert dlg.take_edit.text() == str(take_dir / "take.c3d") and dlg.neutral_frames_edit.text() == "120:120"
    assert not dlg.calibration_spin.isEnabled()     # the chosen frame is the neutral, not the frames at the start
    out = tmp_path / "from_frame_120.bsproj"
    _type(dlg.output_edit, str(out))
    with qtbot.waitSignal(w.actor.personalized, timeout=300000):
        _click(dlg.ok_button)
    qtbot.waitUntil(lambda: w.document.path == out and not w.is_loading, timeout=60000)
    assert w.actor.last_summary["neutral_frames"] == [120, 120]
    take, mm = load_take(take_dir / "take.c3d"), load_marker_map(take_dir / "marker_map.json")
    at_120, _ = _marker_neutral(template, take, mm, neutral_frames=(120, 120))
    at_start, _ = _marker_neutral(template, take, mm, 30)
    actor = np.asarray(w.document.rig.neutral, dtype=np.float64)
    assert np.abs(actor - at_120).max() < 1e-4                     # cm: what the model gives for frame 120
    assert np.abs(at_120 - at_start).max() > 0.05 and np.abs(actor - at_start).max() > 0.05


def test_the_personalize_progress_says_the_stage_and_the_time_so_far(qtbot, tmp_path, ict_dir):
    """The progress window said "Personalising … to the actor…" from start to end, for up to minutes: it now says the
    stage the job reached (the actor's neutral, shape k/K of the solve, the shapes' deltas, writing) and the time so
    far, and changes as the job goes on. A real run: ICT FaceKit from mocap/actor_take alone (about 10 s)."""
    import re

    from tests.conftest import DATA, require_data
    take_dir = require_data(DATA / "mocap" / "actor_take")
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    assert w.mocap.load_take(take_dir / "take.c3d") and w.mocap.load_map(take_dir / "marker_map.json")
    seen = []
    w.actor.progress_changed.connect(lambda text: seen.append((text, w.actor.progress.labelText())))
    _key(qtbot, w, QtCore.Qt.Key_P, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    dlg = w.actor.dialog
    _type(dlg.output_edit, str(tmp_path / "actor.bsproj"))
    with qtbot.waitSignal(w.actor.personalized, timeout=300000):
        _click(dlg.ok_button)
    texts = [t for t, _ in seen]
    assert all(t == shown for t, shown in seen)          # what the progress window showed
    stages = [re.match(r"Personalising \S+ to the actor: (.*)… \((\d+) s\)\n", t) for t in texts]
    assert all(stages), texts
    said = [m.group(1) for m in stages]
    assert len(set(said)) >= 3, said
    K = w.document.rig.n_shapes
    assert any(re.fullmatch(rf"shape \d+/{K}: its transferred gradients", s) for s in said), said
    assert any(s.startswith(f"the {K} shapes' deltas (") for s in said), said
    assert [int(m.group(2)) for m in stages] == sorted(int(m.group(2)) for m in stages)
    assert int(stages[-1].group(2)) >= 2                 # the time so far, counted on


def test_the_personalize_dialogs_neutral_frames_go_with_the_mocap_panels_take(qtbot, tmp_path):
    """The dialog fills in the Mocap panel's take and the neutral frames chosen on it; typing another take's path
    kept those frames, frames of a different recording, which the job then read as that take's neutral. They are
    cleared now when the path names another take (the calibration frames at its start count again) and come back
    when it names the panel's take again; a range the user typed stays."""
    from model.take_csv import write_marker_csv
    from model.take_data import MarkerTake
    from model.takes import load_take
    from tests.conftest import DATA, require_data
    real = load_take(require_data(DATA / "mocap" / "actor_take" / "take.trc"))
    w = make_window(qtbot, tmp_path)
    take, other = tmp_path / "actor.csv", tmp_path / "other.csv"
    for path in (take, other):
        write_marker_csv(path, MarkerTake(real.positions[:40], real.labels, real.rate, real.units))
    assert w.mocap.load_take(take)
    _type(w.mocap.panel.neutral_edit, "12:14")
    _key(qtbot, w, QtCore.Qt.Key_P, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    dlg = w.actor.dialog
    assert dlg.take_edit.text() == str(take) and dlg.neutral_frames_edit.text() == "12:14"
    assert not dlg.calibration_spin.isEnabled()
    _type(dlg.take_edit, str(other))
    assert dlg.neutral_frames_edit.text() == "" and dlg.calibration_spin.isEnabled()
    assert dlg.request()["take"] == str(other) and dlg.request()["neutral_frames"] is None
    _type(dlg.take_edit, str(take))                   # the panel's take again: its chosen frames again
    assert dlg.neutral_frames_edit.text() == "12:14" and not dlg.calibration_spin.isEnabled()
    _type(dlg.neutral_frames_edit, "3:5")             # a range typed for the take is the user's: it stays
    _type(dlg.take_edit, str(other))
    assert dlg.request()["take"] == str(other) and dlg.request()["neutral_frames"] == "3:5"
    dlg.reject()
