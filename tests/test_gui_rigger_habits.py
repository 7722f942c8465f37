"""Issue 18's "What riggers expect" (the editor's part), driven with real input events: keys of one shape, the
Graph Editor, next/previous key, frame selected / frame all, files dropped on the window, image export at a
size, the first start, Marker mode's button, status messages in the user's words."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from tests.gui_helpers import drop_files, make_window, open_and_wait
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


def test_the_graph_editor_and_the_take_curves_label_their_time_axis_in_seconds(qtbot, tmp_path, llf_csv):
    """The Graph Editor's curves and the Mocap Views' weight and error curves had no time axis: a key's time could
    only be read by moving the playhead onto it. The seconds are written under the curves, a key at 1 s on the
    "1 s" tick."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    kf = w.keyframes
    jaw = w.document.rig.shape_index("jawOpen")
    kf.set_key(0.0)
    kf.scrub(1.0)
    _pose(w, jawOpen=0.5)
    kf.set_key(1.0)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_G, QtCore.Qt.ControlModifier)     # Animation ▸ Graph Editor
    plot = kf.graph.plot
    qtbot.waitUntil(lambda: plot.isVisible() and plot.height() > 120, timeout=3000)
    ticks = dict((label, x) for x, label in plot.time_ticks())
    assert ticks.keys() >= {"0 s", "1 s", "2 s"}
    assert abs(ticks["1 s"] - plot.key_point(1.0, 0.5).x()) < 0.5 and jaw in plot.keys
    image = plot.grab().toImage()
    bottom = plot.key_point(1.0, plot.y_range[0]).y()        # the plot's lower edge
    below = [QtGui.QColor(image.pixel(int(ticks["1 s"]) + dx, int(bottom) + dy)).lightness()
             for dx in range(-8, 9) for dy in range(5, 14)]
    assert max(below) > 120                                    # the label is drawn under its tick
    assert w.mocap.load_take(llf_csv)                          # a Live Link Face take: its weight curves
    weights = w.mocap.weight_plot
    labels = [label for _, label in weights.time_ticks()]
    assert labels[0] == "0 s" and weights.rate == w.mocap.take.rate and len(labels) >= 2


