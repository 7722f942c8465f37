"""Marker dragging, regional poses and keyframes in the main window (pytest-qt, sample rig, real mouse events)."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore

from tests.gui_helpers import make_window, mouse, open_and_wait


@pytest.fixture(scope="module")
def geometry():
    from resources.sample_rig import sample_geometry
    return sample_geometry()


@pytest.fixture(scope="module")
def nose_tip(sample_rig, geometry):
    """The skin vertex farthest forward on the midline: the tip of the nose."""
    p = sample_rig.neutral
    mid = np.flatnonzero(geometry.skin & (np.arange(len(p)) < geometry.n_grid) & (np.abs(p[:, 0]) < 0.3))
    return int(mid[np.argmax(p[mid, 2])])


def _window(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=30000)
    return w


def _pins(w, geometry, nose_tip):
    """Markers on both mouth corners, the nose tip and the chin; returns the controller."""
    c = w.markers
    chin = int(geometry.mouth.lower[len(geometry.mouth.lower) // 2]) - 3 * geometry.n_cols
    for v in (int(geometry.mouth.upper[0]), int(geometry.mouth.upper[-1]), nose_tip, chin):
        assert c.add_marker_at(v), c.last_message
    return c


def _screen(w, points):
    """Widget-local Qt positions of world points on the viewport's interactor widget."""
    d = w.viewport.world_to_display(points)
    return [w.viewport.display_to_qt(x, y) for x, y, _ in d]


def _assert_picture_changed_at_the_corner(w, before, P0, corner, nose):
    """The viewport's picture during the drag differs from the one before it at the mouth, around the dragged
    corner, and not at the pinned nose tip: the pixels a user sees change are where the edit is."""
    from tests.image_compare import LEVELS, pixel_difference
    changed = pixel_difference(w.viewport.picture(), before) > LEVELS
    rows, cols = np.nonzero(changed)
    d = w.viewport.world_to_display(P0)
    x, row = d[:, 0], changed.shape[0] - 1 - d[:, 1]             # image column and row of each marker
    reach = np.hypot(x[nose] - x[corner], row[nose] - row[corner])
    assert changed.sum() > 500                                  # measured: 1,800 pixels
    assert (np.hypot(cols - x[corner], rows - row[corner]) < reach).mean() > 0.7   # around the corner (81 %)
    # the lower face only: the mouth corner's region reaches the cheek beside the nose (a few pixels above the
    # tip's row), never the eyes or brows, which lie a whole corner-to-nose distance higher
    assert (rows > row[nose] - 0.25 * reach).all()
    r, c = int(round(row[nose])), int(round(x[nose]))
    assert not changed[r - 3:r + 4, c - 3:c + 4].any()          # the pinned nose tip stays where it was


