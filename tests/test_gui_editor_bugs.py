"""Issue 18's "Bugs seen", each driven with real input events (keyboard and mouse through qtbot) or, where a real
event is impractical (file dialogs), through the public method the dialog calls: each test failed before its fix."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from tests.gui_helpers import make_window, open_and_wait
from tests.test_gui_editor_habits import _focus

pytestmark = pytest.mark.gui


def _key(qtbot, widget, key, modifier=QtCore.Qt.NoModifier):
    _focus(qtbot, widget)
    qtbot.keyClick(widget, key, modifier)
    QtWidgets.QApplication.processEvents()


def _overlays(w) -> set[str]:
    """What the viewport draws over the surface besides the colour map: its region legend and legend title."""
    p = w.viewport.plotter
    return ({"legend"} if p.legend is not None else set()) | ({"legend_title"} & set(p.actors))


# --- stale overlays -------------------------------------------------------------------------------------------------
def test_shaded_view_drops_the_region_legend_and_level_text(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.segmentation.wait()
    combo = w.segmentation_panel.view
    _key(qtbot, combo, QtCore.Qt.Key_End)              # the last view: Segmentation
    assert combo.currentData() == "segmentation"
    assert _overlays(w) == {"legend", "legend_title"}
    _key(qtbot, combo, QtCore.Qt.Key_Home)             # back to Shaded
    assert combo.currentData() == "shaded"
    assert w.viewport.colormap is None
    assert _overlays(w) == set()


def test_status_line_says_the_level_shown_with_plurals(qtbot, tmp_path):
    from model.correctives import Corrective
    from model.project import Project
    from resources.sample_rig import build_sample_rig
    w = make_window(qtbot, tmp_path)
    w.segmentation.wait()
    seg = w.segmentation.segmentation
    assert len(seg.levels) >= 3 and seg.levels[-1].n_regions == 1
    slider, status = w.segmentation_panel.level, w.segmentation_panel.status
    _key(qtbot, slider, QtCore.Qt.Key_Right)
    assert slider.value() == 1
    assert status.text().startswith(f"{seg.levels[1].n_regions} regions at level 1 ·"), status.text()
    _key(qtbot, slider, QtCore.Qt.Key_End)
    top = len(seg.levels) - 1
    assert status.text().startswith(f"1 region at level {top} ·"), status.text()
    assert w.segmentation_panel.level_label.text() == f"{top} of {top}: 1 region"
    assert "1 regions" not in w.viewport.colormap.title if w.viewport.colormap else True
    # the window's counts: one corrective is "1 corrective"
    rig = build_sample_rig()
    rig.correctives.append(Corrective(drivers=rig.shape_names[:2], delta=np.zeros_like(rig.neutral)))
    w.document.set_project(Project(rig=rig), None)
    assert "· 1 corrective ·" in w.counts_label.text(), w.counts_label.text()


def test_a_live_link_take_clears_the_previous_solves_views(qtbot, tmp_path, ict_dir, take_dir, llf_csv):
    """Load Take's file dialog is not driven: the test calls ``load_take``, which the dialog calls."""
    w = make_window(qtbot, tmp_path, size=(1400, 1000))
    mc = w.mocap
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=180000):
        qtbot.mouseClick(mc.panel.solve_button, QtCore.Qt.LeftButton)
    assert mc.views_dock.isVisible() and mc.views.has_residual_bar()
    assert {"surface_left", "markers", "errors"} <= set(mc.views.plotter.renderers[0].actors)
    assert mc.load_take(llf_csv)
    QtWidgets.QApplication.processEvents()
    assert not mc.views.has_residual_bar()
    left, right = (set(r.actors) for r in mc.views.plotter.renderers)
    assert not ({"surface_left", "markers", "errors"} & left) and "surface_right" not in right


