"""Motion capture in the GUI: solve the real marker take on ICT, scrub the side-by-side views, exports,
bad input, and Live Link Face weight takes playing on ICT and on the sample rig."""
from __future__ import annotations

import json

import numpy as np
import pytest
from PySide6 import QtWidgets

from tests.cli_runner import run_cli
from tests.gui_helpers import make_window, open_and_wait
from tests.image_compare import assert_matches_reference, assert_wrong_picture_fails


def _install(qtbot, tmp_path, size=(1400, 1000)):
    w = make_window(qtbot, tmp_path, size=size)
    return w, w.mocap


def _not_background(img: np.ndarray) -> float:
    """Fraction of pixels unlike the background gradient (which is constant along a row: column 0)."""
    d = np.abs(img.astype(int) - img[:, :1].astype(int)).max(axis=2)
    return float((d > 30).mean())


def test_solve_take_scrub_views_export_and_bad_input(qtbot, tmp_path, ict_dir, take_dir, llf_csv):
    w, mc = _install(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    assert w.document.rig.n_vertices == 26719
    rig = w.document.rig

    # bad input first: nothing is loaded yet, nothing gets loaded
    truncated = tmp_path / "truncated.c3d"
    truncated.write_bytes((take_dir / "take.c3d").read_bytes()[:3000])
    assert not mc.load_take(truncated)
    assert "truncated.c3d" in w.last_error and "truncated" in w.last_error
    assert mc.take is None and w.document.rig is rig

    assert mc.load_take(take_dir / "take.c3d")
    assert mc.load_map(take_dir / "marker_map.json")
    assert "60 markers" in mc.panel.map_label.text()
    with qtbot.waitSignal(mc.solved, timeout=120000):
        mc.solve()
    sol = mc.solution
    assert sol.n_frames == 358 and sol.weights.shape == (358, rig.n_shapes)
    assert mc.views.has_residual_bar()
    assert mc.views_dock.isVisible()
    assert f"motion explained {100 * sol.motion_explained:.1f}%" in mc.panel.status_label.text()
    assert "neutral frames 0–29" in mc.panel.status_label.text() and sol.motion_explained > 0.9
    assert mc.panel.settings()["neutral_frames"] is None and mc.panel.settings()["stable"] is None
    # with every panel and the Mocap Views open the window still fits its 1400x900 default (a 1080p screen);
    # the faces and the curves share the dock's width
    assert w.minimumSizeHint().height() <= 900
    qtbot.waitUntil(lambda: mc.weight_plot.width() > 300)
    assert mc.views.width() > 300 and mc.views.height() >= 200
    # the stabilised raw take markers sit on the rig's fit plus the solver's misfit, up to the optical noise
    # the solver smooths away in time (about 0.3 mm in this take)
    ok = np.isfinite(sol.misfit[100]).all(axis=1)
    diff = mc.cache.markers[100][ok] - (mc.cache.fitted[100][ok] + sol.misfit[100][ok])
    assert np.sqrt(np.mean(np.sum(diff ** 2, axis=1))) < 0.05
    np.testing.assert_allclose(mc.cache.fitted[100], sol.solver.markers_at(sol.weights[100]), atol=1e-9)

    # scrub: both views and the markers move; residual colours change; cursors follow
    shots = {}
    for f in (0, 120, 240):
        mc.panel.slider.setValue(f)
        QtWidgets.QApplication.processEvents()
        assert mc.frame == f and mc.panel.frame_label.text().startswith(f"frame {f + 1}/358")
        assert mc.weight_plot.cursor == f and mc.error_plot.cursor == f
        shots[f] = (np.array(mc.views.left_mesh.points), np.array(mc.views.right_mesh.points),
                    np.array(mc.views.right_mesh.point_data["values"]), np.array(mc.views.marker_cloud.points))
    for a, b in ((0, 120), (120, 240)):
        for i in range(4):
            assert np.abs(shots[a][i] - shots[b][i]).max() > 1e-3, (a, b, i)
    # the keyboard: Alt+. / Alt+, step the take, Ctrl+Space plays and pauses it
    acts = {a.text(): a for a in w.actions()}
    acts["Next Take Frame"].trigger()
    assert mc.frame == 241 and mc.panel.slider.value() == 241
    acts["Previous Take Frame"].trigger()
    acts["Previous Take Frame"].trigger()
    assert mc.frame == 239
    acts["Play / Pause &Take"].trigger()
    assert mc.playing and acts["Play / Pause &Take"].shortcut().toString() == "Ctrl+Space"
    acts["Play / Pause &Take"].trigger()
    assert not mc.playing
    proj, dense, res = shots[240][:3]
    np.testing.assert_allclose(res, np.linalg.norm(dense - proj, axis=1) * 10.0, rtol=1e-3, atol=1e-3)  # cm -> mm
    np.testing.assert_allclose(dense, sol.dense(240)[mc.views.shown_vertices], atol=1e-4)
    assert res.max() > 0.05  # the residual is there and coloured

    # screenshot of the side-by-side view: both halves show a face
    mc.set_frame(180)
    img = mc.views.grab_image(size=(560, 440))  # a fixed size, whatever the dock layout
    half = img.shape[1] // 2
    assert _not_background(img[:, :half]) > 0.1 and _not_background(img[:, half:]) > 0.1
    assert_matches_reference(img, "mocap_side_by_side", unlike=["mocap_side_by_side_neutral"])
    # its wrong-picture twin: the first (neutral calibration) frame is not frame 180
    mc.set_frame(0)
    neutral = mc.views.grab_image(size=(560, 440))
    assert_matches_reference(neutral, "mocap_side_by_side_neutral", unlike=["mocap_side_by_side"])
    assert_wrong_picture_fails(neutral, "mocap_side_by_side", unlike=["mocap_side_by_side_neutral"])
    # orbiting round to the back: culling goes off, so the mask's back is drawn instead of nothing
    assert mc.views.culling()
    mc.views.plotter.renderers[0].GetActiveCamera().Azimuth(180)
    back = mc.views.grab_image()
    assert not mc.views.culling()
    half = back.shape[1] // 2
    # (culled, only labels, markers and a few inward faces cover about 6 %; drawn, about 20 %)
    assert _not_background(back[:, :half]) > 0.12 and _not_background(back[:, half:]) > 0.12
    mc.views.set_camera("front")
    assert mc.views.culling()

    # exports
    assert mc.export_weights_csv(tmp_path / "w.csv")
    from model.weights_csv import read_weights_csv
    frames, times, names, W = read_weights_csv(tmp_path / "w.csv")
    assert names == rig.shape_names and W.shape == (358, rig.n_shapes)
    np.testing.assert_allclose(W, sol.weights)
    assert mc.export_report(tmp_path / "report.json")
    rep = json.loads((tmp_path / "report.json").read_text())
    assert rep["rig_units"] == "cm" and rep["frames"] == 358 and rep["markers"] == 60
    assert len(rep["marker_rmse_per_frame"]) == 358 and len(rep["marker_rmse_per_marker"]) == 60
    assert 0 < rep["marker_rmse"] < 0.2 and rep["neutral_frames"] == [0, 29] and rep["mode"] == "global"
    np.testing.assert_allclose(rep["marker_rmse_per_frame"], sol.marker_rmse, rtol=1e-12)
    # `solve --report` on the same take and map writes the same report: same keys, same values but the timings
    run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json", "-o", tmp_path / "c.csv",
            "--report", tmp_path / "cli_report.json")
    cli = json.loads((tmp_path / "cli_report.json").read_text())
    assert set(cli) == set(rep)
    for key in set(rep) - {"solve_seconds", "frames_per_second"}:
        assert _same(cli[key], rep[key]), key

    # a map naming markers the take lacks is refused; the solve and the map stay
    bad = json.loads((take_dir / "marker_map.json").read_text())
    bad["markers"]["NOPE1"] = 10
    (tmp_path / "bad_map.json").write_text(json.dumps(bad))
    kept_map = mc.marker_map
    assert not mc.load_map(tmp_path / "bad_map.json")
    assert "NOPE1" in w.last_error and "bad_map.json" in w.last_error
    assert mc.marker_map is kept_map and mc.solution is sol and mc.take is not None
    assert not mc.load_take(truncated)
    assert mc.solution is sol and w.document.rig is rig

    # a Live Link Face take plays on ICT in the main viewport, without undo steps
    undo_before = w.document.undo_stack.count()
    assert mc.load_take(llf_csv)
    assert mc.take.unmapped == ["TongueOut"] and "TongueOut" in mc.panel.take_label.text()
    _check_weight_playback(qtbot, w, mc)
    assert w.document.undo_stack.count() == undo_before

    # the views / curves split the user chose comes back in the next session
    splitter = mc.views.parentWidget()
    splitter.setSizes([400, sum(splitter.sizes()) - 400])
    chosen = splitter.sizes()
    w2, mc2 = _install(qtbot, tmp_path)
    mc.shutdown()   # what closing the first window does
    mc2._show_views_dock()
    qtbot.waitUntil(lambda: mc2.views.parentWidget().sizes() == chosen, timeout=5000)
    w2.close()