def test_a_click_on_a_curve_makes_it_the_graph_editors_active_curve(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    kf, rig = w.keyframes, w.document.rig
    jaw, smile = rig.shape_index("jawOpen"), rig.shape_index("mouthSmile_L")
    kf.set_key(0.0)
    _pose(w, jawOpen=0.2, mouthSmile_L=0.9)
    kf.set_key(1.0)
    kf.show_graph_editor()
    qtbot.waitUntil(lambda: kf.graph.plot.isVisible() and kf.graph.plot.height() > 120, timeout=3000)
    plot = kf.graph.plot
    assert kf.graph.selected_shapes() == [] and set(plot.shapes) == {jaw, smile}   # the shapes that move
    f = int(round(0.8 * kf.fps))                                  # a frame on the smile's curve, off its keys
    value = float(plot.curves[plot.shapes.index(smile)][1][f])
    assert abs(value - float(plot.curves[plot.shapes.index(jaw)][1][f])) > 0.3
    qtbot.mouseClick(plot, QtCore.Qt.LeftButton, pos=plot.key_point(f / kf.fps, value).toPoint())
    assert kf.graph.selected_shapes() == [smile] and plot.active == smile and plot.shapes == [smile]
    assert kf.time == 0.0                                         # a click on a curve selects, it does not scrub


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
    qtbot.mouseClick(kf.panel.next_key, QtCore.Qt.LeftButton)      # the timeline's buttons do the same
    assert kf.time == 1.25
    qtbot.mouseClick(kf.panel.previous_key, QtCore.Qt.LeftButton)
    qtbot.mouseClick(kf.panel.previous_key, QtCore.Qt.LeftButton)
    assert kf.time == 0.0
    assert w.document.undo_stack.count() == steps     # navigation, not an edit


# --- frame selected / frame all -------------------------------------------------------------------------------------
def _view_extent(w, points) -> float:
    """How much of the view ``points`` fill: their on-screen bounding box's larger side over the view's."""
    d = w.viewport.world_to_display(points)
    wx, wy = w.viewport.plotter.window_size
    return float(max(np.ptp(d[:, 0]) / wx, np.ptp(d[:, 1]) / wy))


def test_f_frames_the_selected_region_and_a_frames_the_whole_model(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.segmentation.wait()
    seg = w.segmentation.segmentation
    labels = seg.levels[w.segmentation.level].core_labels(w.document.rig.n_vertices)
    region = int(np.argmin(np.bincount(labels[labels >= 0])))      # the smallest region
    tree = w.segmentation_panel.regions                               # click the region in the list
    item = next(tree.topLevelItem(i) for i in range(tree.topLevelItemCount())
                if int(tree.topLevelItem(i).data(0, QtCore.Qt.UserRole)) == region)
    tree.scrollToItem(item)
    qtbot.mouseClick(tree.viewport(), QtCore.Qt.LeftButton, pos=tree.visualItemRect(item).center())
    assert w.segmentation_panel.selected_region() == region
    pts = w.document.surface()[labels == region]
    face = w.viewport.focus_points()
    whole = _view_extent(w, face)           # as the window opened: the face framed
    before = _view_extent(w, pts)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_F)
    after = _view_extent(w, pts)
    assert after > 3 * before and 0.35 < after <= 1.0, (before, after)
    centre = w.viewport.world_to_display(pts.mean(axis=0, keepdims=True))[0]
    wx, wy = w.viewport.plotter.window_size
    assert abs(centre[0] - wx / 2) < 0.15 * wx and abs(centre[1] - wy / 2) < 0.15 * wy
    assert "region" in w.statusBar().currentMessage()
    assert _view_extent(w, face) > 1.2
    # A frames the whole model as posed (the sample's head and neck): the face inside, no larger than as opened (the
    # sample opens framed whole: its shapes act across most of it, model.rig_prep.focus_vertices)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_A)
    all_in = _view_extent(w, w.viewport.points())
    assert 0.45 < all_in <= 1.0 and 0.3 < _view_extent(w, face) <= whole + 1e-6 and 0.45 < whole <= 1.0
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_F)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_Home)        # Home frames all too
    assert _view_extent(w, w.viewport.points()) == pytest.approx(all_in, abs=0.01)


def test_f_frames_the_selected_marker_in_marker_mode(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    mk = w.markers
    mk.mode_action.setChecked(True)
    rig = w.document.rig
    v = int(np.argmax(np.abs(rig.deltas[rig.shape_index("jawOpen")]).sum(axis=1)))
    assert mk.add_marker_at(v)
    mk.panel.marker_selected.emit(len(mk.markers) - 1)
    assert mk.selected_marker == len(mk.markers) - 1
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_F)
    p = mk.marker_positions()[-1]
    d = w.viewport.world_to_display(p[None])[0]
    wx, wy = w.viewport.plotter.window_size
    assert abs(d[0] - wx / 2) < 2 and abs(d[1] - wy / 2) < 2          # the marker in the middle of the view
    assert _view_extent(w, w.viewport.focus_points()) > 1.3          # zoomed in past the whole face
    assert "marker" in w.statusBar().currentMessage()


# --- files dropped on the window ------------------------------------------------------------------------------------
def test_a_rig_folder_take_and_marker_map_dropped_together_open(qtbot, tmp_path, ict_dir, take_dir):
    w = make_window(qtbot, tmp_path)
    assert drop_files(w, [take_dir / "marker_map.json", take_dir / "take.c3d", ict_dir])
    qtbot.waitUntil(lambda: not w.is_loading, timeout=60000)
    QtWidgets.QApplication.processEvents()
    assert w.document.rig.n_vertices == 26719
    assert w.mocap.workspace.take_path == take_dir / "take.c3d"
    assert w.mocap.marker_map is not None and len(w.mocap.marker_map.markers) == 60
    assert w.last_error is None