# --- keyed playback -------------------------------------------------------------------------------------------------
def test_keyed_playback_keeps_real_time_when_drawing_is_slow(qtbot, tmp_path):
    """Space plays the keyed animation; with every frame's drawing taking 100 ms (as ICT under software OpenGL),
    the animation follows the clock by dropping frames instead of running in slow motion."""
    import time
    w = make_window(qtbot, tmp_path)
    kf = w.keyframes
    kf.set_key(0.0)
    jaw = w.document.rig.shape_index("jawOpen")
    pose = np.zeros(w.document.rig.n_shapes)
    pose[jaw] = 1.0
    w.set_pose(pose, "jaw")
    kf.set_key(2.0)
    kf.scrub(0.0)
    assert kf.duration == 2.0 and kf.fps == 24.0
    w.document.pose_changed.connect(lambda: time.sleep(0.1))   # a slow draw of every frame shown
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_Space)
    assert kf.playing and w.keyframes.panel.play.isChecked()
    t0 = time.perf_counter()
    qtbot.wait(1200)
    elapsed = time.perf_counter() - t0
    assert abs(kf.time - elapsed) < 0.3, (kf.time, elapsed)
    assert w.document.weights[jaw] == pytest.approx(kf.timeline.evaluate(kf.time)[jaw], abs=1e-6)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_Space)
    assert not kf.playing and not w.keyframes.panel.play.isChecked()


# --- marker keys keep the level the user solves at ------------------------------------------------------------------
def _regional_pose(w, level, seed):
    from app.document import PoseState
    lvl = w.segmentation.segmentation.levels[level]
    rng = np.random.default_rng(seed)
    W = rng.uniform(0, 1, (lvl.blend.shape[1], w.document.rig.n_shapes))
    return PoseState(np.zeros(w.document.rig.n_shapes), W, lvl.blend, level)


def test_a_key_at_a_finer_level_is_kept_not_averaged_onto_the_first_keys_level(qtbot, tmp_path):
    """S keys the pose (a real key press); the regional poses are set through ``Document.set_pose_state``, as a
    marker drag at that level leaves them."""
    w = make_window(qtbot, tmp_path)
    w.segmentation.wait()
    doc, kf = w.document, w.keyframes
    coarse, fine = _regional_pose(w, 2, 1), _regional_pose(w, 0, 2)
    doc.set_pose_state(coarse)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S)
    kf.scrub(1.0)
    doc.set_pose_state(fine)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S)
    assert [k.time for k in kf.timeline.keys] == [0.0, 1.0]
    assert kf.level == 0
    size = np.ptp(doc.rig.neutral, axis=0).max()

    def error(t, state):
        return np.abs(doc.evaluate_state(kf.pose_at(t)) - doc.evaluate_state(state)).max() / size
    assert error(1.0, fine) < 1e-6          # the key just set is the pose the user made
    assert error(0.0, coarse) < 0.02        # the earlier key moved to the finer level keeps its surface


# --- the keyed weights CSV ------------------------------------------------------------------------------------------
def _save_dialog_answers(monkeypatch, path):
    """The file dialog answers ``path`` (a native dialog cannot be driven by events)."""
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName", staticmethod(lambda *a, **k: (str(path), "")))


def _menu_action(w, text):
    return next(a for a in w.actions() if a.text().replace("&", "") == text)