def _same(a, b) -> bool:
    """Equal JSON values, numbers to 1e-9 relative (the two solves run the same code on the same data)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, (int, float)):
        return abs(a - b) <= 1e-9 * max(1.0, abs(a))
    return a == b


def _check_weight_playback(qtbot, w, mc):
    mc.set_frame(0)
    w.redraw_now()
    before = w.viewport.points().copy()
    mc.panel.loop_check.setChecked(False)
    mc.play()
    qtbot.waitUntil(lambda: mc.frame >= 130, timeout=20000)  # the performance starts moving near frame 100
    mc.pause()
    w.redraw_now()
    f = mc.frame
    np.testing.assert_allclose(w.document.weights, mc.take.weights[f])
    np.testing.assert_allclose(w.viewport.points(), w.document.evaluator.evaluate(mc.take.weights[f]), atol=1e-4)
    moved = np.linalg.norm(w.viewport.points() - before, axis=1)
    assert moved.max() > 0.1 * np.abs(w.document.rig.deltas).max()


def test_live_link_face_plays_on_sample_rig(qtbot, tmp_path, llf_csv):
    w, mc = _install(qtbot, tmp_path, size=(1100, 800))
    rig = w.document.rig
    assert mc.load_take(llf_csv)
    take = mc.take
    assert take.names == rig.shape_names and take.n_frames == 328
    assert take.unmapped and all(c in mc.panel.take_label.text() for c in take.unmapped)
    assert not mc.panel.solve_button.isEnabled()
    _check_weight_playback(qtbot, w, mc)
    assert w.document.undo_stack.count() == 0
    assert mc.export_pc2(tmp_path / "llf.pc2")
    from model.pc2 import read_pc2
    data, _, _ = read_pc2(tmp_path / "llf.pc2")
    assert data.shape == (328, rig.n_vertices, 3)
    np.testing.assert_allclose(data[50], w.document.evaluator.evaluate(take.weights[50]), atol=1e-4)


def test_a_point_cache_its_disk_has_no_room_for_is_refused(qtbot, tmp_path, llf_csv, monkeypatch):
    """Export PC2 Point Cache checks the room on the disk first, as `solve --cache` does (``model.free_space``):
    a dialog naming the file, the size and the space free, nothing written (before, it wrote until the disk was
    full). File ▸ Export Keyed Animation as PC2 likewise."""
    import shutil
    from collections import namedtuple
    from model.errors import RigInputError
    from model.free_space import human_size
    from model.pc2 import pc2_size
    w, mc = _install(qtbot, tmp_path, size=(1100, 800))
    assert mc.load_take(llf_csv)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: namedtuple("Usage", "total used free")(10**9, 0, 1000))
    assert not mc.export_pc2(tmp_path / "llf.pc2") and not (tmp_path / "llf.pc2").exists()
    needed = human_size(pc2_size(328, w.document.rig.n_vertices))
    assert w.last_error == (f"{tmp_path / 'llf.pc2'}: needs {needed}, but the disk of {tmp_path} has 1 KB free; "
                            "free some space or write to another disk.")
    k = w.keyframes
    k.set_key(0.0)
    k.set_key(1.0)
    with pytest.raises(RigInputError, match="keys.pc2: needs .*, but the disk of .* has 1 KB free"):
        k.export_pc2(tmp_path / "keys.pc2")
    assert not (tmp_path / "keys.pc2").exists()


def test_solve_without_map_or_segmentation_says_why(qtbot, tmp_path, take_dir):
    w, mc = _install(qtbot, tmp_path, size=(1100, 800))
    assert mc.load_take(take_dir / "take.c3d")
    mc.solve()
    assert "marker map" in w.last_error and mc.solution is None


def test_the_mocap_views_draw_the_parts_view_parts_shows(qtbot, tmp_path, ict_dir, take_dir):
    """The Mocap Views draw what View ▸ Parts shows, as the viewport does: ICT's helper shells (hidden by default:
    drawn opaque they cover the eyes) are not drawn after a solve, and hiding the teeth from the menu takes them
    out of both views at once, at the same frame and from the same camera, with the picture changed in the mouth."""
    from model.parts import rig_parts
    w, mc = _install(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    rig = w.document.rig
    parts = rig_parts(rig)
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=120000):
        mc.solve()

    def drawn_parts() -> dict[str, int]:
        """Faces of each part that the left view draws (its faces are the rig's, renumbered, in the rig's order)."""
        views = mc.views
        counts, local = views.left_mesh.n_cells, views.left_mesh.faces
        ids = []
        i = 0
        while i < len(local):          # pyvista's faces: n, i0 .. in-1, back to the rig's vertex numbers
            n = local[i]
            ids.append(tuple(views.shown_vertices[local[i + 1:i + 1 + n]]))
            i += n + 1
        assert len(ids) == counts
        starts = np.concatenate(([0], np.cumsum(rig.face_counts)[:-1]))
        key = {tuple(rig.face_indices[a:a + n]): k for k, (a, n) in enumerate(zip(starts, rig.face_counts))}
        faces = np.array([key[t] for t in ids])
        names, n = np.unique(np.array(parts.names)[parts.face_part[faces]], return_counts=True)
        return dict(zip(names.tolist(), n.tolist()))

    drawn = drawn_parts()
    for shell in ("M_EyeOcclusion", "M_LacrimalFluid", "M_EyeBlend"):
        assert shell not in drawn, drawn          # hidden by default in the viewport: not drawn here either
    assert drawn["M_Teeth"] > 1000 and drawn["M_Face"] > 5000 and drawn["M_IrisLeft"] > 500
    mc.set_frame(180)
    camera = mc.views.plotter.camera_position
    before = mc.views.grab_image(size=(560, 440))
    teeth = w.parts.part_actions["M_Teeth"]
    assert teeth.isChecked()
    teeth.trigger()                               # View ▸ Parts ▸ M_Teeth, as a click on the menu item does
    assert not teeth.isChecked()
    after_drawn = drawn_parts()
    assert "M_Teeth" not in after_drawn and after_drawn["M_Face"] == drawn["M_Face"]
    assert mc.frame == 180 and mc.views.plotter.camera_position == camera
    after = mc.views.grab_image(size=(560, 440))
    changed = np.abs(after.astype(int) - before.astype(int)).max(axis=2) > 40
    rows, cols = np.nonzero(changed[:, :280])     # the left view: the teeth between the lips, nothing else
    assert 100 < rows.size < 0.05 * 440 * 280, rows.size
    assert rows.mean() > 0.5 * 440                # the mouth is in the face's lower half
    teeth.trigger()                               # shown again: the same picture as before
    again = mc.views.grab_image(size=(560, 440))
    assert np.abs(again.astype(int) - before.astype(int)).max() <= 2


def test_side_by_side_culls_the_faces_turned_away_whatever_the_winding():
    """The views cull back faces of a mesh wound counter-clockwise seen from the front (+Z), front faces of
    one wound the other way: the face the camera looks at is never the culled side."""
    from solvers.normals import VertexNormals
    from widgets.side_by_side import _faces_forward
    quad = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    ccw, cw = np.array([0, 1, 2, 3]), np.array([0, 3, 2, 1])
    assert _faces_forward(quad, VertexNormals(np.array([4]), ccw, 4))
    assert not _faces_forward(quad, VertexNormals(np.array([4]), cw, 4))


def test_a_30_fps_live_link_face_take_plays_in_real_time(qtbot, tmp_path, monkeypatch):
    """Issue 16: a Live Link Face CSV recorded at 30 fps plays at 30 frames a second: on the playback's clock, the
    frame shown 1.5 s after Play is the one the timecodes put at 1.5 s (frame 45, not frame 90 as at a fixed 60),
    and the face shows that row's weights."""
    import app.mocap_playback as playback
    from tests.test_takes import _codes, _llf_file
    w, mc = _install(qtbot, tmp_path, size=(1100, 800))
    jaw = np.linspace(0.0, 0.9, 90)
    assert mc.load_take(_llf_file(tmp_path / "llf30.csv", _codes(range(90), 30), jaw))
    take = mc.take
    assert take.rate == 30.0 and take.n_frames == 90 and mc.playback.rate == 30.0
    clock = [1000.0]
    monkeypatch.setattr(playback.time, "perf_counter", lambda: clock[0])
    mc.set_frame(0)
    mc.panel.loop_check.setChecked(False)
    mc.play()
    mc.playback._tick()                       # the first tick: the clock starts (frame 0 is shown)
    clock[0] += 1.5
    mc.playback._tick()                       # the timer's tick at 1.5 s on the clock
    mc.pause()
    assert mc.frame == 45 and take.times()[mc.frame] == pytest.approx(1.5)
    np.testing.assert_allclose(w.document.weights, take.weights[45])
    assert w.document.weights[w.document.rig.shape_index("jawOpen")] == pytest.approx(jaw[45], abs=1e-4)
    # the same weights as a weights CSV (what `solve` writes) open as a weight take at the same rate
    from model.weights_csv import write_weights_csv
    write_weights_csv(tmp_path / "w.csv", take.weights, take.names, rate=30.0)
    assert mc.load_take(tmp_path / "w.csv")
    assert mc.take.rate == 30.0 and np.array_equal(mc.take.weights, take.weights) and mc.playback.rate == 30.0