def test_real_mouse_drag_moves_the_marker_and_one_undo_restores_the_pose(qtbot, tmp_path, geometry, nose_tip):
    w = _window(qtbot, tmp_path)
    c = _pins(w, geometry, nose_tip)
    w.markers.mode_action.trigger()
    assert c.mode and "Marker mode" in w.statusBar().currentMessage()
    lvl = w.segmentation.segmentation.levels[c.level]
    assert 1 < lvl.n_regions < w.segmentation.segmentation.levels[0].n_regions  # a middle level by default
    doc = w.document
    before_state = doc.pose_state()
    before_pts = w.viewport.points().copy()
    P0 = c.marker_positions()
    corner = 0
    widget = w.viewport.canvas
    q = _screen(w, P0[corner:corner + 1])[0]
    start = QtCore.QPoint(round(q.x()), round(q.y()))
    # Outward (screen left is the character's right) and up, by about 1.5 cm and 1 cm on the face, whatever
    # the viewport's size: measure how many pixels a centimetre is at the corner.
    q_cm = _screen(w, P0[corner:corner + 1] + np.array([[1.0, 0.0, 0.0]]))[0]
    px_per_cm = np.hypot(q_cm.x() - q.x(), q_cm.y() - q.y())
    drag = QtCore.QPoint(-round(1.5 * px_per_cm), -round(1.0 * px_per_cm))
    before_img = w.viewport.picture()
    mouse(widget, "press", start)
    assert c.drag is not None and c.drag.index == corner
    cam_before = w.viewport.camera_frame().position
    for i in range(1, 7):
        mouse(widget, "move", start + drag * i / 6)
    qtbot.waitUntil(lambda: not w.redraw_pending)
    assert doc.is_regional and doc.region_level == c.level
    np.testing.assert_array_equal(w.viewport.points(), doc.surface())  # the face updated during the drag
    targets = c.drag.targets.copy()
    _assert_picture_changed_at_the_corner(w, before_img, P0, corner, nose=2)
    mouse(widget, "release", start + drag)
    np.testing.assert_array_equal(w.viewport.camera_frame().position, cam_before)  # camera stayed
    assert doc.undo_stack.count() == 5  # 4 markers + one drag
    P1 = c.marker_positions()
    moved, wanted = P1[corner] - P0[corner], targets[corner] - P0[corner]
    assert np.linalg.norm(wanted) > 0.3  # the damped target moved (cm)
    along = moved @ wanted / np.linalg.norm(wanted)
    assert along > 0.5 * np.linalg.norm(wanted)  # the corner follows its target
    # In screen space it went the way the mouse went.
    q1 = _screen(w, P1[corner:corner + 1])[0]
    d_screen = np.array([q1.x() - q.x(), q1.y() - q.y()])
    assert d_screen @ np.array([drag.x(), drag.y()]) > 0.5 * np.hypot(drag.x(), drag.y()) * np.linalg.norm(d_screen)
    others = [1, 2, 3]
    assert np.linalg.norm(P1[others] - P0[others], axis=1).max() < 0.25 * np.linalg.norm(moved)  # pins stay
    W = doc.region_weights
    assert W.min() >= 0.0 and W.max() <= 1.0
    w.undo_action.trigger()
    qtbot.waitUntil(lambda: not w.redraw_pending)
    assert doc.pose_state().equals(before_state) and not doc.is_regional
    np.testing.assert_array_equal(doc.weights, before_state.weights)
    np.testing.assert_array_equal(w.viewport.points(), before_pts)
    w.redo_action.trigger()
    np.testing.assert_array_equal(doc.region_weights, W)
    # the regional pose is the current pose: saved with the project, shown again on reopening
    qtbot.waitUntil(lambda: not w.redraw_pending)
    shown = w.viewport.points().copy()
    np.testing.assert_array_equal(shown, doc.surface())
    assert w.save_to(tmp_path / "regional.bsproj")
    w.document.set_weights(np.zeros(doc.rig.n_shapes))  # another pose in between
    open_and_wait(qtbot, w, tmp_path / "regional.bsproj")
    qtbot.waitUntil(lambda: not w.redraw_pending)
    assert w.document.is_regional and w.document.region_level == c.level
    np.testing.assert_array_equal(w.document.region_weights, W)
    np.testing.assert_allclose(w.viewport.points(), shown, atol=1e-6)
    # Mirror Pose flips a regional pose too: the per-region weights closest to its mirror image; for this
    # drag's pose that is the exact mirror image (measured to 6e-6)
    from app.document import PoseState
    from solvers.symmetry import mirror_map
    doc = w.document
    m, flip = mirror_map(doc.rig.neutral), np.array([-1.0, 1.0, 1.0])
    before = doc.surface().copy()
    n = doc.undo_stack.count()
    assert w.mirror_pose()
    assert doc.is_regional and doc.undo_stack.count() == n + 1
    assert np.abs(doc.surface() - before[m] * flip).max() < 1e-4
    # arbitrary weights in every region: the sample's regions are not all mirror images of each other, and the
    # flip is the nearest regional pose (measured: 3.5 % RMS of the motion)
    rng = np.random.default_rng(1)
    state = PoseState(doc.weights, rng.uniform(0, 0.6, doc.region_weights.shape), doc.region_blend, doc.region_level)
    doc.set_pose_state(state)
    before = doc.surface().copy()
    assert w.mirror_pose()
    err = np.linalg.norm(doc.surface() - before[m] * flip, axis=1)
    motion = np.linalg.norm(before - doc.rig.neutral, axis=1)
    assert np.sqrt((err ** 2).mean()) < 0.05 * np.sqrt((motion ** 2).mean())
    doc.undo_stack.undo()
    np.testing.assert_array_equal(doc.region_weights, state.region_weights)