def test_a_take_given_to_open_goes_to_the_mocap_panel(qtbot, tmp_path, ict_dir, take_dir):
    """``open_path`` (``blendshape-studio TAKE``, a recent file) with a take or a marker map loads it in the Mocap
    panel on the open rig, as a drop does; a truncated C3D is refused by the take reader in one sentence saying so,
    and the rig and take stay. It said "unknown rig format '.c3d'" for any take, good or bad."""
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    w.open_path(take_dir / "take.c3d")
    w.open_path(take_dir / "marker_map.json")
    qtbot.waitUntil(lambda: w.mocap.workspace.marker_map is not None, timeout=20000)
    assert w.mocap.workspace.take_path == take_dir / "take.c3d" and w.last_error is None
    cut = tmp_path / "cut.c3d"
    cut.write_bytes((take_dir / "take.c3d").read_bytes()[:3000])
    w.open_path(cut)
    qtbot.waitUntil(lambda: w.last_error is not None, timeout=20000)
    assert str(cut) in w.last_error and "rig format" not in w.last_error and ". " not in w.last_error
    assert w.mocap.workspace.take_path == take_dir / "take.c3d" and w.document.rig.n_vertices == 26719


def test_a_dropped_take_brings_the_mocap_panel_forward(qtbot, tmp_path, llf_csv):
    """A take dropped on the window loaded into the Mocap panel behind the Shapes tab (or into a closed panel):
    nothing on screen changed and the status bar said nothing, so the drop looked ignored."""
    w = make_window(qtbot, tmp_path)
    w.shapes_dock.raise_()
    w.mocap.dock.toggleViewAction().trigger()       # View ▸ Panels ▸ Mocap: closed
    qtbot.waitUntil(lambda: not w.mocap.dock.isVisible())
    assert drop_files(w, [llf_csv])
    QtWidgets.QApplication.processEvents()
    assert w.mocap.workspace.take_path == llf_csv
    assert w.mocap.dock.isVisible() and not w.mocap.dock.visibleRegion().isEmpty()   # shown, its tab in front
    assert w.mocap.panel.take_label.isVisible()
    assert llf_csv.name in w.statusBar().currentMessage()


def test_a_rig_folder_with_its_neutral_alone_is_refused_in_one_sentence(qtbot, tmp_path):
    """An actor's neutral scan dropped on the window (its folder holds no shape OBJ) failed with "could not be opened
    (ValueError: cannot reshape array of size 0 into shape (0,newaxis))". Now: one sentence saying there are no
    blendshapes; the open rig stays."""
    from model.obj_io import write_obj
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    scan = tmp_path / "actor" / "actor_neutral.obj"
    scan.parent.mkdir()
    write_obj(scan, rig.neutral, rig.face_counts, rig.face_indices)
    assert drop_files(w, [scan])
    qtbot.waitUntil(lambda: not w.is_loading, timeout=60000)
    QtWidgets.QApplication.processEvents()
    assert w.last_error == (f"{scan}: has no blendshapes (no OBJ beside its neutral), so there is nothing to "
                            "pose; a rig needs at least one shape besides its neutral.")
    assert w.document.rig is rig


def test_a_dropped_project_gltf_or_take_opens_and_anything_else_is_one_sentence(qtbot, tmp_path, llf_csv):
    from model.project import Project, save_project
    from resources.sample_rig import build_sample_rig
    w = make_window(qtbot, tmp_path)
    rig = build_sample_rig()
    project = tmp_path / "face.bsproj"
    save_project(Project(rig=rig), project)
    assert drop_files(w, [project])
    qtbot.waitUntil(lambda: not w.is_loading, timeout=60000)
    assert w.document.path == project
    note = tmp_path / "notes.txt"
    note.write_text("not a rig")
    assert drop_files(w, [note])
    assert w.last_error.startswith(f"{note}: is not something Blendshape Studio opens")
    assert w.last_error.endswith(".") and ". " not in w.last_error and w.document.path == project   # one sentence
    w.last_error = None
    assert drop_files(w, [llf_csv])                 # a Live Link Face take on the open rig
    assert w.mocap.workspace.take_path == llf_csv
    from model.export import export_rig
    gltf = tmp_path / "face.glb"
    export_rig(rig, gltf)
    assert drop_files(w, [gltf])
    qtbot.waitUntil(lambda: not w.is_loading, timeout=60000)
    QtWidgets.QApplication.processEvents()
    assert w.document.path is None and w.document.rig.n_vertices == rig.n_vertices and w.last_error is None
    assert w.windowTitle().startswith(w.document.rig.name)
    http = QtCore.QMimeData()
    http.setUrls([QtCore.QUrl("https://example.com/face.glb")])
    enter = QtGui.QDragEnterEvent(QtCore.QPoint(5, 5), QtCore.Qt.CopyAction, http, QtCore.Qt.LeftButton,
                                  QtCore.Qt.NoModifier)
    QtWidgets.QApplication.sendEvent(w, enter)
    assert not enter.isAccepted()              # only local files are taken