def test_auto_map_runs_in_the_background_and_gives_the_models_map(qtbot, tmp_path, ict_dir, take_dir):
    """Auto Map (a few seconds: registration, then the re-fit from the take's motion) returns control at once and
    uses the map when it arrives: the same map the model finds (``TakeWorkspace.find_auto_map``), the same place
    for every marker as ``solve`` without ``--map``."""
    from PySide6 import QtCore

    from model.take_workspace import TakeWorkspace
    w, mc = _install(qtbot, tmp_path, size=(1100, 800))
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take_dir / "take.c3d")
    qtbot.mouseClick(mc.panel.auto_map_button, QtCore.Qt.LeftButton)
    assert mc.marker_map is None and "Mapping" in mc.panel.status_label.text()   # the click did not wait
    with qtbot.waitSignal(mc.map_found, timeout=120000):
        pass
    ws = TakeWorkspace(w.document.rig)
    ws.load_take(take_dir / "take.c3d")
    expected, _ = ws.find_auto_map()
    assert mc.marker_map.markers == expected.markers and len(expected.markers) == 60
    assert "Automatic map: 60 markers" in mc.panel.status_label.text()


def test_the_views_of_a_solve_are_prepared_off_the_gui_thread(qtbot, tmp_path, ict_dir, take_dir, monkeypatch):
    """The Mocap Views' faces, frame cache, first frame and residual range of a solve (``views_data``: 0.2-0.3 s
    on ICT, a frozen window after each solve when the GUI thread made them) are made on the solve's thread; the
    GUI thread only uploads them."""
    import app.mocap_controller as mocap_controller
    from tests.gui_helpers import calls_on_gui_thread
    threads = calls_on_gui_thread(monkeypatch, mocap_controller, "views_data")
    w, mc = _install(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=120000):
        mc.solve()
    assert threads == [False] and mc.cache is not None and mc.views.left_mesh.n_points > 1000