def test_the_same_drag_moves_the_nose_tip_less_than_a_mouth_corner(qtbot, tmp_path, geometry, nose_tip):
    w = _window(qtbot, tmp_path)
    c = _pins(w, geometry, nose_tip)
    delta = np.array([0.0, 0.6, 0.0])  # 6 mm up in the view plane

    def drag(i):
        P0 = c.marker_positions()
        c.begin_drag(i)
        c.drag_by(delta)
        c.end_drag()
        moved = np.linalg.norm(c.marker_positions()[i] - P0[i])
        w.document.undo_stack.undo()
        return moved

    nose, corner = c.markers.index("M02"), c.markers.index("M00")
    assert c.markers.markers[nose].vertex == nose_tip
    at_nose, at_corner = drag(nose), drag(corner)
    assert at_corner > 0.3
    assert at_nose < 0.3 * at_corner


def test_bad_marker_input(qtbot, tmp_path, geometry, nose_tip):
    w = _window(qtbot, tmp_path)
    c = _pins(w, geometry, nose_tip)
    rig = w.document.rig
    count = len(c.markers)
    # Duplicate: refused, with a message, nothing pushed.
    steps = w.document.undo_stack.count()
    assert not c.add_marker_at(nose_tip)
    assert len(c.markers) == count and w.document.undo_stack.count() == steps
    assert "Marker not added" in w.statusBar().currentMessage() and "same surface point" in c.last_message
    # Background (no shape moves it): allowed, with a message.
    still = int(np.flatnonzero(np.abs(rig.deltas).max(axis=(0, 2)) == 0)[0])
    assert c.add_marker_at(still)
    assert len(c.markers) == count + 1 and "background" in w.statusBar().currentMessage()
    assert "(background)" in w.markers.panel.list.item(count).text()
    # A target far out of reach: the weights stay within [0, 1].
    c.begin_drag(c.markers.index("M00"))
    W = c.drag_by(np.array([-40.0, 60.0, 25.0]))
    c.end_drag()
    assert np.isfinite(W).all() and W.min() >= 0.0 and W.max() <= 1.0
    assert w.document.region_weights.max() == pytest.approx(1.0)


def test_click_adds_right_click_removes_and_markers_are_saved(qtbot, tmp_path, geometry, nose_tip):
    w = _window(qtbot, tmp_path)
    c = w.markers
    assert not w.markers.panel.hint.isHidden()     # an empty list says how to place markers
    w.markers.mode_action.trigger()
    widget = w.viewport.canvas
    corner = int(geometry.mouth.upper[0])
    # A click beside the corner, on the cheek: a marker on the surface where the click was.
    target = w.document.surface()[corner] + np.array([-0.8, 0.4, 0.0], dtype=np.float32)
    q = _screen(w, target[None])[0]
    pos = QtCore.QPoint(round(q.x()), round(q.y()))
    mouse(widget, "press", pos)
    mouse(widget, "release", pos)
    assert len(c.markers) == 1, c.last_message
    P = c.marker_positions()[0]
    q1 = _screen(w, P[None])[0]
    assert abs(q1.x() - pos.x()) < 3 and abs(q1.y() - pos.y()) < 3  # it sits under the click
    assert w.markers.panel.list.count() == 1 and w.markers.overlay.n_markers == 1
    assert w.markers.panel.hint.isHidden()
    w.markers.panel.list.setCurrentRow(0)                 # the Delete key in the list removes it (undoable)
    w.activateWindow()
    w.markers.panel.list.setFocus()
    qtbot.waitUntil(w.markers.panel.list.hasFocus)
    qtbot.keyClick(w.markers.panel.list, QtCore.Qt.Key_Delete)
    assert len(c.markers) == 0
    w.document.undo_stack.undo()
    assert len(c.markers) == 1
    pos2 = QtCore.QPoint(round(q1.x()), round(q1.y()))
    mouse(widget, "press", pos2, buttons=QtCore.Qt.RightButton, button=QtCore.Qt.RightButton)
    mouse(widget, "release", pos2, buttons=QtCore.Qt.RightButton, button=QtCore.Qt.RightButton)
    assert len(c.markers) == 0
    assert not w.markers.panel.hint.isHidden()
    w.document.undo_stack.undo()
    assert len(c.markers) == 1
    _pins(w, geometry, nose_tip)
    names = c.markers.names
    path = tmp_path / "markers.bsproj"
    assert w.save_to(path)
    w.document.undo_stack.undo()
    assert len(c.markers) == len(names) - 1
    open_and_wait(qtbot, w, path)
    assert w.markers.markers.names == names
    np.testing.assert_allclose(w.markers.marker_positions()[0], P, atol=1e-5)