# --- File ▸ Export Image at a chosen size ---------------------------------------------------------------------------
def _skin_extent(rgb, axis: int) -> float:
    """The fraction of the picture's width (axis 1) or height (axis 0) the face covers (skin: red well above blue)."""
    rgb = np.asarray(rgb, dtype=np.int32)
    idx = np.flatnonzero(((rgb[:, :, 0] - rgb[:, :, 2]) > 30).any(axis=1 - axis))
    return (idx[-1] - idx[0] + 1) / rgb.shape[axis]


def test_export_image_at_a_chosen_size_keeps_the_view(qtbot, tmp_path, monkeypatch):
    """Ctrl+Shift+E asks the size, then writes the view as shown at that size: a narrower picture keeps what is
    seen across (the view angle widens), a wider one keeps what is seen top to bottom."""
    from PIL import Image
    w = make_window(qtbot, tmp_path)
    vw, vh = w.viewport.plotter.window_size
    shown = w.viewport.picture()
    out = tmp_path / "tall"
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName", lambda *a, **k: (str(out), ""))
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_E, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    dialog = w.image_size_dialog
    qtbot.waitUntil(dialog.isVisible, timeout=3000)
    width, height = dialog.findChildren(QtWidgets.QSpinBox)
    assert (width.value(), height.value()) == (vw, vh)
    size = (vw, 2 * vh)                         # narrower than the view
    for box, value in zip((width, height), size):
        _focus(qtbot, box)
        qtbot.keyClick(box.lineEdit(), QtCore.Qt.Key_A, QtCore.Qt.ControlModifier)
        qtbot.keyClicks(box.lineEdit(), str(value))
    qtbot.keyClick(height.lineEdit(), QtCore.Qt.Key_Return)
    w.jobs.wait()                               # the PNG is written in the background
    img = np.asarray(Image.open(tmp_path / "tall.png").convert("RGB"))
    assert img.shape[:2] == (size[1], size[0])
    assert _skin_extent(img, 1) == pytest.approx(_skin_extent(shown, 1), abs=0.03)   # the same view across
    assert _skin_extent(img, 0) < 0.7 * _skin_extent(shown, 0)
    assert f"{size[0]}x{size[1]}" in w.statusBar().currentMessage()
    assert w.viewport.plotter.camera.view_angle == 30.0                             # the view itself unchanged
    # wider than the view: the same view top to bottom
    assert w.save_image(tmp_path / "wide.png", (3 * vw, vh))
    w.jobs.wait()
    img = np.asarray(Image.open(tmp_path / "wide.png").convert("RGB"))
    assert img.shape[:2] == (vh, 3 * vw)
    assert _skin_extent(img, 0) == pytest.approx(_skin_extent(shown, 0), abs=0.03)
    # the size is remembered for the next export
    w.save_image_dialog()
    assert [b.value() for b in w.image_size_dialog.findChildren(QtWidgets.QSpinBox)] == list(size)
    w.image_size_dialog.reject()