def test_keyed_weights_csv_has_one_column_per_shape_fitting_each_frame(qtbot, tmp_path, monkeypatch):
    """File ▸ Export Keyed Weights as CSV… of a marker-keyed (regional) animation writes the global rig's weights,
    one column per shape, that reproduce each frame's surface best; ... per Region … keeps the per-region CSV.
    The menu actions are triggered (their menus are not opened with the mouse) and run in the background."""
    from model.weights_csv import read_weights_csv
    w = make_window(qtbot, tmp_path)
    w.segmentation.wait()
    doc, kf = w.document, w.keyframes
    rig = doc.rig
    lvl = w.segmentation.segmentation.levels[0]
    rng = np.random.default_rng(3)
    # a regional pose close to a global one (each region a little off): its best global fit is near that one
    base = rng.uniform(0.1, 0.6, rig.n_shapes)
    from app.document import PoseState
    W = np.clip(base + rng.normal(0, 0.05, (lvl.blend.shape[1], rig.n_shapes)), 0, 1)
    doc.set_pose_state(PoseState(np.zeros(rig.n_shapes), W, lvl.blend, 0))
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S)
    out = tmp_path / "keys.csv"
    _save_dialog_answers(monkeypatch, out)
    _menu_action(w, "Export Keyed Weights as CSV…").trigger()
    qtbot.waitUntil(out.exists, timeout=60000)     # written in the background (atomically)
    frames, times, names, G = read_weights_csv(out)
    assert names == rig.shape_names and G.shape == (len(kf.frame_times()), rig.n_shapes)
    target = doc.evaluate_state(PoseState(np.zeros(rig.n_shapes), W, lvl.blend, 0), dtype=np.float64)
    fit = doc.evaluate_state(PoseState(G[0]), dtype=np.float64)
    mean = doc.evaluate_state(PoseState(W.mean(axis=0)), dtype=np.float64)
    # the fitted global weights reproduce the surface better than the obvious average of the regions' rows
    assert np.linalg.norm(fit - target) < 0.8 * np.linalg.norm(mean - target)
    assert np.all((G >= 0) & (G <= 1))
    per_region = tmp_path / "regions.csv"
    _save_dialog_answers(monkeypatch, per_region)
    _menu_action(w, "Export Keyed Weights per Region as CSV…").trigger()
    qtbot.waitUntil(per_region.exists, timeout=60000)
    _, _, names_r, Wr = read_weights_csv(per_region)
    assert len(names_r) == lvl.blend.shape[1] * rig.n_shapes and "jawOpen@region0" in names_r
    np.testing.assert_allclose(Wr[0], W.reshape(-1))


# --- freezes: control comes back at once, the work finishes in the background ---------------------------------------
def _returns_fast(fn, limit=0.2) -> float:
    import time
    t0 = time.perf_counter()
    fn()
    took = time.perf_counter() - t0
    assert took < limit, f"blocked the window {took:.2f} s"
    return took


def test_keyed_pc2_and_pose_obj_exports_return_at_once_on_ict(qtbot, tmp_path, monkeypatch, ict_dir):
    """File ▸ Export Keyed Animation as PC2… (triggered; 8.3 s on ICT before) and Ctrl+E, Export Pose as OBJ
    (a real key press; 1.6 s before): control comes back within 0.2 s, a busy bar says what runs, the files
    arrive complete."""
    from model.obj_io import read_obj
    from model.pc2 import read_pc2
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    rig, kf = w.document.rig, w.keyframes
    kf.set_key(0.0)
    pose = np.zeros(rig.n_shapes)
    pose[rig.shape_index("jawOpen")] = 0.8
    w.set_pose(pose, "jaw")
    kf.set_key(2.0)
    pc2 = tmp_path / "keys.pc2"
    _save_dialog_answers(monkeypatch, pc2)
    _returns_fast(_menu_action(w, "Export Keyed Animation as PC2…").trigger)
    assert w.jobs_bar.isVisible() and "PC2" in w.jobs_bar.format()
    obj = tmp_path / "pose.obj"
    _save_dialog_answers(monkeypatch, obj)
    _focus(qtbot, w.viewport.canvas)
    _returns_fast(lambda: qtbot.keyClick(w.viewport.canvas, QtCore.Qt.Key_E, QtCore.Qt.ControlModifier))
    qtbot.waitUntil(lambda: pc2.exists() and obj.exists() and not w.jobs_bar.isVisible(), timeout=120000)
    cache, _, _ = read_pc2(pc2)
    assert cache.shape == (49, rig.n_vertices, 3)
    np.testing.assert_allclose(cache[-1], w.document.evaluate_state(kf.pose_at(2.0), dtype=np.float64), atol=1e-5)
    assert np.allclose(read_obj(obj).vertices, w.document.surface(), atol=1e-4)
    # what `export` writes for the same pose (model.export.write_surface_obj): the rig's UVs, usemtl records and
    # material library (pose.mtl beside it), line for line but for the header
    from model.export import export_rig
    (tmp_path / "cli").mkdir()
    export_rig(rig, tmp_path / "cli" / "pose.obj", pose)
    body = lambda p: [l for l in p.read_text().splitlines() if not l.startswith("#")]
    same_obj = body(obj) == body(tmp_path / "cli" / "pose.obj")      # (a bool: pytest would diff 80k lines)
    assert same_obj, "the window's pose OBJ differs from the export command's"
    assert body(tmp_path / "pose.mtl") == body(tmp_path / "cli" / "pose.mtl")
    assert sum(l.startswith("usemtl ") for l in body(obj)) == 12 and read_obj(obj).corners.uvs is not None