def test_shapes_panel_edits_the_selected_region_of_a_regional_pose(qtbot, tmp_path, geometry, nose_tip):
    w = _window(qtbot, tmp_path)
    c = _pins(w, geometry, nose_tip)
    c.begin_drag(0)
    c.drag_by(np.array([-0.5, 0.5, 0.0]))
    c.end_drag()
    doc = w.document
    assert doc.is_regional and "background row" in w.shapes_panel.target.text()
    seg = w.segmentation
    slider = w.segmentation_panel.level                 # the user steps the level slider with the arrow keys
    for _ in range(abs(c.level - slider.value())):
        qtbot.keyClick(slider, QtCore.Qt.Key_Right if slider.value() < c.level else QtCore.Qt.Key_Left)
    assert slider.value() == c.level and seg.level == c.level
    w.segmentation_panel.region_selected.emit(0)
    qtbot.waitUntil(lambda: doc.edit_region == 0)
    assert "region 0" in w.shapes_panel.target.text()
    before = doc.region_weights.copy()
    k = doc.rig.shape_index("jawOpen")
    w.shapes_panel.row("jawOpen").box.setValue(0.7)
    after = doc.region_weights
    assert after[0, k] == 0.7
    np.testing.assert_array_equal(np.delete(after, 0, axis=0), np.delete(before, 0, axis=0))  # others kept
    w.document.undo_stack.undo()
    np.testing.assert_array_equal(doc.region_weights, before)
    # "Reset all" in the panel resets the selected region only.
    w.shapes_panel.row("jawOpen").box.setValue(0.7)
    w.shapes_panel.reset.click()
    assert not doc.region_weights[0].any()
    np.testing.assert_array_equal(doc.region_weights[1:], before[1:])
    w.document.undo_stack.undo()
    w.document.undo_stack.undo()
    np.testing.assert_array_equal(doc.region_weights, before)
    # Edit ▸ Reset Pose with no region selected makes a global pose; undo brings the regional one back exactly.
    w.segmentation_panel.region_selected.emit(-1)
    # the background row (no marker is on the background here: it keeps its weights)
    assert doc.edit_region is None and np.array_equal(doc.weights, before[-1])
    w.reset_pose()
    assert not doc.is_regional and not doc.weights.any()
    w.document.undo_stack.undo()
    np.testing.assert_array_equal(doc.region_weights, before)