# --- first start ----------------------------------------------------------------------------------------------------
def test_first_start_fills_the_screen_frames_the_face_and_never_restores_empty_mocap_views(qtbot, tmp_path, ict_dir):
    from app.main_window import MainWindow
    from tests.gui_helpers import isolate_settings
    isolate_settings(tmp_path)
    w = MainWindow()
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    qtbot.waitExposed(w)
    screen = w.screen().availableGeometry()
    assert w.isMaximized() or (w.width() >= 0.95 * screen.width() and w.height() >= 0.95 * screen.height())
    area = w.viewport.width() * w.viewport.height()
    assert area > 0.45 * w.width() * w.height()
    docks = [d for d in w.findChildren(QtWidgets.QDockWidget) if d.isVisible()]
    assert all(d.width() * d.height() < area for d in docks)
    assert not w.mocap.views_dock.isVisible()
    open_and_wait(qtbot, w, ict_dir)
    qtbot.wait(200)
    face = w.viewport.focus_points()
    assert len(face) < 0.6 * w.document.rig.n_vertices          # where the shapes act, not the whole head
    assert _view_extent(w, face) > 0.8                           # the face fills the view
    assert _view_extent(w, w.document.rig.neutral) > 1.1          # head and shoulders go past its edges
    # a layout saved with the Mocap Views dock open does not bring it back empty
    w.mocap.views_dock.show()
    w.close()
    w2 = MainWindow()
    w2.confirm_discard = False
    qtbot.addWidget(w2)
    w2.show()
    qtbot.waitExposed(w2)
    assert not w2.mocap.views_dock.isVisible()
    w2.open_sample()
    assert not w2.mocap.views_dock.isVisible()


# --- Marker mode's button, status messages in the user's words ------------------------------------------------------
def _mean_colour(widget) -> np.ndarray:
    img = widget.grab().toImage().convertToFormat(QtGui.QImage.Format_RGB888)
    a = np.frombuffer(img.constBits(), dtype=np.uint8, count=img.sizeInBytes())
    a = a.reshape(img.height(), img.bytesPerLine())[:, :img.width() * 3].reshape(img.height(), img.width(), 3)
    return a.reshape(-1, 3).mean(axis=0)


def test_marker_mode_button_shows_when_it_is_on(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    button = w.marker_mode_button
    assert button.isVisible() and not button.isChecked() and not w.markers.mode
    off = _mean_colour(button)
    qtbot.mouseClick(button, QtCore.Qt.LeftButton)
    assert w.markers.mode and button.isChecked() and "On" in button.text()
    on = _mean_colour(button)
    assert on[0] - on[2] > 60 and on[0] - on[2] > off[0] - off[2] + 50      # orange while on
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_M)                       # M turns it off: the button follows
    assert not w.markers.mode and not button.isChecked() and "On" not in button.text()
    assert np.abs(_mean_colour(button) - off).max() < 8