def _select_region_in_viewport(qtbot, w, region):
    """Shows the Segmentation view (keyboard) and picks ``region`` (the pick a click on it emits)."""
    _key(qtbot, w.segmentation_panel.view, QtCore.Qt.Key_End)
    lvl = w.segmentation.segmentation.levels[w.segmentation.level]
    v = int(lvl.regions[region].core[0])
    w.viewport.picked.emit(v, w.document.rig.neutral[v])
    assert w.segmentation.highlight == region


def test_nudge_falls_off_smoothly_over_the_overlap_rings(qtbot, tmp_path):
    """Ctrl+Shift+= nudges the selected region out: the core moves by the step, each overlap ring less than the
    one inside it (a smooth falloff, not a block with a cliff at its edge)."""
    from solvers.laplacian import mesh_adjacency
    w = make_window(qtbot, tmp_path)
    w.segmentation.wait()
    _key(qtbot, w.segmentation_panel.overlap, QtCore.Qt.Key_Up)     # 2 overlap rings
    qtbot.waitUntil(lambda: w.segmentation.settings()["overlap_rings"] == 2 and not w.segmentation.runner.busy)
    w.segmentation.wait()
    lvl = w.segmentation.segmentation.levels[0]
    rig = w.document.rig
    A = mesh_adjacency(rig.n_vertices, rig.face_counts, rig.face_indices)
    labels = lvl.core_labels()

    def bordering(r):   # core vertices next to another region's core: where the partition of unity dips
        core = lvl.regions[r].core
        nb = labels[A[core].indices]
        return int(((nb >= 0) & (nb != r)).sum())
    region = max(range(lvl.n_regions), key=bordering)
    assert bordering(region) > 0
    _select_region_in_viewport(qtbot, w, region)
    before = w.document.surface().copy()
    step = w.segmentation_panel.nudge_amount.value()
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_Equal, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    moved = np.linalg.norm(w.document.surface() - before, axis=1)
    reg = lvl.regions[region]
    ring1 = np.setdiff1d(np.unique(A[reg.core].indices), reg.core)
    ring2 = np.setdiff1d(np.unique(A[ring1].indices), np.union1d(reg.core, ring1))
    ring1, ring2 = np.intersect1d(ring1, reg.vertices), np.intersect1d(ring2, reg.vertices)
    assert ring1.size and ring2.size
    # the whole core moves by the step (the region, not a block whose edge sags where a neighbour overlaps it)
    np.testing.assert_allclose(moved[reg.core], step, rtol=1e-3)
    # each ring moves by one amount (no stair steps along the edge), less than the ring inside it
    assert np.ptp(moved[ring1]) < 1e-3 * step and np.ptp(moved[ring2]) < 1e-3 * step
    assert step > moved[ring1].max() and moved[ring1].min() > moved[ring2].max() > 0
    assert moved[ring2].max() < 0.35 * step


def test_save_as_new_shape_names_it_sets_it_to_1_keeps_regions_and_returns_at_once(qtbot, tmp_path, monkeypatch):
    """The Save as new shape… button (a real click): the suggested name is the region and its direction, the
    shape comes in at 1 (the face stays as nudged), the regions and the selected region stay."""
    suggested = []

    def answer(parent, title, label, text=""):
        suggested.append(text)
        return text, True
    monkeypatch.setattr(QtWidgets.QInputDialog, "getText", staticmethod(answer))
    w = make_window(qtbot, tmp_path)
    w.segmentation.wait()
    seg = w.segmentation.segmentation
    lvl = seg.levels[0]
    region = max(range(lvl.n_regions), key=lambda r: lvl.regions[r].core.size)
    _select_region_in_viewport(qtbot, w, region)
    qtbot.mouseClick(w.segmentation_panel.nudge_buttons["up"], QtCore.Qt.LeftButton)
    nudged = w.document.surface().copy()
    n = w.document.rig.n_shapes
    _returns_fast(lambda: qtbot.mouseClick(w.segmentation_panel.save_shape, QtCore.Qt.LeftButton))
    qtbot.waitUntil(lambda: w.document.rig.n_shapes == n + 1, timeout=30000)
    name = f"region{region}_up"
    assert suggested == [name] and w.document.rig.shape_names[-1] == name
    assert w.document.weights[-1] == 1.0 and w.shapes_panel.row(name).box.value() == 1.0
    np.testing.assert_allclose(w.document.surface(), nudged, atol=1e-5)
    QtWidgets.QApplication.processEvents()
    assert w.segmentation.segmentation is seg and w.segmentation.highlight == region
    assert w.segmentation_panel.selected_region() == region
    # a second nudge of the same region and direction gets its own name
    qtbot.mouseClick(w.segmentation_panel.nudge_buttons["up"], QtCore.Qt.LeftButton)
    assert w.segmentation.nudge_shape_name() == f"{name}_2"


