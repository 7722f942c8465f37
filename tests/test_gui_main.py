"""The main window with pytest-qt: posing with a real slider drag, undo, open, save, bad input."""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from tests.gui_helpers import make_window, mouse, open_and_wait, wait_until_still
from tests.rig_files import write_rig_folder


def _drag_slider(slider, fraction):
    """Press on the slider handle, move to ``fraction`` of the groove, release (real mouse events)."""
    opt = QtWidgets.QStyleOptionSlider()
    slider.initStyleOption(opt)
    style = slider.style()
    handle = style.subControlRect(QtWidgets.QStyle.CC_Slider, opt, QtWidgets.QStyle.SC_SliderHandle, slider)
    groove = style.subControlRect(QtWidgets.QStyle.CC_Slider, opt, QtWidgets.QStyle.SC_SliderGroove, slider)
    start = handle.center()
    mouse(slider, "press", start)
    x_end = groove.left() + int(fraction * groove.width())
    for x in np.linspace(start.x(), x_end, 6)[1:]:
        mouse(slider, "move", QtCore.QPoint(int(x), start.y()))
    mouse(slider, "release", QtCore.QPoint(x_end, start.y()))


def test_opens_sample_face(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    assert rig.name == "sample" and rig.n_vertices >= 5000 and rig.n_shapes >= 24
    assert w.viewport.points().shape == (rig.n_vertices, 3)
    assert f"{rig.n_vertices:,} vertices" in w.counts_label.text()


def test_slider_drag_moves_mesh_and_undo_restores(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    k = rig.shape_index("jawOpen")
    row = w.shapes_panel.row("jawOpen")
    w.shapes_dock.raise_()
    before = w.viewport.points().copy()
    _drag_slider(row.slider, 0.8)
    qtbot.waitUntil(lambda: not w.redraw_pending)
    weight = w.document.weights[k]
    assert 0.5 < weight <= 1.0
    moved = np.linalg.norm(w.viewport.points() - before, axis=1)
    jaw = np.linalg.norm(rig.deltas[k], axis=1)
    assert moved[jaw > 0.5 * jaw.max()].min() > 0.25 * weight * jaw.max()  # the jaw moved, by its weight
    assert w.document.undo_stack.count() == 1  # one drag is one undo step
    w.undo_action.trigger()
    qtbot.waitUntil(lambda: not w.redraw_pending)
    assert w.document.weights[k] == 0
    np.testing.assert_array_equal(w.viewport.points(), before)
    assert row.slider.value() == 0
    w.redo_action.trigger()
    assert w.document.weights[k] == weight


def test_preset_reset_and_typed_value_are_undo_steps(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.apply_preset("happy")
    happy = w.document.weights
    assert happy.sum() > 0
    w.shapes_panel.row("jawOpen").box.setValue(0.3)
    w.reset_pose()
    assert w.document.weights.sum() == 0
    assert w.document.undo_stack.count() == 3
    w.document.undo_stack.undo()
    w.document.undo_stack.undo()
    np.testing.assert_array_equal(w.document.weights, happy)


def test_save_and_reopen_project(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.apply_preset("surprised")
    pose = w.document.weights
    path = tmp_path / "face.bsproj"
    assert w.save_to(path)
    assert not w.isWindowModified() and path.exists()
    w.reset_pose()
    rows = list(w.shapes_panel.rows)
    open_and_wait(qtbot, w, path)
    np.testing.assert_array_equal(w.document.weights, pose)
    assert w.shapes_panel.rows == rows      # the same shapes keep their rows, which show the project's pose
    np.testing.assert_allclose([r.box.value() for r in w.shapes_panel.rows], pose, atol=5e-4)
    assert w.document.path == path and w.document.rig.n_shapes >= 24
    assert str(path) in [a.text() for a in w.recent_menu.actions()][0]


def test_opening_a_project_shows_its_progress_dialog(qtbot, tmp_path, monkeypatch):
    """A studio rig's project takes seconds to read and reports no steps (an OBJ folder reports each file): the
    "Opening" dialog shows after 0.3 s all the same (it never showed for a project: its bar was never set)."""
    import time

    import app.loading
    from model.project import Project, save_project
    from resources.sample_rig import build_sample_rig
    path = tmp_path / "slow.bsproj"
    save_project(Project(rig=build_sample_rig()), path)
    w = make_window(qtbot, tmp_path)
    real = app.loading.open_project_or_rig

    def slow(*args, **kwargs):
        time.sleep(1.0)
        return real(*args, **kwargs)
    monkeypatch.setattr(app.loading, "open_project_or_rig", slow)
    shown = []
    QtCore.QTimer.singleShot(700, lambda: shown.extend(
        d.labelText() for d in w.findChildren(QtWidgets.QProgressDialog) if d.isVisible()))
    open_and_wait(qtbot, w, path)
    assert shown == ["Opening slow.bsproj…"]
    assert w.document.path == path
    assert not [d for d in w.findChildren(QtWidgets.QProgressDialog) if d.isVisible()]


def test_save_writes_off_the_gui_thread_and_the_window_keeps_drawing(qtbot, tmp_path, monkeypatch):
    """A studio rig's project takes seconds to write: the writing runs off the GUI thread while the window goes on
    drawing and running its timers, a busy dialog naming the file shows after 0.2 s (it showed only after Qt's
    default 4 s: its bar was never set), and save_to returns once the file is whole."""
    import threading
    import time

    import app.document
    from model.project import load_project
    w = make_window(qtbot, tmp_path)
    real, seen = app.document.save_project, {}

    def slow(project, path):
        seen["gui thread"] = threading.current_thread() is threading.main_thread()
        time.sleep(0.6)
        real(project, path)
    monkeypatch.setattr(app.document, "save_project", slow)
    w.set_pose(np.full(w.document.rig.n_shapes, 0.25), "pose")
    ticks = []
    timer = QtCore.QTimer()
    timer.setInterval(20)
    timer.timeout.connect(lambda: ticks.append(1))
    timer.start()
    shown = []
    QtCore.QTimer.singleShot(400, lambda: shown.extend(
        d.labelText() for d in w.findChildren(QtWidgets.QProgressDialog) if d.isVisible()))
    path = tmp_path / "saved.bsproj"
    assert w.save_to(path)
    timer.stop()
    assert shown == ["Saving saved.bsproj…"]
    assert not [d for d in w.findChildren(QtWidgets.QProgressDialog) if d.isVisible()]
    assert seen == {"gui thread": False}
    assert len(ticks) >= 10, f"{len(ticks)} timer ticks during a 0.6 s write"
    assert not w.document.is_modified and w.document.path == path
    np.testing.assert_array_equal(load_project(path).weights, w.document.weights)


def test_lengths_show_the_rigs_units(qtbot, tmp_path):
    """Brush radius, nudge step and RBF kernel length are in rig units: each box says which."""
    w = make_window(qtbot, tmp_path)
    boxes = [w.correctives.panel.radius, w.segmentation_panel.nudge_amount, w.mocap.panel.rbf_scale]
    assert w.document.rig.units == "cm" and [b.suffix() for b in boxes] == [" cm"] * 3
    rig = w.document.rig.copy()
    rig.units = "mm"
    from model.project import Project, save_project
    save_project(Project(rig=rig), tmp_path / "mm.bsproj")
    open_and_wait(qtbot, w, tmp_path / "mm.bsproj")
    assert w.document.rig.units == "mm" and [b.suffix() for b in boxes] == [" mm"] * 3
    assert "mm" in w.correctives.panel.radius.text()


def test_bad_folder_keeps_the_open_rig(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.apply_preset("happy")
    rig, pose = w.document.rig, w.document.weights
    bad = tmp_path / "bad"
    write_rig_folder(bad)
    (bad / "raise.obj").write_text("v 0 0 nan\n")
    with qtbot.waitSignal(w.load_failed, timeout=30000) as blocker:
        w.open_path(bad)
    qtbot.waitUntil(lambda: not w.is_loading)
    assert "raise.obj" in blocker.args[0] and "raise.obj" in w.last_error
    assert w.document.rig is rig
    np.testing.assert_array_equal(w.document.weights, pose)


def test_open_obj_folder_in_background(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    folder = tmp_path / "grid"
    write_rig_folder(folder)
    open_and_wait(qtbot, w, folder)
    assert w.last_error is None
    assert w.document.rig.n_vertices == 36 and w.document.rig.shape_names == ["push", "raise"]
    assert w.viewport.points().shape == (36, 3)


def test_opening_a_rig_leaves_its_passes_over_the_shapes_to_the_loader_thread(qtbot, tmp_path, ict_dir, monkeypatch):
    """The passes over every shape's deltas (the display evaluator's gather, the shapes' reach that frames the camera
    and damps marker drags) and the surface's triangulation for its normals run in the loader's thread, not the GUI
    thread: on a 228-shape, 422k-vertex rig they froze the window for seconds after its progress dialog closed.
    And the segmentation starts only once the window has taken the new rig in."""
    import threading

    import model.pose
    import model.rig_prep
    import app.segmentation_controller as seg_ctl
    import solvers.normals
    w = make_window(qtbot, tmp_path)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=60000)    # the sample face's
    calls = []
    for module, name, label in ((model.pose.PoseEvaluator, "__init__", "__init__"),
                                (model.rig_prep, "shape_reach", "shape_reach"), (seg_ctl, "segment_rig", "segment_rig"),
                                (solvers.normals.VertexNormals, "__init__", "normals")):
        real = getattr(module, name)

        def spy(*args, _real=real, _name=label, **kwargs):
            calls.append((_name, threading.current_thread() is threading.main_thread(), w.is_loading))
            return _real(*args, **kwargs)
        monkeypatch.setattr(module, name, spy)
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=60000)
    made = [c for c in calls if c[0] in ("__init__", "shape_reach")]
    assert ("__init__", False, True) in made and ("shape_reach", False, True) in made   # in the loader, once each
    assert [c for c in made if c[1]] == [], f"made on the GUI thread: {made}"
    segmented = [c for c in calls if c[0] == "segment_rig"]
    assert segmented == [("segment_rig", False, False)]   # one job, after the load had been taken in
    # what they made is what the window uses: the camera framed on the face, the drag gains from the same reach
    reach = w.document.shape_reach()
    assert reach.shape == (26719,) and reach.max() > 0
    assert np.array_equal(w.markers.gains, np.clip(reach / np.median(reach[reach > 0]), 0.05, 1.5))
    assert [c for c in calls if c[0] == "shape_reach"] == [("shape_reach", False, True)]   # not again
    # the surface drawn shades with the normals the loader made for its faces, and none were made on the GUI thread
    assert w.viewport.mesh._display_normals is w.document.default_view.normals
    assert [c for c in calls if c[0] == "normals"] == [("normals", False, True)]
    from solvers.mesh import fan_triangulate
    from solvers.normals import vertex_normals
    vp = w.viewport
    drawn = vertex_normals(vp.points(), fan_triangulate(*vp.mesh._faces))   # of the faces drawn, made afresh
    np.testing.assert_allclose(vp.mesh.point_data["Normals"], drawn, atol=1e-5)


def test_every_shortcut_is_unambiguous_and_listed(qtbot, tmp_path):
    """Qt ignores a key bound to two actions ("ambiguous shortcut"): each key does one thing, and F1 lists it."""
    from PySide6 import QtGui
    w = make_window(qtbot, tmp_path)
    keys: dict[str, list[str]] = {}
    for act in w.findChildren(QtGui.QAction):
        for sc in act.shortcuts():
            if sc.toString():
                keys.setdefault(sc.toString(), []).append(act.text())
    scoped = []                                   # keys of one list (Delete in a list with the focus)
    for sc in w.findChildren(QtGui.QShortcut):
        if sc.context() == QtCore.Qt.WidgetShortcut:
            scoped.append((sc.key().toString(), sc.whatsThis()))
        else:
            keys.setdefault(sc.key().toString(), []).append(sc.whatsThis())
    assert {k: v for k, v in keys.items() if len(v) > 1} == {}
    assert len(set(scoped)) == len(scoped) and all(k not in keys for k, _ in scoped)
    for key in ("Ctrl+Z", "Ctrl+S", "M", "Ctrl+Shift+M", "Ctrl+Space", "Ctrl+Shift+F", "F1"):
        assert key in keys, key
    listed = {k for *_, ks in w.shortcut_rows() for k in ks.split(", ")}
    assert sorted(set(keys) - listed) == [] and {k for k, _ in scoped} <= listed
    w.show_shortcuts()                                     # F1: every shortcut, with its menu
    table = w.shortcuts_dialog.findChild(QtWidgets.QTreeWidget)
    rows = [tuple(table.topLevelItem(i).text(c) for c in range(3)) for i in range(table.topLevelItemCount())]
    assert ("Ctrl+Shift+M", "Mirror Corrective", "Correctives") in rows
    assert ("[", "Smaller Brush", "Correctives ▸ Brush") in rows
    assert ("Alt+,", "Previous Take Frame") in [r[:2] for r in rows]
    # Undo and Redo by their names, not by the step they would undo now ("Undo Key the pose at 0 s")
    w.set_pose(np.full(w.document.rig.n_shapes, 0.5), "Half pose")
    names = {name for _where, name, _keys in w.shortcut_rows()}
    assert {"Undo", "Redo"} <= names and not any(n.startswith("Undo ") for n in names)
    assert rows[0][2] == "File"                            # in menu order until a column header is clicked
    assert ("Ctrl+Z", "Undo", "Edit") in rows
    assert ("Ctrl+Shift+Up", "Nudge Region Up", "Panels") in rows


def test_every_control_explains_itself_in_a_tooltip(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    silent = []
    for cls in (QtWidgets.QPushButton, QtWidgets.QComboBox, QtWidgets.QAbstractSpinBox, QtWidgets.QCheckBox,
                QtWidgets.QSlider):
        for c in w.findChildren(cls):
            if not c.toolTip() and not (c.parent() is not None and c.parent().toolTip()):
                silent.append((cls.__name__, c.text() if hasattr(c, "text") else "", type(c.parent()).__name__))
    assert silent == []


def test_mirror_pose_flips_the_face_and_undoes(qtbot, tmp_path):
    from solvers.symmetry import mirror_map
    w = make_window(qtbot, tmp_path)
    doc, rig = w.document, w.document.rig
    weights = np.zeros(rig.n_shapes)
    for name, value in (("browInnerUp_L", 0.7), ("mouthSmile_R", 0.4), ("jawOpen", 0.3)):
        weights[rig.shape_index(name)] = value
    w.set_pose(weights, "asymmetric pose")
    before = doc.surface().copy()
    assert w.mirror_pose()
    got = {n: doc.weights[rig.shape_index(n)] for n in ("browInnerUp_R", "mouthSmile_L", "jawOpen",
                                                        "browInnerUp_L", "mouthSmile_R")}
    assert got == {"browInnerUp_R": 0.7, "mouthSmile_L": 0.4, "jawOpen": 0.3, "browInnerUp_L": 0.0,
                   "mouthSmile_R": 0.0}
    m = mirror_map(rig.neutral)                 # the sample face is symmetric: the surface is the mirror image
    np.testing.assert_allclose(doc.surface(), before[m] * np.array([-1.0, 1.0, 1.0]), atol=1e-4)
    assert w.undo_action.text().endswith("Mirror pose")
    doc.undo_stack.undo()
    np.testing.assert_array_equal(doc.weights, weights)


def test_save_viewport_image(qtbot, tmp_path, monkeypatch):
    from PIL import Image
    w = make_window(qtbot, tmp_path)
    assert w.save_image(tmp_path / "shot")               # the .png suffix is added
    w.jobs.wait()                                        # written in the background
    img = np.asarray(Image.open(tmp_path / "shot.png").convert("RGB"))
    ratio = w.viewport.canvas.devicePixelRatioF()
    assert img.shape[:2] == (round(w.viewport.canvas.height() * ratio),
                             round(w.viewport.canvas.width() * ratio))
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 100   # a shaded face, not a blank frame
    # through File > Save Viewport Image and File > Export Pose: the dialog's answer is written
    answers = iter([(str(tmp_path / "menu.png"), ""), (str(tmp_path / "menu.obj"), "")])
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName", lambda *a, **k: next(answers))
    w.save_image_dialog()
    w.image_size_dialog.accept()                         # File > Export Image asks the size first
    w.export_pose()
    w.jobs.wait()                                        # the export runs in the background
    assert (tmp_path / "menu.png").stat().st_size > 0 and (tmp_path / "menu.obj").stat().st_size > 0
    assert not w.save_image("/proc/no/such/dir/x.png")
    assert w.last_error.startswith("/proc/no/such/dir/x.png: could not be written")


def test_export_image_encodes_and_writes_the_png_off_the_gui_thread(qtbot, tmp_path, monkeypatch):
    """File ▸ Export Image at 3840x2160: the picture is drawn on the GUI thread (VTK's), then encoded and written in
    the background (a 4K PNG is ~1.6 s of zlib; with the render the window froze 2.2 s); the status says so, and
    then that it is saved with its size."""
    import model.atomic
    from PIL import Image
    from tests.gui_helpers import calls_on_gui_thread
    threads = calls_on_gui_thread(monkeypatch, model.atomic, "write_png")
    w = make_window(qtbot, tmp_path)
    out = tmp_path / "big.png"
    assert w.save_image(out, (3840, 2160))
    assert w.statusBar().currentMessage() == "Writing big.png (3840x2160 pixels)…"
    assert w.jobs_bar.isVisible() and w.jobs_bar.format() == "Writing big.png…"   # the busy bar while it writes
    w.jobs.wait()
    assert threads == [False]
    assert Image.open(out).size == (3840, 2160)
    assert w.statusBar().currentMessage() == f"Saved {out} (3840x2160 pixels)"


def test_mirror_shape_replaces_or_adds_the_other_side(qtbot, tmp_path):
    from solvers.symmetry import mirror_delta, mirror_map
    from tests.rig_files import grid, obj_text
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    r = rig.shape_index("browInnerUp_R")
    right = rig.deltas[r].copy()
    n = w.document.undo_stack.count()
    w.shapes_panel.row("browInnerUp_L").label.customContextMenuRequested.emit(QtCore.QPoint(2, 2))
    menu = w.shapes_panel.row("browInnerUp_L").findChild(QtWidgets.QMenu)
    assert "Key browInnerUp_L" in [a.text() for a in menu.actions()]
    mirror = next(a for a in menu.actions() if a.text() == "Mirror to the Other Side")
    mirror.trigger()                                   # the right-click menu of the left shape's row
    menu.close()
    mirrored = mirror_delta(rig.deltas[rig.shape_index("browInnerUp_L")], mirror_map(rig.neutral))
    np.testing.assert_allclose(rig.deltas[r], mirrored)
    assert np.abs(rig.deltas[r] - right).max() < 1e-3 * np.abs(right).max() + 1e-6   # the sample is symmetric
    assert w.document.undo_stack.count() == n + 1
    w.document.undo_stack.undo()
    np.testing.assert_array_equal(rig.deltas[r], right)
    assert not w.mirror_shape("jawOpen")
    assert w.last_error.startswith("jawOpen has no side in its name")
    # a rig with only the left shape: mirroring adds the right one
    verts, faces = grid(7)
    verts[:, 0] -= 3.0                                 # centred on x = 0
    folder = tmp_path / "one_sided"
    folder.mkdir()
    (folder / "neutral.obj").write_text(obj_text(verts, faces))
    lift = verts + np.where(verts[:, :1] > 0, [0.0, 0.0, 0.4], 0.0) * verts[:, :1] / 3.0
    (folder / "lift_L.obj").write_text(obj_text(lift, faces))
    open_and_wait(qtbot, w, folder)
    rig = w.document.rig
    assert w.mirror_shape("lift_L")
    assert rig.shape_names == ["lift_L", "lift_R"] and w.shapes_panel.row("lift_R") is not None
    d = rig.deltas[1]
    assert np.abs(d[verts[:, 0] < 0, 2]).max() > 0.3 and np.abs(d[verts[:, 0] > 0]).max() == 0
    w.document.undo_stack.undo()
    assert rig.shape_names == ["lift_L"]


def test_mirror_shape_mirrors_its_inbetweens_in_one_undo_step(qtbot, tmp_path):
    """Mirror to the Other Side replaced the other side's full shape and left its in-betweens as they were: a
    mouthSmile_L with an in-between at 0.5 mirrored onto mouthSmile_R gave a right smile that went through the
    right side's old in-between (or none) at half weight. Its in-betweens are mirrored too, in the same undo step,
    and undo and redo give back each side exactly."""
    from solvers.symmetry import mirror_delta, mirror_map
    w = make_window(qtbot, tmp_path)
    doc, rig = w.document, w.document.rig
    weights = np.zeros(rig.n_shapes)
    weights[[rig.shape_index("mouthSmile_L"), rig.shape_index("jawOpen")]] = [0.5, 0.4]
    w.set_pose(weights, "pose")
    w.shape_list.add_inbetween_from_pose("mouthSmile_L", 0.5)        # a smile with the jaw a little open at 0.5
    left = rig.inbetweens["mouthSmile_L"][0].delta.copy()
    assert "mouthSmile_R" not in rig.inbetweens
    n = doc.undo_stack.count()
    row = w.shapes_panel.row("mouthSmile_L")
    row.label.customContextMenuRequested.emit(QtCore.QPoint(2, 2))
    menu = row.findChild(QtWidgets.QMenu)
    next(a for a in menu.actions() if a.text() == "Mirror to the Other Side").trigger()
    menu.close()
    rig = doc.rig
    assert doc.undo_stack.count() == n + 1
    right = rig.inbetweens["mouthSmile_R"]
    assert [i.weight for i in right] == [0.5]
    np.testing.assert_allclose(right[0].delta, mirror_delta(left, mirror_map(rig.neutral)))
    after = doc.surface().copy()
    doc.undo_stack.undo()
    assert "mouthSmile_R" not in doc.rig.inbetweens
    doc.undo_stack.redo()
    np.testing.assert_array_equal(doc.rig.inbetweens["mouthSmile_R"][0].delta, right[0].delta)
    np.testing.assert_array_equal(doc.surface(), after)


def test_tool_options_come_back_in_the_next_session(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    cp, mp = w.correctives.panel, w.mocap.panel
    cp.brush.setCurrentIndex(cp.brush.findData("smooth"))
    cp.falloff.setCurrentIndex(cp.falloff.count() - 1)
    cp.strength.setValue(0.4)
    cp.top.setValue(35)
    mp.mode_combo.setCurrentText("per region")
    mp.residual_combo.setCurrentText("none")
    mp.calibration_spin.setValue(12)
    falloff = cp.falloff.currentData()
    w.close()
    w2 = make_window(qtbot, tmp_path)       # the same settings folder: the next session
    cp, mp = w2.correctives.panel, w2.mocap.panel
    assert (cp.brush.currentData(), cp.falloff.currentData(), cp.strength.value(), cp.top.value()) == \
        ("smooth", falloff, 0.4, 35)
    assert (mp.mode_combo.currentText(), mp.residual_combo.currentText(), mp.calibration_spin.value()) == \
        ("per region", "none", 12)
    w2.close()
    from app.settings import settings
    settings().setValue("sculpt/brush", "chisel")          # an item that no longer exists, a broken number
    settings().setValue("sculpt/strength", "strong")
    w3 = make_window(qtbot, tmp_path)
    assert w3.correctives.panel.brush.currentData() == "grab" and w3.correctives.panel.strength.value() == 1.0


def test_a_pose_change_and_a_view_change_in_one_turn_draw_one_frame(qtbot, tmp_path):
    """A slider step and View ▸ Wireframe (W) handled in the same turn of the event loop: the wireframe's render
    draws the new pose too, and the render the pose change asked for is dropped (it drew the old pose, then the new
    one a moment later: two frames, the first stale)."""
    import vtk

    from widgets.shapes_panel import PoseEdit
    w = make_window(qtbot, tmp_path)
    wait_until_still(qtbot, w)
    drawn = []
    w.viewport.plotter.ren_win.AddObserver(vtk.vtkCommand.EndEvent, lambda *_: drawn.append(w.viewport.points()))
    wireframe = next(a for a in w.findChildren(QtGui.QAction) if a.text().replace("&", "") == "Wireframe")
    k = w.document.rig.shape_index("jawOpen")
    w.shapes_panel.pose_edited.emit(PoseEdit("drag-start", k))
    w.shapes_panel.pose_edited.emit(PoseEdit("drag", k, 0.7))
    wireframe.trigger()
    qtbot.wait(100)
    w.shapes_panel.pose_edited.emit(PoseEdit("drag-end", k))
    assert len(drawn) == 1 and not w.redraw_pending and w.viewport.wireframe
    np.testing.assert_allclose(drawn[0], w.document.surface(), atol=1e-5)
    assert np.abs(drawn[0] - w.document.rig.neutral).max() > 0.1      # the jaw open in it


def test_a_pose_change_draws_one_frame(qtbot, tmp_path):
    """Issue 20: never render twice for one change. A slider drag step renders once, on the event loop's next
    turn; a playback tick renders its frame at once (redraw_now), and the render its pose change had requested
    is then dropped, not drawn a second time."""
    import vtk

    from widgets.shapes_panel import PoseEdit
    w = make_window(qtbot, tmp_path)
    renders = [0]
    w.viewport.plotter.ren_win.AddObserver(vtk.vtkCommand.StartEvent,
                                           lambda *_: renders.__setitem__(0, renders[0] + 1))
    # the sample's segmentation done and shown first: its colour map's render is another change's
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=30000)
    qtbot.wait(100)
    k = w.document.rig.shape_index("jawOpen")
    p = w.shapes_panel
    p.pose_edited.emit(PoseEdit("drag-start", k))
    for value in (0.2, 0.4, 0.6):
        renders[0] = 0
        p.pose_edited.emit(PoseEdit("drag", k, value))
        assert w.redraw_pending
        qtbot.waitUntil(lambda: not w.redraw_pending, timeout=2000)
        qtbot.wait(30)
        assert renders[0] == 1
    p.pose_edited.emit(PoseEdit("drag-end", k))
    np.testing.assert_allclose(w.viewport.points(), w.document.surface(), atol=1e-5)
    # keyed playback: two keys, then the player's tick (the frame's pose, then its redraw now)
    kf = w.keyframes
    kf.set_key(0.0)
    weights = w.document.weights.copy()
    weights[k] = 1.0
    w.set_pose(weights, "open")
    kf.set_key(1.0)
    qtbot.wait(30)
    for frame in (6, 12, 18):
        renders[0] = 0
        kf.playback.frame_changed.emit(frame)
        kf.playback.ticked.emit(frame)
        qtbot.wait(30)
        assert renders[0] == 1 and not w.redraw_pending
        np.testing.assert_allclose(w.viewport.points(), w.document.surface(), atol=1e-5)
    # a new surface (a rig opened) is framed by the camera and drawn once, not once for the camera and again
    renders[0] = 0
    rig = w.document.rig
    w.viewport.set_surface(w.document.surface(), rig.face_counts, rig.face_indices)
    assert renders[0] == 1
    # and a rig opened into the document (its rig, then its pose, announced) is drawn once, in its pose
    from model.project import Project
    project = Project(rig=rig.copy())
    project.weights[:] = 0.0
    project.weights[rig.shape_index("jawOpen")] = 0.8
    renders[0] = 0
    w.document.set_project(project, None)
    # not in the turn that takes the rig in (a studio rig's first render is 0.16 s more of a frozen window) ...
    started = []        # ... but on a later one, once, and before its segmentation starts (whose thread would slow it)
    segment = w.segmentation.recompute
    w.segmentation.recompute = lambda settings: (started.append(renders[0]), segment(settings))
    assert renders[0] == 0 and w.redraw_pending
    qtbot.waitUntil(lambda: bool(started), timeout=2000)
    assert started == [1] and not w.redraw_pending
    np.testing.assert_allclose(w.viewport.points(), w.document.surface(), atol=1e-5)
    # the next pose change is drawn as before (once the new rig's segmentation, which recolours the view, is in)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=60000)
    qtbot.wait(100)
    renders[0] = 0
    w.set_pose(np.zeros(rig.n_shapes), "close")
    qtbot.wait(50)
    assert renders[0] == 1
    np.testing.assert_allclose(w.viewport.points(), w.document.surface(), atol=1e-5)
    # a view whose camera was never set (a new window's first rig) draws its first surface once too: pyvista's
    # camera getter had framed the scene itself and rendered it twice before the preset's framing and render
    from widgets.viewport import Viewport
    fresh = Viewport()
    qtbot.addWidget(fresh)
    fresh.resize(400, 400)
    fresh.show()
    qtbot.wait(50)
    drawn = [0]
    fresh.plotter.ren_win.AddObserver(vtk.vtkCommand.StartEvent, lambda *_: drawn.__setitem__(0, drawn[0] + 1))
    fresh.set_surface(w.document.surface(), rig.face_counts, rig.face_indices)
    assert drawn[0] == 1
    fresh.close()


def test_a_view_change_draws_one_frame(qtbot, tmp_path):
    """Issue 20: never render twice for one change. Choosing a view whose colour map has a legend (segmentation, the
    deformation's direction colours) or leaves one with a colour bar rendered the picture up to four times: pyvista's
    remove_scalar_bar, add_legend and add_text each render it (0.11 s a render at 422k vertices)."""
    import vtk
    w = make_window(qtbot, tmp_path)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=60000)
    w.segmentation.wait()
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=5000)
    renders = [0]
    w.viewport.plotter.ren_win.AddObserver(vtk.vtkCommand.StartEvent,
                                           lambda *_: renders.__setitem__(0, renders[0] + 1))
    sp = w.segmentation_panel
    for view in ("deformation", "deformation-rgb", "segmentation", "deformation", "shaded", "segmentation"):
        qtbot.wait(30)
        renders[0] = 0
        sp.view.setCurrentIndex(sp.view.findData(view))
        w.segmentation.wait()
        qtbot.waitUntil(lambda: not w.redraw_pending, timeout=5000)
        qtbot.wait(30)
        assert renders[0] == 1, f"{view}: {renders[0]} renders"
        colormap = w.viewport.colormap
        assert (colormap is None) == (view == "shaded")


def test_the_direction_colour_view_finds_its_vectors_off_the_gui_thread(qtbot, tmp_path, monkeypatch):
    """The direction-colour view (Joshi §2's vector view) colours each vertex by the Laplacian vector of its
    strongest shape. Those vectors are made with the segmentation, on its worker thread: choosing the view made them
    on the GUI thread (0.1-0.2 s of a frozen window on the 422k-vertex studio rig), and the view shows them."""
    import solvers.deformation_maps as deformation_maps
    from tests.gui_helpers import calls_on_gui_thread
    threads = calls_on_gui_thread(monkeypatch, deformation_maps, "argmax_vectors")
    w = make_window(qtbot, tmp_path)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=60000)
    sp = w.segmentation_panel
    sp.view.setCurrentIndex(sp.view.findData("deformation-rgb"))
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=5000)
    assert threads == [False]
    maps = w.segmentation.cache.maps()
    expected = deformation_maps.vector_colors(maps.vector, float(np.percentile(np.abs(maps.vector)[maps.vector != 0],
                                                                                 98)))
    shown = w.viewport.colormap
    assert shown.rgb and np.abs(shown.scalars.astype(float) - expected * 255).max() <= 1.0
    assert len(np.unique(shown.scalars, axis=0)) > 100       # colours by direction, not one grey


def test_an_expose_shows_the_last_render_again_unless_something_changed(qtbot, tmp_path):
    """A window closing over the viewport (a menu, a tooltip, a dialog; no compositor) exposes it: the picture VTK
    keeps is shown again without a render when nothing changed since the last one (a render is 0.1-0.16 s at 422k
    vertices), and rendered when anything did (here the camera, turned without a render)."""
    import vtk
    w = make_window(qtbot, tmp_path)
    plotter = w.viewport.plotter
    wait_until_still(qtbot, w)      # the sample's segmentation shown: its colour map's render comes late when busy
    renders = [0]
    plotter.ren_win.AddObserver(vtk.vtkCommand.StartEvent, lambda *_: renders.__setitem__(0, renders[0] + 1))
    corner = plotter.mapToGlobal(QtCore.QPoint(0, 0))
    box = (corner.x(), corner.y(), plotter.width(), plotter.height())

    def on_screen() -> np.ndarray:
        image = QtWidgets.QApplication.primaryScreen().grabWindow(0, *box).toImage()
        image = image.convertToFormat(QtGui.QImage.Format_RGB888)
        return np.array(image.constBits(), np.uint8).reshape(image.height(), image.bytesPerLine())[:, :box[2] * 3]

    def cover_and_expose() -> None:
        cover = QtWidgets.QWidget(None, QtCore.Qt.FramelessWindowHint | QtCore.Qt.Tool)
        cover.setStyleSheet("background: rgb(255, 0, 0)")
        cover.setGeometry(corner.x() + 20, corner.y() + 20, box[2] // 2, box[3] // 2)
        cover.show()
        qtbot.waitExposed(cover)
        qtbot.wait(50)
        assert (on_screen() != shown).any(axis=1).sum() > box[3] // 3      # the viewport's pixels were covered
        cover.close()
        plotter.repaint()               # the expose (done at once here; the X server's own may come later)
        qtbot.wait(50)

    shown = on_screen()
    cover_and_expose()
    assert renders[0] == 0
    np.testing.assert_array_equal(on_screen(), shown)
    cover_and_expose()                  # again: still the same picture, still no render
    assert renders[0] == 0
    np.testing.assert_array_equal(on_screen(), shown)
    # something changed without a render (the camera turned): the expose renders it
    plotter.camera.Azimuth(40.0)
    plotter.repaint()
    assert renders[0] == 1
    turned = on_screen()
    assert (turned != shown).any(axis=1).sum() > box[3] // 4
    shown = turned
    cover_and_expose()
    assert renders[0] == 1
    np.testing.assert_array_equal(on_screen(), shown)
    # a change whose redraw is pending (the window renders on the event loop's next turn): an expose before it shows
    # the last picture, and the redraw renders the change once
    plotter.camera.Azimuth(-40.0)
    w.request_render()
    plotter.repaint()
    assert renders[0] == 1 and w.redraw_pending
    np.testing.assert_array_equal(on_screen(), shown)
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=2000)
    qtbot.wait(50)
    assert renders[0] == 2
    assert (on_screen() != shown).any(axis=1).sum() > box[3] // 4


def _dock_tab_bars(w) -> list[list[str]]:
    """The tabs of every dock tab bar the window shows."""
    return [[bar.tabText(i) for i in range(bar.count())]
            for bar in w.findChildren(QtWidgets.QTabBar, options=QtCore.Qt.FindDirectChildrenOnly)
            if bar.isVisible() and bar.count()]


def _assert_one_tab_bar_per_group(w) -> None:
    docks = {d.windowTitle(): d for d in w.findChildren(QtWidgets.QDockWidget)}
    bars = _dock_tab_bars(w)
    assert bars, "no dock tab bar is shown"
    shown = [t for tabs in bars for t in tabs]
    assert len(shown) == len(set(shown)), f"a panel's tab is shown twice: {bars}"
    for tabs in bars:
        group = {tabs[0], *(d.windowTitle() for d in w.tabifiedDockWidgets(docks[tabs[0]]) if not d.isHidden())}
        assert set(tabs) == group, f"a tab bar {tabs} is not the tab group {sorted(group)}"


def test_the_side_panels_are_two_tab_groups_on_first_start(qtbot, tmp_path):
    """On first start the left panels are one tab group and the right ones another, Shapes first and full height: a
    Qt version left Texture (or History, Mocap) as a dock of its own beside the group, taking half the Shapes list's
    height."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    right = {w.shapes_dock, *w.tabifiedDockWidgets(w.shapes_dock)}
    assert {d.windowTitle() for d in right} == {"Shapes", "History", "Texture", "Mocap"}
    left = {w.segmentation_dock, *w.tabifiedDockWidgets(w.segmentation_dock)}
    assert {d.windowTitle() for d in left} == {"Segmentation", "Correctives", "Markers"}
    assert not w.shapes_dock.visibleRegion().isEmpty()
    assert w.shapes_dock.height() > 0.8 * w.centralWidget().height()


def test_each_tab_group_shows_one_tab_bar_also_after_a_restart(qtbot, tmp_path):
    """QMainWindow left the tab bars it made before the window first showed on screen (docks tabified one by one,
    a saved layout restored): a ghost 'Segmentation | Correctives' bar and the right panels' tabs twice."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    _assert_one_tab_bar_per_group(w)
    first = sorted(map(sorted, _dock_tab_bars(w)))
    assert ["Correctives", "Markers", "Segmentation"] in first
    w.close()                                            # saves the layout
    again = make_window(qtbot, tmp_path, size=(1400, 900))   # restores it
    _assert_one_tab_bar_per_group(again)
    assert sorted(map(sorted, _dock_tab_bars(again))) == first


def test_every_button_shows_its_whole_label_at_the_default_size(qtbot, tmp_path):
    """At the window's default size every panel's buttons show their whole text (a label cut to 'ew corrective
    from combinatio' tells a user nothing)."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    checked, cut = 0, []
    for dock in w.findChildren(QtWidgets.QDockWidget):
        if dock.isHidden():
            continue
        dock.raise_()
        QtWidgets.QApplication.processEvents()
        for b in dock.findChildren(QtWidgets.QPushButton) + dock.findChildren(QtWidgets.QToolButton):
            if b.isVisible() and b.text():
                checked += 1
                room = b.width() - 4                   # a tool button's frame
                if isinstance(b, QtWidgets.QPushButton):
                    opt = QtWidgets.QStyleOptionButton()
                    opt.initFrom(b)
                    room = b.style().subElementRect(QtWidgets.QStyle.SE_PushButtonContents, opt, b).width()
                if b.fontMetrics().horizontalAdvance(b.text().replace("&", "")) > room:
                    cut.append((dock.windowTitle(), b.text(), b.width()))
    assert checked > 30
    assert not cut, f"buttons whose label does not fit: {cut}"


def test_every_panel_fits_its_dock_at_the_default_size(qtbot, tmp_path, ict_dir):
    """At the window's default size with ICT FaceKit open, no panel is wider than its dock: a panel cut off at the
    right behind a horizontal scroll bar hides its values (the segmentation's level, a threshold's digits) and its
    right-hand buttons. Long choices in drop-down lists are cut instead (the open list shows them whole)."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    checked, too_wide = 0, []
    for dock in w.findChildren(QtWidgets.QDockWidget):
        area = dock.widget()
        if dock.isHidden() or not isinstance(area, QtWidgets.QScrollArea):
            continue
        dock.raise_()
        QtWidgets.QApplication.processEvents()
        checked += 1
        need, room = area.widget().minimumSizeHint().width(), area.viewport().width()
        if need > room or area.horizontalScrollBar().isVisible():
            too_wide.append((dock.windowTitle(), need, room))
    assert checked >= 5
    assert not too_wide, f"panels wider than their docks (title, needs px, has px): {too_wide}"


def test_the_window_compiles_the_take_solver_in_the_background_and_says_so_meanwhile(qtbot, tmp_path, monkeypatch):
    """A fresh installation: the window starts the solver's build in a process of its own when it opens and the
    status bar says so until that process ends; with the solver built, nothing is started or shown."""
    import subprocess
    import sys

    from solvers import take_kernel
    window = make_window(qtbot, tmp_path)
    real_start = take_kernel.start_background_build
    started = []

    def start():      # a build process that takes a second
        started.append(subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.0)"]))
        return started[-1]
    monkeypatch.setattr(take_kernel, "start_background_build", start)
    window.prepare_take_solver()
    label = window.solver_build_label
    assert len(started) == 1 and label.isVisible() and label.text() == take_kernel.BUILD_MESSAGE
    qtbot.waitUntil(lambda: not label.isVisible(), timeout=10000)
    assert started[0].poll() == 0
    monkeypatch.setattr(take_kernel, "start_background_build", real_start)
    monkeypatch.setattr(take_kernel, "ready", lambda: True)        # built
    window.prepare_take_solver()
    assert not label.isVisible()


def test_a_background_result_waits_for_an_edit_under_way(qtbot, tmp_path):
    """A background job's result (e.g. Save as new shape's) arriving while an undo command's edit runs off the GUI
    thread (``run_modal``, whose event loop goes on) is delivered after the edit, never in its middle."""
    import threading
    import time

    from app.background import run_modal
    w = make_window(qtbot, tmp_path)
    order, started = [], threading.Event()

    def job():
        started.wait(5)
        return "result"

    w.run_in_background("Job…", job, lambda r: order.append(("delivered", r)))

    def edit():
        started.set()
        time.sleep(0.5)                    # the job's result reaches the GUI thread meanwhile
        order.append(("edit done",))
        return 1

    assert run_modal(w, "Shapes", "Move…", edit) == 1
    order.append(("returned",))
    qtbot.waitUntil(lambda: len(order) == 3, timeout=5000)
    assert order == [("edit done",), ("returned",), ("delivered", "result")]


def test_export_pose_refuses_the_rigs_own_obj_folder(qtbot, tmp_path):
    """File ▸ Export Pose as OBJ wrote into the rig's own OBJ folder: a new OBJ there is read as one more shape the
    next time the rig is opened, an old one (a shape) was overwritten. The command line refuses both; the window
    shows the same rule's sentence (``model.beside_inputs``) and writes nothing. Elsewhere it writes as before."""
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    before = sorted(p.name for p in rig.iterdir())
    raise_obj = (rig / "raise.obj").read_bytes()
    w = make_window(qtbot, tmp_path, sample=False)
    open_and_wait(qtbot, w, rig)
    w.export_pose_to(rig / "pose.obj")
    assert w.last_error == (f"{rig / 'pose.obj'}: is in {rig}, the folder the rig is read from, and would be read "
                            "there as one more shape; choose a file elsewhere.")
    w.export_pose_to(rig / "raise.obj")
    assert w.last_error == (f"{rig / 'raise.obj'}: is in {rig}, the folder the rig is read from, and would "
                            "overwrite a file it reads; choose a file elsewhere.")
    w.jobs.wait()
    assert sorted(p.name for p in rig.iterdir()) == before and (rig / "raise.obj").read_bytes() == raise_obj
    w.export_pose_to(tmp_path / "pose.obj")
    w.jobs.wait()
    assert (tmp_path / "pose.obj").stat().st_size > 0