def test_added_marker_is_described_in_the_users_words(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    mk = w.markers
    mk.mode_action.setChecked(True)
    rig = w.document.rig
    jaw = rig.shape_index("jawOpen")
    v = int(np.argmax(np.linalg.norm(rig.deltas[jaw], axis=1)))
    # a click on the face where jawOpen acts most (through the viewport's pick, as a click does)
    d = w.viewport.world_to_display(w.document.surface()[v][None])[0]
    pos = w.viewport.display_to_qt(d[0], d[1]).toPoint()
    qtbot.mouseClick(w.viewport.canvas, QtCore.Qt.LeftButton, pos=pos)
    QtWidgets.QApplication.processEvents()
    assert len(mk.markers) == 1
    text = w.statusBar().currentMessage()
    assert text.startswith(f"Added marker {mk.markers.names[0]} on the face")
    assert "triangle" not in text and "vertex" not in text
    assert "moved most by" in text


def test_help_lists_the_new_keys(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_F1)
    table = w.shortcuts_dialog.findChild(QtWidgets.QTreeWidget)
    rows = {(table.topLevelItem(i).text(1), table.topLevelItem(i).text(0)) for i in range(table.topLevelItemCount())}
    for name, keys in (("Frame Selected", "F"), ("Frame All", "A"), ("Frame All (in the viewport)", "Home"),
                       ("Next Key", "."),
                       ("Previous Key", ","), ("Graph Editor", "Ctrl+G"), ("Set Key", "S"),
                       ("Export Image…", "Ctrl+Shift+E"), ("Delete the Selected Key (Graph Editor)", "Del")):
        assert (name, keys) in rows, name
    shortcuts = [k for _n, k in rows]
    singles = [k for ks in shortcuts for k in ks.split(", ")]
    assert len([k for k in singles if k == "F"]) == 1                   # F is Frame Selected alone


def test_region_legend_is_white_text_at_a_readable_size_in_the_corner(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path, size=(1920, 1200))        # the window as it opens (the screen's size)
    w.segmentation.wait()
    combo = w.segmentation_panel.view
    _key(qtbot, combo, QtCore.Qt.Key_End)                       # the Segmentation view
    assert combo.currentData() == "segmentation"
    legend = w.viewport.plotter.legend
    n = legend.GetNumberOfEntries()
    assert n >= 3
    colours = {tuple(np.round(legend.GetEntryColor(i), 3)) for i in range(n)}
    assert colours == {(1.0, 1.0, 1.0)}                          # the text: white on the dark box
    swatches = [legend.GetEntrySymbol(i).GetCellData().GetArray("rgb").GetTuple(0) for i in range(n)]
    assert len(set(swatches)) >= n - 1                            # the region colours are on the swatches
    vw, vh = w.viewport.plotter.window_size
    x, y = legend.GetPosition()
    lw, lh = legend.GetPosition2()
    # rows of 18-30 px (widgets.scene.overlay_layout: min(w, h) / 46), as wide as the labels need: at least 220 px
    assert vw > 846 and lw * vw >= 220 and 18 <= lh * vh / n <= 30
    assert (x + lw) * vw < 0.5 * vw and y * vh > 0.5 * vh         # in the upper left, clear of the lower-right title


def test_take_actions_without_a_take_to_play_say_why(qtbot, tmp_path, take_dir):
    """Play / Pause Take (Ctrl+Space), Previous / Next Take Frame (Alt+, / Alt+.) and Use Take Frame as Neutral
    (Alt+N) did nothing, silently, with no take or an unsolved marker take: each now says why in the status bar."""
    w = make_window(qtbot, tmp_path)
    for key in (QtCore.Qt.Key_Space, QtCore.Qt.Key_Period):
        w.statusBar().clearMessage()
        _key(qtbot, w.viewport.canvas, key, QtCore.Qt.ControlModifier if key == QtCore.Qt.Key_Space
             else QtCore.Qt.AltModifier)
        assert w.statusBar().currentMessage() == "There is no take to play: load one in the Mocap panel."
    assert w.mocap.load_take(take_dir / "take.c3d") and w.mocap.n_frames == 0
    for key, modifier in ((QtCore.Qt.Key_Comma, QtCore.Qt.AltModifier), (QtCore.Qt.Key_N, QtCore.Qt.AltModifier)):
        w.statusBar().clearMessage()
        _key(qtbot, w.viewport.canvas, key, modifier)
        assert w.statusBar().currentMessage().startswith("Solve the take first"), key
    assert not w.mocap.playback.playing and w.document.undo_stack.count() == 0


def test_export_and_open_dialogs_start_where_the_last_such_file_went_not_in_the_working_folder(
        qtbot, tmp_path, monkeypatch, take_dir):
    """Export Pose, Export Image, the keys' and take's exports and Load Take gave their file dialogs a bare name:
    they opened in the folder the program was started from, every time, and the folder chosen last was forgotten
    (Export Rig alone remembered its own). Now an export starts in the folder the last export went to -- in a later
    session too -- and Load Take in the folder the last take came from."""
    started_in = tmp_path / "started_here"
    started_in.mkdir()
    monkeypatch.chdir(started_in)
    out = tmp_path / "renders"
    out.mkdir()
    starts = []

    def save_dialog(parent, title, start, *a, **k):
        starts.append(Path(start))
        return str(out / Path(start).name), ""
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName", staticmethod(save_dialog))
    w = make_window(qtbot, tmp_path)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_E, QtCore.Qt.ControlModifier)        # Export Pose as OBJ
    assert starts[0].is_absolute() and starts[0].parent != started_in and starts[0].suffix == ".obj"
    qtbot.waitUntil(lambda: (out / starts[0].name).exists(), timeout=20000)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_E, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    w.image_size_dialog.accept()                                                      # Export Image: the size
    assert starts[1].parent == out and starts[1].suffix == ".png"
    w.close()
    w2 = make_window(qtbot, tmp_path)                                                 # the next session
    _key(qtbot, w2.viewport.canvas, QtCore.Qt.Key_E, QtCore.Qt.ControlModifier)
    assert starts[2].parent == out
    opened = []

    def open_dialog(parent, title, start, *a, **k):
        opened.append(Path(start))
        return str(take_dir / "take.c3d"), ""
    monkeypatch.setattr(QtWidgets.QFileDialog, "getOpenFileName", staticmethod(open_dialog))
    w2.mocap.dock.show()
    w2.mocap.dock.raise_()
    for _ in range(2):
        qtbot.mouseClick(w2.mocap.panel.load_take_button, QtCore.Qt.LeftButton)
    assert opened[0] != started_in and opened[1] == take_dir
    assert w2.mocap.workspace.take_path == take_dir / "take.c3d"