# --- saved projects bring back the view, the take and the marker map; Save As starts beside, not inside -------------
def test_a_saved_project_brings_back_view_level_take_and_map(qtbot, tmp_path, monkeypatch, ict_dir, take_dir):
    """Ctrl+S saves (the dialog answers the path); reopening the project restores the Segmentation view at its
    level, the take and the marker map. The take is loaded with ``load_take``/``load_map`` (what their dialogs call)."""
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    w.segmentation.wait()
    mc = w.mocap
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    _key(qtbot, w.segmentation_panel.view, QtCore.Qt.Key_End)
    _key(qtbot, w.segmentation_panel.level, QtCore.Qt.Key_Right)
    assert w.segmentation.view == "segmentation" and w.segmentation.level == 1
    project = tmp_path / "projects" / "face.bsproj"
    project.parent.mkdir()
    _save_dialog_answers(monkeypatch, project)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S, QtCore.Qt.ControlModifier)
    assert project.exists()
    w.open_sample()                                          # something else, in Shaded view at level 0
    _key(qtbot, w.segmentation_panel.view, QtCore.Qt.Key_Home)
    w.segmentation.wait()
    _key(qtbot, w.segmentation_panel.level, QtCore.Qt.Key_Home)
    assert w.segmentation.view == "shaded" and w.segmentation.level == 0
    open_and_wait(qtbot, w, project)
    w.segmentation.wait()
    QtWidgets.QApplication.processEvents()
    assert w.segmentation_panel.view.currentData() == "segmentation" and w.segmentation.view == "segmentation"
    assert w.segmentation.level == 1 and w.segmentation_panel.level.value() == 1
    assert w.viewport.colormap is not None and w.viewport.colormap.title.startswith("level 1 of")
    assert mc.workspace.take_path == take_dir / "take.c3d" and mc.take.n_frames == 358
    assert mc.marker_map is not None and len(mc.marker_map.labels) == 60
    assert "60 markers" in mc.panel.map_label.text()


def test_save_as_starts_beside_the_rig_folder_then_in_the_projects_folder(qtbot, tmp_path, monkeypatch, ict_dir):
    """Ctrl+O and Ctrl+Shift+S with real keys; the native dialogs answer through monkeypatched QFileDialog calls,
    which record the folder each one starts in."""
    w = make_window(qtbot, tmp_path)
    monkeypatch.setattr(QtWidgets.QFileDialog, "getExistingDirectory", staticmethod(lambda *a, **k: str(ict_dir)))
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_O, QtCore.Qt.ControlModifier)
    qtbot.waitUntil(lambda: not w.is_loading and w.document.rig.n_vertices == 26719, timeout=60000)
    starts = []
    project = tmp_path / "projects" / "face.bsproj"
    project.parent.mkdir()

    def save_dialog(parent, title, start, *a, **k):
        starts.append(Path(start))
        return str(project), ""
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName", staticmethod(save_dialog))
    shift_s = QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S, shift_s)
    assert project.exists()
    assert starts[0].parent != ict_dir and starts[0].parent == ict_dir.parent and starts[0].suffix == ".bsproj"
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S, shift_s)
    assert starts[1] == project                              # the project's own folder and name
    w.open_sample()
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_S, shift_s)
    assert starts[2].parent == project.parent                # the last folder a project went to