def _shown_whole_in(widget, dock) -> None:
    """``widget`` is drawn whole inside ``dock``: inside the view of every scroll area around it (no scrolling
    needed to see it) and not clipped by anything."""
    from PySide6 import QtCore
    parent = widget.parentWidget()
    while parent is not None and parent is not dock:
        if isinstance(parent, QtWidgets.QAbstractScrollArea):
            view = parent.viewport()
            where = QtCore.QRect(widget.mapTo(view, QtCore.QPoint(0, 0)), widget.size())
            assert view.rect().contains(where), (widget, where, view.rect())
        parent = parent.parentWidget()
    assert parent is dock
    assert widget.isVisible() and widget.visibleRegion().boundingRect() == widget.rect(), widget


def test_after_a_solve_the_transport_and_the_status_are_in_view(qtbot, tmp_path, ict_dir, take_dir):
    """After a solve (the Mocap Views dock taking the lower part of the window) the solve's result line, Play,
    the frame slider and the frame label are in view without scrolling, at the default 1400x900 and at 1366x768;
    neither the Mocap nor the Segmentation panel needs a horizontal scroll bar. The Mocap panel needed ~900 px of
    height: all of them sat below the dock's bottom, and the Segmentation panel was 10 px too wide for its dock
    once its vertical scroll bar showed."""
    from PySide6 import QtCore
    w, mc = _install(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    mc.dock.show()
    mc.dock.raise_()
    panel = mc.panel
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    QtWidgets.QApplication.processEvents()
    _shown_whole_in(panel.status_label, mc.dock)           # "Ready: Solve the take."
    _shown_whole_in(panel.solve_button, mc.dock)
    with qtbot.waitSignal(mc.solved, timeout=180000):
        qtbot.mouseClick(panel.solve_button, QtCore.Qt.LeftButton)
    assert mc.views_dock.isVisible() and panel.status_label.text().startswith("Solved 358 frames")
    for size in ((1400, 900), (1366, 768)):
        w.resize(*size)
        qtbot.wait(200)
        assert w.size().toTuple() == size
        for widget in (panel.status_label, panel.play_button, panel.slider, panel.frame_label):
            _shown_whole_in(widget, mc.dock)
        label = panel.status_label
        assert label.height() >= label.heightForWidth(label.width()), size     # every line of the result
        for dock, content in ((mc.dock, panel), (w.segmentation_dock, w.segmentation_panel)):
            area = dock.widget()
            assert not area.horizontalScrollBar().isVisible(), (size, dock.windowTitle())
            assert content.minimumSizeHint().width() <= area.viewport().width(), (size, dock.windowTitle())
    # the transport is live: a click on Play plays the take
    qtbot.mouseClick(panel.play_button, QtCore.Qt.LeftButton)
    assert panel.play_button.isChecked()
    qtbot.mouseClick(panel.play_button, QtCore.Qt.LeftButton)
    assert not panel.play_button.isChecked()


def test_the_advanced_solver_settings_unfold_with_a_click_and_stay_unfolded(qtbot, tmp_path):
    """The residual kernel, the λs and the RBF kernel are folded away under 'Advanced solver settings' (so that
    Solve stays in view above the transport); a click shows them, and the next session shows them again."""
    from PySide6 import QtCore
    w, mc = _install(qtbot, tmp_path, size=(1400, 900))
    mc.dock.show()
    mc.dock.raise_()
    panel = mc.panel
    boxes = (panel.residual_combo, panel.lam_sparsity, panel.lam_temporal, panel.rbf_scale, panel.rbf_lambda)
    assert not any(b.isVisibleTo(panel) for b in boxes)
    qtbot.mouseClick(panel.advanced_button, QtCore.Qt.LeftButton)
    assert all(b.isVisibleTo(panel) for b in boxes)
    w.close()
    w2 = make_window(qtbot, tmp_path, size=(1400, 900))
    assert all(b.isVisibleTo(w2.mocap.panel) for b in (w2.mocap.panel.residual_combo, w2.mocap.panel.rbf_lambda))
    qtbot.mouseClick(w2.mocap.panel.advanced_button, QtCore.Qt.LeftButton)
    assert not w2.mocap.panel.rbf_lambda.isVisibleTo(w2.mocap.panel)


def test_the_first_solve_frames_the_views_at_their_size_and_draws_them_once(qtbot, tmp_path, ict_dir, take_dir):
    """The Mocap Views dock opens with a solve's result at its final size, framed for it and drawn once: before, the
    views were drawn five times while still hidden (each mesh added, the framing, the first frame) and framed again
    when the dock's splitter took its size on the event loop's next turn, a window frozen 0.25 s after the first
    solve (the progress dialog just closed)."""
    w, mc = _install(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    assert not mc.views_dock.isVisible()
    renders: list[int] = []
    mc.views.plotter.ren_win.AddObserver("EndEvent", lambda *_: renders.append(1))
    at_solved: dict = {}
    mc.solved.connect(lambda: at_solved.update(renders=len(renders), size=mc.views.size().toTuple(),
                                               camera=mc.views.plotter.camera_position))
    with qtbot.waitSignal(mc.solved, timeout=180000):
        mc.solve()
    assert at_solved["renders"] == 1, at_solved["renders"]   # the first frame
    qtbot.wait(400)
    assert mc.views.size().toTuple() == at_solved["size"]
    assert mc.views.plotter.camera_position == at_solved["camera"]   # not framed again at another size
    assert at_solved["size"][0] > 600 and at_solved["size"][1] > 150


def test_a_marker_map_replaced_by_load_map_or_auto_map_comes_back_with_undo(qtbot, tmp_path, ict_dir, take_dir,
                                                                             monkeypatch):
    """Load Map… or Auto Map over a map already loaded threw the old map away with no undo step, though dragging one
    of its points is undoable: a map corrected by hand, or an automatic map that took seconds, was lost for good."""
    from PySide6 import QtCore, QtGui
    w, mc = _install(qtbot, tmp_path, size=(1100, 800))
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take_dir / "take.c3d")
    qtbot.mouseClick(mc.panel.auto_map_button, QtCore.Qt.LeftButton)
    with qtbot.waitSignal(mc.map_found, timeout=120000):
        pass
    auto = mc.marker_map
    steps = w.document.undo_stack.count()
    monkeypatch.setattr(QtWidgets.QFileDialog, "getOpenFileName",
                        staticmethod(lambda *a, **k: (str(take_dir / "marker_map.json"), "")))
    qtbot.mouseClick(mc.panel.load_map_button, QtCore.Qt.LeftButton)          # Load Map… over the automatic map
    loaded = mc.marker_map
    assert loaded is not auto and loaded.source and w.document.undo_stack.count() == steps + 1
    undo = next(a for a in w.findChildren(QtGui.QAction) if a.shortcut() == QtGui.QKeySequence.Undo)
    undo.trigger()
    assert mc.marker_map is auto and "automatic" in mc.panel.map_label.text()
    w.redo_action.trigger()
    assert mc.marker_map is loaded and "marker_map.json" in mc.panel.map_label.text()
    qtbot.mouseClick(mc.panel.auto_map_button, QtCore.Qt.LeftButton)          # Auto Map over the loaded map
    with qtbot.waitSignal(mc.map_found, timeout=120000):
        pass
    assert mc.marker_map.markers == auto.markers and "Automatic map: 60 markers" in mc.panel.status_label.text()
    undo.trigger()
    assert mc.marker_map is loaded


def test_a_new_take_that_the_kept_marker_map_does_not_fit_is_not_called_ready(qtbot, tmp_path, ict_dir, take_dir):
    """The marker map stays when another take is loaded; the panel said "Ready: Solve the take." even when the map
    names none of the new take's markers (a body take from another lab), and only Solve said otherwise."""
    from tests.conftest import DATA, require_data
    body = require_data(DATA / "thirdparty" / "c3d" / "pyomeca_Vicon.c3d")
    w, mc = _install(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    assert mc.panel.status_label.text() == "Ready: Solve the take."
    assert mc.load_take(body)
    status = mc.panel.status_label.text()
    assert "Ready" not in status and "none of its 60 marker labels appear in the take" in status
    assert mc.load_take(take_dir / "take.c3d")
    assert mc.panel.status_label.text() == "Ready: Solve the take."


def test_the_mocap_panels_status_is_of_the_rig_that_is_open(qtbot, tmp_path, take_dir):
    """A failed take load's sentence stayed under the Mocap panel after another rig was opened, above a take that
    had loaded fine; the panel now says the take's next step on the new rig."""
    w, mc = _install(qtbot, tmp_path)
    assert mc.load_take(take_dir / "take.c3d")
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"\x02P" + b"\x00" * 600)
    assert not mc.load_take(bad)
    assert str(bad) in mc.panel.status_label.text()
    w.open_sample()
    QtWidgets.QApplication.processEvents()
    assert mc.workspace.take_path == take_dir / "take.c3d"
    assert mc.panel.status_label.text() == "Load or build a marker map, then Solve."


def test_a_take_the_new_rig_drops_leaves_no_frame_shown(qtbot, tmp_path, llf_csv):
    """A Live Link Face take that does not fit the next rig opened is dropped ("no take"), but the panel went on
    showing its frame ("frame 151/328 · 2.50 s") and slider; it shows none now."""
    from tests.conftest import DATA, require_data
    cube = require_data(DATA / "thirdparty" / "gltf" / "singleBlendshapeCube_sparse.glb")
    w, mc = _install(qtbot, tmp_path)
    assert mc.load_take(llf_csv)
    mc.panel.slider.setValue(150)
    assert mc.panel.frame_label.text().startswith("frame 151/328")
    open_and_wait(qtbot, w, cube)
    assert mc.take is None and mc.panel.take_label.text() == "no take"
    assert mc.panel.frame_label.text() == "frame –" and mc.panel.slider.maximum() == 0
    assert "The weight take does not fit this rig" in mc.panel.status_label.text()


def test_a_take_loaded_in_the_mocap_panel_shows_its_readers_warnings(qtbot, tmp_path):
    """A plain marker CSV loaded in the Mocap panel is read at 60 fps, which its file does not say: the panel said
    nothing of it (nor of any reader's warning). The model's sentence is now in the panel's status, before the next
    step, and on the take's label as a tooltip."""
    from model.takes import load_take
    w, mc = _install(qtbot, tmp_path)
    take = tmp_path / "plain.csv"
    take.write_text("frame,A_X,A_Y,A_Z\n0,1,2,3\n1,1,2,4\n")
    assert mc.load_take(take)
    said = load_take(take).warnings
    assert len(said) == 1 and "60 frames a second" in said[0]
    status = mc.panel.status_label.text()
    assert said[0] in status and status.endswith("Load or build a marker map, then Solve.")
    assert mc.panel.take_label.toolTip() == said[0] and "at 60 fps" in mc.panel.take_label.text()


def _type_rate(qtbot, spin, text: str) -> None:
    """Select the Frame rate field's text and type ``text`` and Enter, as a user does."""
    from PySide6.QtTest import QTest
    from PySide6 import QtCore
    spin.setFocus()
    QTest.keyClick(spin, QtCore.Qt.Key_A, QtCore.Qt.ControlModifier)
    QTest.keyClicks(spin, text)
    QTest.keyClick(spin, QtCore.Qt.Key_Return)
    QtWidgets.QApplication.processEvents()


def test_the_rate_of_a_take_whose_file_gives_none_is_typed_in_the_mocap_panel(qtbot, tmp_path, take_dir):
    """The command line gives a plain marker CSV or an untimed weights CSV its rate (--rate); the Mocap panel read
    them at 60 and 30 fps with no way to say otherwise. A Frame rate field now shows for such a take only; a rate
    typed there reads the take again at it (no 'assumed' warning), and is remembered for the file."""
    from PySide6 import QtCore
    from PySide6.QtTest import QTest
    from model.takes import load_take
    actor = load_take(take_dir.parent / "actor_take" / "take.trc")   # a real take, written as a plain marker CSV
    plain = tmp_path / "actor.csv"
    flat = actor.positions[:40].reshape(40, -1)
    plain.write_text("frame," + ",".join(f"{n}_{a}" for n in actor.labels for a in "XYZ") + "\n" + "".join(
        f"{i}," + ",".join("" if not np.isfinite(v) else f"{v:.4f}" for v in row) + "\n" for i, row in enumerate(flat)))
    w, mc = _install(qtbot, tmp_path)
    panel, spin = mc.panel, mc.panel.rate_spin
    assert mc.load_take(take_dir / "take.c3d")
    assert not spin.isVisibleTo(panel)               # a rate the file gives is not editable
    assert mc.load_take(plain)
    assert spin.isVisibleTo(panel) and spin.value() == 60.0 and "assumed" in panel.status_label.text()
    before = mc.take.positions.copy()
    _type_rate(qtbot, spin, "30")
    assert mc.take.rate == 30.0 and mc.take.warnings == [] and mc.workspace.take_path == plain
    assert np.array_equal(mc.take.positions, before, equal_nan=True)
    assert "at 30 fps" in panel.take_label.text() and "assumed" not in panel.status_label.text()
    assert w.document.undo_stack.count() == 0        # loading a take is no undo step; giving its rate neither
    assert mc.load_take(take_dir / "take.c3d") and not spin.isVisibleTo(panel) and mc.take.rate == 60.0
    assert mc.load_take(plain)                       # remembered for the file
    assert mc.take.rate == 30.0 and spin.value() == 30.0 and mc.take.warnings == []
    project = tmp_path / "with_take.bsproj"          # and kept with the project, for another machine
    assert w.save_to(project)
    from app import settings as app_settings
    app_settings.settings().remove("mocap/takeRates")
    assert mc.load_take(take_dir / "take.c3d")
    open_and_wait(qtbot, w, project)
    qtbot.waitUntil(lambda: mc.workspace.take_path == plain, timeout=30000)
    assert mc.take.rate == 30.0 and spin.value() == 30.0 and spin.isVisibleTo(panel)
    untimed = tmp_path / "weights.csv"               # a weights CSV without times plays at the rate given
    untimed.write_text("frame,eyeBlink_L,eyeBlink_R\n" + "".join(f"{i},{i / 20:.2f},0\n" for i in range(20)))
    assert mc.load_take(untimed) and mc.take.rate == 30.0 and spin.value() == 30.0
    _type_rate(qtbot, spin, "24")
    assert mc.take.rate == 24.0 and mc.playback.rate == 24.0 and mc.n_frames == 20
    QTest.keyClick(spin, QtCore.Qt.Key_Up)
    QtWidgets.QApplication.processEvents()
    assert mc.take.rate == 25.0 and mc.playback.rate == 25.0
    w.open_sample()                                  # the weight take read again on the new rig keeps its rate
    QtWidgets.QApplication.processEvents()
    assert mc.take.rate == 25.0 and spin.isVisibleTo(panel) and spin.value() == 25.0
    untimed.unlink()                                 # a file gone: said, and the take and the field keep 25
    _type_rate(qtbot, spin, "50")
    assert str(untimed) in w.last_error and mc.take.rate == 25.0 and spin.value() == 25.0


def test_save_map_may_write_over_its_own_map_but_no_export_over_the_take_or_map(qtbot, tmp_path, ict_dir, take_dir):
    """The window's exports refuse the files it has open (``model.beside_inputs``): the Mocap panel's report or weights
    over the take or its marker map are refused in one sentence, nothing written; Save Map writes the map (with the
    points moved on the rig) over the file it came from, as before."""
    import shutil
    take, mapping = tmp_path / "take.c3d", tmp_path / "map.json"
    shutil.copy(take_dir / "take.c3d", take)
    shutil.copy(take_dir / "marker_map.json", mapping)
    w, mc = _install(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take) and mc.load_map(mapping)
    before = take.read_bytes(), mapping.read_bytes()
    assert not mc.export_report(mapping)
    assert w.last_error == f"{mapping}: is the marker map itself, which the window has open; choose another file."
    assert not mc.export_weights_csv(take)
    assert w.last_error == f"{take}: is the take itself, which the window has open; choose another file."
    assert (take.read_bytes(), mapping.read_bytes()) == before
    assert mc.save_map(mapping) and json.loads(mapping.read_text())["markers"] == mc.marker_map.markers


def test_the_mocap_panel_says_what_a_weight_take_is(qtbot, tmp_path, ict_dir, take_dir, llf_csv):
    """A weight take is described by what its file is: the weights CSV ``solve`` writes is a weights CSV (it was
    labelled "Live Link Face", as every weight take was), the iPhone recording a Live Link Face CSV; both in the
    take's line and in the panel's status while it plays."""
    w, mc = _install(qtbot, tmp_path, size=(1100, 800))
    open_and_wait(qtbot, w, ict_dir)
    solved = tmp_path / "solved.csv"
    run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json", "--global",
            "--residual", "none", "-o", solved)
    for path, what, other in ((solved, "weights CSV", "Live Link Face"), (llf_csv, "Live Link Face CSV", "weights")):
        assert mc.load_take(path)
        line, status = mc.panel.take_label.text(), mc.panel.status_label.text()
        assert line.startswith(f"{path.name}: {what}, ") and other not in line, line
        assert f"{what[:1].upper()}{what[1:]} take: plays on the rig" in status and other not in status, status