# --- undoing a key ----------------------------------------------------------------------------------------------------
def test_undoing_a_key_shows_what_the_animation_gives_without_it(qtbot, tmp_path):
    """Set Key at 1 s between keys at 0 s and 2 s, then Ctrl+Z: the face showed the removed key's pose, which the
    animation no longer gives anywhere; now it shows the animation's pose at 1 s (as Maya and Blender re-evaluate),
    and Ctrl+Shift+Z the key's again. Remove key and its undo follow the animation the same way."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    kf, doc = w.keyframes, w.document
    ruler, canvas = kf.panel.ruler, w.viewport.canvas

    def scrub_to(t):
        qtbot.mouseClick(ruler, QtCore.Qt.LeftButton, pos=QtCore.QPoint(round(ruler.x_of(t)), ruler.height() // 2))
        QtWidgets.QApplication.processEvents()
        assert kf.time == pytest.approx(t, abs=0.03)

    _key(qtbot, canvas, QtCore.Qt.Key_S)                      # the neutral at 0 s
    scrub_to(2.0)
    _pose(w, jawOpen=1.0)
    _key(qtbot, canvas, QtCore.Qt.Key_S)                      # the jaw open at 2 s
    scrub_to(1.0)
    between = kf.timeline.evaluate(kf.time)
    assert np.allclose(doc.weights, between) and 0.2 < between[doc.rig.shape_index("jawOpen")] < 0.8
    keyed = _pose(w, mouthSmile_L=0.9)
    qtbot.mouseClick(kf.panel.set_key, QtCore.Qt.LeftButton)  # Set key at 1 s: the face keeps the pose it keys
    assert len(kf.timeline.keys) == 3 and np.allclose(doc.weights, keyed)
    _key(qtbot, canvas, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)
    assert len(kf.timeline.keys) == 2
    assert np.allclose(doc.weights, kf.timeline.evaluate(kf.time)) and np.allclose(doc.weights, between)
    _key(qtbot, canvas, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    assert len(kf.timeline.keys) == 3 and np.allclose(doc.weights, keyed)
    # Remove key at 1 s: the animation's pose without it; undone, the key's
    qtbot.mouseClick(kf.panel.remove_key, QtCore.Qt.LeftButton)
    assert len(kf.timeline.keys) == 2 and np.allclose(doc.weights, between)
    _key(qtbot, canvas, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)
    assert len(kf.timeline.keys) == 3 and np.allclose(doc.weights, keyed)
    # the viewport shows the document's pose
    _key(qtbot, canvas, QtCore.Qt.Key_Z, QtCore.Qt.ControlModifier)   # the key set: the animation without it
    w.redraw_now()
    assert np.allclose(doc.weights, between)
    assert np.allclose(w.viewport.points(), doc.surface(), atol=1e-5)