# --- the Mocap panel ------------------------------------------------------------------------------------------------
def test_mocap_panel_counts_the_takes_frames_says_the_next_step_and_keeps_solve_still(qtbot, tmp_path, ict_dir,
                                                                                       take_dir):
    """The take and map are loaded with ``load_take``/``load_map`` (what their file dialogs call); Solve is clicked."""
    w = make_window(qtbot, tmp_path, size=(1400, 1000))
    mc = w.mocap
    open_and_wait(qtbot, w, ict_dir)
    mc.dock.show()
    mc.dock.raise_()
    QtWidgets.QApplication.processEvents()
    button = mc.panel.solve_button

    def where():
        return button.mapTo(mc.panel, QtCore.QPoint(0, 0))
    before = where()
    assert mc.load_take(take_dir / "take.c3d")
    QtWidgets.QApplication.processEvents()
    assert where() == before                       # the take's description did not push Solve down
    assert "marker map" in mc.panel.status_label.text()
    assert mc.load_map(take_dir / "marker_map.json")
    QtWidgets.QApplication.processEvents()
    assert where() == before
    assert "Load or build" not in mc.panel.status_label.text() and "Solve" in mc.panel.status_label.text()
    labels = []

    def label_now(*_):       # after the controller's own slot has set the dialog's text for this progress step
        if mc._progress is not None:
            labels.append(mc._progress.labelText())
    mc._relay.progress.connect(label_now)     # every step seen (a timer sampling the text missed them under load)
    with qtbot.waitSignal(mc.solved, timeout=180000):
        qtbot.mouseClick(button, QtCore.Qt.LeftButton)
    mc._relay.progress.disconnect(label_now)
    frames = [t for t in labels if "frame" in t]
    assert frames and all("/358" in t for t in frames), labels[-3:]
    assert not any("/716" in t for t in labels)


# --- marker mode and sculpting ----------------------------------------------------------------------------------------
def test_sculpting_turns_marker_mode_off_and_m_stops_sculpting(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_M)
    assert w.markers.mode and w.viewport.has_tool(w.markers.tool)
    pose = np.zeros(rig.n_shapes)
    pose[[rig.shape_index("browInnerUp_L"), rig.shape_index("browInnerUp_R")]] = 1.0
    w.set_pose(pose, "brows")
    w.correctives.dock.show()
    w.correctives.dock.raise_()
    QtWidgets.QApplication.processEvents()
    qtbot.mouseClick(w.correctives.panel.new_button, QtCore.Qt.LeftButton)
    assert w.correctives.sculpting
    assert not w.markers.mode and not w.markers.mode_action.isChecked()
    assert not w.viewport.has_tool(w.markers.tool)
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_M)       # back to markers: sculpting stops
    assert w.markers.mode and not w.correctives.sculpting


# --- the Correctives panel fits its dock ----------------------------------------------------------------------------
def _fully_visible(widget) -> bool:
    return widget.isVisible() and widget.visibleRegion().boundingRect() == widget.rect()