def test_keys_interpolate_play_save_and_export(qtbot, tmp_path, geometry, nose_tip):
    from model.pc2 import read_pc2
    from model.weights_csv import read_weights_csv
    w = _window(qtbot, tmp_path)
    c, k = _pins(w, geometry, nose_tip), w.keyframes
    doc = w.document
    k.scrub(0.0)
    w.keyframes.set_key_action.trigger()
    assert len(k.timeline) == 1 and k.timeline.keys[0].weights.ndim == 1  # a global key
    k.scrub(1.0)  # go to 1 s (shows the key's pose), then pose by dragging and key it
    c.begin_drag(0)
    c.drag_by(np.array([-0.5, 0.6, 0.0]))
    c.end_drag()
    W1 = doc.region_weights.copy()
    k.set_key()
    assert len(k.timeline) == 2 and k.timeline.keys[1].weights.shape == W1.shape  # now regional keys
    np.testing.assert_array_equal(k.timeline.keys[1].weights, W1)
    np.testing.assert_array_equal(k.timeline.keys[0].weights, np.zeros_like(W1))
    k.set_settings(interpolation="linear")
    k.scrub(0.5)
    np.testing.assert_allclose(doc.region_weights, 0.5 * W1)
    assert "◆" not in w.keyframes.panel.time_label.text()
    k.scrub(1.0)
    assert "◆" in w.keyframes.panel.time_label.text()
    # Undo the settings change and the second key.
    doc.undo_stack.undo()
    assert k.timeline.interpolation == "smooth"
    doc.undo_stack.undo()
    assert len(k.timeline) == 1
    doc.undo_stack.redo()
    doc.undo_stack.redo()
    assert len(k.timeline) == 2 and k.timeline.interpolation == "linear"
    # Play advances time.
    k.scrub(0.0)
    w.keyframes.play_action.trigger()
    assert k.playing
    qtbot.waitUntil(lambda: k.time > 0.1, timeout=5000)
    w.keyframes.play_action.trigger()
    assert not k.playing
    # Export.
    csv_path, pc2_path = tmp_path / "keys.csv", tmp_path / "keys.pc2"
    n = k.export_csv(csv_path, per_region=True)
    assert n == int(round(k.duration * k.fps)) + 1
    frames, times, names, Wcsv = read_weights_csv(csv_path)
    assert len(frames) == n and "jawOpen@region0" in names and "jawOpen" in names
    fi = int(round(1.0 * k.fps))
    np.testing.assert_allclose(Wcsv[fi], W1.reshape(-1))
    assert k.export_pc2(pc2_path) == n
    cache, _, _ = read_pc2(pc2_path)
    assert cache.shape == (n, doc.rig.n_vertices, 3)
    np.testing.assert_allclose(cache[0], doc.rig.neutral, atol=1e-5)
    expect = doc.evaluate_state(k.pose_at(1.0), dtype=np.float64)
    np.testing.assert_allclose(cache[fi], expect, atol=1e-5)
    # Saved in the project, and played back the same after reopening.
    path = tmp_path / "keys.bsproj"
    assert w.save_to(path)
    open_and_wait(qtbot, w, path)
    assert len(w.keyframes.timeline) == 2 and w.keyframes.timeline.interpolation == "linear"
    np.testing.assert_array_equal(w.keyframes.timeline.keys[1].weights, W1)
    w.keyframes.scrub(1.0)
    np.testing.assert_allclose(doc.surface(), expect, atol=1e-5)


def test_a_drag_on_a_rig_with_correctives_puts_the_marker_where_it_is_dragged(qtbot, tmp_path, geometry,
                                                                             nose_tip):
    """With jawOpen posed, a corrective on jawOpen + mouthSmile_R doubles the smile at the mouth corner. A drag
    along the smile lands on the cursor when the solve knows the corrective; solving the shapes alone puts
    twice the smile on the face and overshoots."""
    from model.correctives import Corrective, set_correctives
    w = _window(qtbot, tmp_path)
    rig = w.document.rig
    smile = rig.shape_index("mouthSmile_R")
    set_correctives(rig, [Corrective(drivers=["jawOpen", "mouthSmile_R"], delta=rig.deltas[smile].copy())])
    w.document.rig_edited()                    # the surface shown now carries the corrective
    pose = np.zeros(rig.n_shapes)
    pose[rig.shape_index("jawOpen")] = 1.0
    w.document.set_weights(pose)
    c = _pins(w, geometry, nose_tip)
    corner = c.markers.index("M00")
    along = c.markers.positions(rig.deltas[smile])[corner]          # the smile's motion of this corner
    errors = {}
    for aware in (True, False):
        dr = c.begin_drag(corner)
        if not aware:
            dr.correctives = None              # what a shapes-only drag solve would do
        c.drag_by(0.4 * along / dr.gain)       # a target the rig reaches: 0.4 of the smile's motion
        errors[aware] = np.linalg.norm(c.marker_positions()[corner] - dr.targets[corner])
        c.end_drag()
        w.document.undo_stack.undo()
    assert errors[True] < 0.02 * np.linalg.norm(along) < 0.2 * errors[False], errors


def test_the_levels_shapes_per_region_are_found_before_the_first_press(qtbot, tmp_path, geometry, nose_tip,
                                                                       monkeypatch):
    """A drag needs the chosen level's shapes per region (``shape_region_max``, a pass over every shape's deltas:
    0.1 s of a first press's 0.23 s on ICT, the window frozen). Marker mode on (M) finds them on a worker thread;
    the first press takes them from there, and a drag poses the face as before."""
    import app.marker_controller as marker_controller
    from tests.gui_helpers import calls_on_gui_thread
    threads = calls_on_gui_thread(monkeypatch, marker_controller, "shape_region_max")
    w = _window(qtbot, tmp_path)
    c = _pins(w, geometry, nose_tip)
    from tests.test_gui_rigger_habits import _key
    _key(qtbot, w.viewport.canvas, QtCore.Qt.Key_M)
    assert c.mode and threads == [False]
    c.begin_drag(0)
    c.drag_by(np.array([-0.5, 0.5, 0.0]))
    c.end_drag()
    assert threads == [False] and w.document.is_regional and w.document.undo_stack.count() > 0


def test_a_press_before_the_levels_set_up_is_ready_never_freezes_the_window(qtbot, tmp_path, geometry, nose_tip,
                                                                             monkeypatch):
    """What a drag of a level needs is found on a worker thread when Marker Mode or a level is chosen (0.7 s on the
    106k-vertex, 228-shape studio rig). A press before it is done used to wait for it with the window frozen; now
    the press is held (a busy cursor) and the drag starts when the work arrives, from where the mouse has gone,
    even if the button is already up: one undo step either way."""
    import threading
    import app.marker_controller as marker_controller
    from PySide6 import QtWidgets
    gate = threading.Event()
    real = marker_controller.shape_region_max

    def slow_region_max(*args, **kwargs):          # the studio rig's wait, as long as the test wants it
        gate.wait(5.0)
        return real(*args, **kwargs)
    monkeypatch.setattr(marker_controller, "shape_region_max", slow_region_max)
    w = _window(qtbot, tmp_path)
    c = _pins(w, geometry, nose_tip)
    doc, widget, corner = w.document, w.viewport.canvas, 0
    w.markers.mode_action.trigger()
    P0 = c.marker_positions()
    q = _screen(w, P0[corner:corner + 1])[0]
    start = QtCore.QPoint(round(q.x()), round(q.y()))
    drag = QtCore.QPoint(-25, -15)
    steps_before = doc.undo_stack.count()

    t0 = QtCore.QElapsedTimer()
    t0.start()
    mouse(widget, "press", start)
    mouse(widget, "move", start + drag / 2)
    mouse(widget, "move", start + drag)
    assert t0.elapsed() < 1000                         # the window did not wait (before: 5 s, the gate's time out)
    assert c.held is not None and c.drag is None and not doc.is_regional
    assert QtWidgets.QApplication.overrideCursor().shape() == QtCore.Qt.BusyCursor
    gate.set()
    qtbot.waitUntil(lambda: c.drag is not None, timeout=5000)
    assert QtWidgets.QApplication.overrideCursor() is None
    assert doc.is_regional and doc.region_level == c.level
    moved = c.marker_positions()[corner] - P0[corner]
    assert np.linalg.norm(moved) > 0.2 and moved[0] < 0 < moved[1]   # toward the mouse: left and up (cm)
    mouse(widget, "release", start + drag)
    assert doc.undo_stack.count() == steps_before + 1 and c.drag is None

    # A whole click-drag-release before the next level's set-up is ready: played when it is, one undo step.
    gate.clear()
    doc.undo_stack.undo()
    level = c.panel.level
    level.setCurrentIndex(level.findData(c.level + 1))
    mouse(widget, "press", start)
    mouse(widget, "move", start + drag)
    mouse(widget, "release", start + drag)
    assert c.held is not None and c.held.released and not doc.is_regional
    gate.set()
    qtbot.waitUntil(lambda: c.held is None, timeout=5000)
    assert c.drag is None and doc.undo_stack.count() == steps_before + 1
    assert doc.is_regional and doc.region_level == c.level
    assert np.linalg.norm(c.marker_positions()[corner] - P0[corner]) > 0.2