def test_correctives_panel_fits_its_dock_on_ict(qtbot, tmp_path, ict_dir):
    """At the default 1400x900 on ICT: New corrective (a click) shows Save corrective without scrolling, the
    table's columns fit (no horizontal scroll bar, every header label whole), and after a sculpt stroke (real
    mouse events on the face) and a click on Save corrective the new row is in view."""
    from tests.gui_helpers import mouse
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    c, panel = w.correctives, w.correctives.panel
    for pair in (("browInnerUp_L", "browInnerUp_R"), ("mouthSmile_L", "eyeBlink_L"), ("jawOpen", "mouthFunnel"),
                 ("cheekPuff_L", "cheekPuff_R"), ("mouthSmile_R", "eyeBlink_R")):
        panel.set_ticked(pair)
        qtbot.mouseClick(panel.new_button, QtCore.Qt.LeftButton)
        assert c.sculpting
        QtWidgets.QApplication.processEvents()
        qtbot.wait(50)
        assert _fully_visible(panel.save_button)
        canvas = w.viewport.canvas
        centre = QtCore.QPoint(canvas.width() // 2, canvas.height() // 2)
        mouse(canvas, "press", centre)
        for k in range(1, 6):
            mouse(canvas, "move", centre + QtCore.QPoint(0, -6 * k))
        mouse(canvas, "release", centre + QtCore.QPoint(0, -30))
        assert w.document.edit_offset is not None
        names = {k.name for k in w.document.rig.correctives}
        qtbot.mouseClick(panel.save_button, QtCore.Qt.LeftButton)
        QtWidgets.QApplication.processEvents()
        qtbot.wait(50)
        (name,) = {k.name for k in w.document.rig.correctives} - names
        table = panel.table
        item = next(table.topLevelItem(i) for i in range(table.topLevelItemCount())
                    if table.topLevelItem(i).text(0) == name)
        assert table.viewport().rect().contains(table.visualItemRect(item)), name     # the new row in view
        assert table.visibleRegion().boundingRect().intersects(table.viewport().geometry())
    header = table.header()
    assert not table.horizontalScrollBar().isVisible()
    assert sum(header.sectionSize(i) for i in range(header.count())) <= table.viewport().width()
    fm = header.fontMetrics()
    for i in range(header.count()):
        assert header.sectionSize(i) >= fm.horizontalAdvance(table.headerItem().text(i)), table.headerItem().text(i)
    for i in range(table.topLevelItemCount()):                # every rule label whole
        text = table.topLevelItem(i).text(2)
        assert header.sectionSize(2) >= fm.horizontalAdvance(text), text


def test_marker_drag_release_returns_at_once_on_ict(qtbot, tmp_path, ict_dir):
    """A marker dragged with the mouse (M, press on the marker, moves, release): the release (1.4 s on ICT when
    reported) returns within 0.2 s and leaves one undo step."""
    from tests.gui_helpers import mouse
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    w.segmentation.wait()
    c = w.markers
    lvl = w.segmentation.segmentation.levels[0]
    for r in range(6):
        assert c.add_marker_at(int(lvl.regions[r].core[len(lvl.regions[r].core) // 2]))
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_M)
    assert c.mode
    w.redraw_now()
    d = w.viewport.world_to_display(c.marker_positions()[:1])[0]
    at = w.viewport.display_to_qt(d[0], d[1]).toPoint()
    steps = w.document.undo_stack.count()
    canvas = w.viewport.canvas
    mouse(canvas, "press", at)
    qtbot.waitUntil(lambda: c.drag is not None, timeout=10000)   # at once, or held until marker mode's set-up is done
    for k in range(1, 6):
        mouse(canvas, "move", at + QtCore.QPoint(3 * k, -4 * k))
    _returns_fast(lambda: mouse(canvas, "release", at + QtCore.QPoint(15, -20)))
    assert c.drag is None and w.document.undo_stack.count() == steps + 1


def test_a_keyed_export_without_keys_says_so_before_asking_for_a_file(qtbot, tmp_path, monkeypatch):
    """File ▸ Export Keyed Weights as CSV…, … per Region …, … Animation as PC2… and the timeline's CSV… and PC2…
    buttons with no key set: one sentence at once. They asked for a file name first (the save dialog), and only
    after Save said there was nothing to export."""
    w = make_window(qtbot, tmp_path)
    asked = []
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName",
                        staticmethod(lambda *a, **k: (asked.append(a), (str(tmp_path / "x"), ""))[1]))
    assert not w.keyframes.timeline.keys
    for text in ("Export Keyed Weights as CSV…", "Export Keyed Weights per Region as CSV…",
                 "Export Keyed Animation as PC2…"):
        w.last_error = None
        _menu_action(w, text).trigger()
        assert asked == [] and w.last_error == "There are no keys to export: set a key first (S).", text
    for button in [b for b in w.keyframes.panel.findChildren(QtWidgets.QPushButton) if b.text() in ("CSV…", "PC2…")]:
        w.last_error = None
        qtbot.mouseClick(button, QtCore.Qt.LeftButton)
        assert asked == [] and w.last_error == "There are no keys to export: set a key first (S).", button.text()
    assert not list(tmp_path.glob("x*"))
