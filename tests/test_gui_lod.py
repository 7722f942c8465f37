"""The viewport's level of detail (``widgets.lod``): a studio-scale surface is drawn by a decimated proxy over its own
vertices while a slider is dragged, and in full once the view is still.

ICT FaceKit (53k triangles) is below the size at which the viewport uses a proxy (150k); these tests lower that
size so that ICT's real surface and a real slider drag exercise the same code a 422k-vertex rig runs.
"""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from solvers.mesh import fan_triangulate
from tests.gui_helpers import decimation_until_stopped, make_window, mouse, open_and_wait, press_shape_slider, \
    wait_until_still


def _areas(points, tris):
    p = np.asarray(points, dtype=np.float64)
    return 0.5 * np.linalg.norm(np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]]), axis=1)


def test_the_proxy_is_a_decimation_of_the_surface_over_its_own_vertices(ict_rig):
    from scipy.sparse.csgraph import connected_components
    import scipy.sparse as sp

    from widgets.lod import proxy_faces
    rig = ict_rig
    full = fan_triangulate(rig.face_counts, rig.face_indices).astype(np.int64)
    proxy = proxy_faces(rig.neutral, rig.face_counts, rig.face_indices, target=20_000)
    assert np.all(np.diff(proxy.vertices) > 0) and proxy.vertices[-1] < rig.n_vertices
    assert proxy.triangles.min() == 0 and proxy.triangles.max() == len(proxy.vertices) - 1
    tris = proxy.vertices[proxy.triangles]                      # over the rig's own vertex ids
    assert abs(len(tris) - 20_000) < 2_000, len(tris)
    # the same surface: its area within 2% (triangles over the wrong vertices would span the head)
    assert abs(_areas(rig.neutral, tris).sum() / _areas(rig.neutral, full).sum() - 1) < 0.02
    # every proxy triangle joins vertices of one connected part of the rig (teeth, eyes, skin stay apart)
    n = rig.n_vertices
    adjacency = sp.coo_matrix((np.ones(full.size), (full.ravel(), np.roll(full, 1, axis=1).ravel())), shape=(n, n))
    _, part = connected_components(adjacency, directed=False)
    assert np.all(part[tris[:, 0]] == part[tris[:, 1]]) and np.all(part[tris[:, 0]] == part[tris[:, 2]])
    # facing as the surface faces: each proxy triangle's normal agrees with its corners' vertex normals
    p = np.asarray(rig.neutral, dtype=np.float64)
    vn = np.zeros_like(p)
    fn = np.cross(p[full[:, 1]] - p[full[:, 0]], p[full[:, 2]] - p[full[:, 0]])
    for k in range(3):
        np.add.at(vn, full[:, k], fn)
    tn = np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]])
    agree = np.einsum("ij,ij->i", tn, vn[tris].sum(axis=1)) > 0
    assert agree.mean() > 0.98, agree.mean()
    # its normals from the faces around its vertices only: the whole surface's display normals there, in a pose
    from solvers.normals import VertexNormals
    posed = rig.neutral + 1.0 * rig.deltas[rig.shape_index("jawOpen")]
    whole = VertexNormals(rig.face_counts, rig.face_indices, rig.n_vertices)(posed)
    np.testing.assert_allclose(proxy.normals(posed), whole[proxy.vertices], atol=1e-6)


def test_a_proxy_made_once_is_read_back_from_the_cache_the_same(ict_rig, tmp_path, monkeypatch):
    """A studio rig opened again has its proxy at once: the decimation's triangles are kept in the cache folder,
    keyed by the points, faces and target, and give the same ProxyFaces; another pose or target makes its own."""
    import widgets.lod as lod
    rig, folder = ict_rig, tmp_path / "lod"
    made = lod.proxy_faces(rig.neutral, rig.face_counts, rig.face_indices, target=20_000, cache=folder)
    assert len(list(folder.glob("*.npy"))) == 1

    def no_decimation(*args):
        raise AssertionError("decimated again")
    monkeypatch.setattr(lod, "_decimate", no_decimation)
    read = lod.proxy_faces(rig.neutral, rig.face_counts, rig.face_indices, target=20_000, cache=folder)
    for name in ("vertices", "triangles", "back_faces", "ring", "kept_in_ring"):
        np.testing.assert_array_equal(getattr(read, name), getattr(made, name))
    np.testing.assert_array_equal(read.normals(rig.neutral), made.normals(rig.neutral))
    with pytest.raises(AssertionError, match="decimated again"):     # another target: not the cached one
        lod.proxy_faces(rig.neutral, rig.face_counts, rig.face_indices, target=19_000, cache=folder)
    moved = rig.neutral.copy()
    moved[0, 0] += 0.5
    with pytest.raises(AssertionError, match="decimated again"):     # another pose: not the cached one
        lod.proxy_faces(moved, rig.face_counts, rig.face_indices, target=20_000, cache=folder)


@pytest.mark.parametrize("damage", ["truncated", "ids beyond the surface", "not triangles", "not an array"])
def test_a_damaged_cache_entry_is_made_again_and_an_unwritable_cache_is_no_error(ict_rig, tmp_path, damage):
    import widgets.lod as lod
    rig, folder = ict_rig, tmp_path / "lod"
    made = lod.proxy_faces(rig.neutral, rig.face_counts, rig.face_indices, target=20_000, cache=folder)
    entry = next(folder.glob("*.npy"))
    if damage == "truncated":
        entry.write_bytes(entry.read_bytes()[:1000])
    elif damage == "ids beyond the surface":
        np.save(entry, np.full((10, 3), rig.n_vertices, np.int32))
    elif damage == "not triangles":
        np.save(entry, np.zeros((10, 4), np.int32))
    else:
        entry.write_bytes(b"not a numpy file at all")
    again = lod.proxy_faces(rig.neutral, rig.face_counts, rig.face_indices, target=20_000, cache=folder)
    np.testing.assert_array_equal(again.triangles, made.triangles)
    np.testing.assert_array_equal(np.load(entry), lod._cached_triangles(folder, entry.stem, rig.n_vertices))
    blocked = tmp_path / "a file"
    blocked.write_text("")
    unwritable = lod.proxy_faces(rig.neutral, rig.face_counts, rig.face_indices, target=20_000, cache=blocked / "lod")
    np.testing.assert_array_equal(unwritable.vertices, made.vertices)


def _drawn_faces(w):
    """The number of faces each render of the viewport drew (its surface actor's), recorded as it ends."""
    import vtk
    drawn = []
    surface = w.viewport.plotter.actors["surface"]
    w.viewport.plotter.ren_win.AddObserver(
        vtk.vtkCommand.EndEvent, lambda *_: drawn.append(surface.GetMapper().GetInput().GetNumberOfPolys()))
    return drawn


def _drag_jaw(qtbot, w, moves=12):
    slider, start = press_shape_slider(qtbot, w, w.shapes_panel.row("jawOpen"))
    x = start.x()
    for _ in range(moves):
        x += 2
        mouse(slider, "move", QtCore.QPoint(x, start.y()))
        qtbot.waitUntil(lambda: not w.redraw_pending, timeout=5000)
    mouse(slider, "release", QtCore.QPoint(x, start.y()))


def test_a_slider_drag_draws_the_proxy_then_the_full_surface_once_still(qtbot, tmp_path, ict_dir, small_lod):
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    wait_until_still(qtbot, w)                        # the next change is drawn in full
    n_faces = w.viewport.mesh.GetNumberOfPolys()      # the faces shown (ICT hides some parts)
    drawn = _drawn_faces(w)
    _drag_jaw(qtbot, w)
    assert drawn[0] == n_faces, "the drag's first frame follows a still moment: drawn in full"
    proxied = [n for n in drawn[1:] if n < n_faces]
    assert len(proxied) >= 8, drawn
    shown = w.viewport.shown_faces if w.viewport.shown_faces is not None else slice(None)
    triangles = int((w.document.rig.face_counts[shown] - 2).sum())
    assert max(proxied) < 0.35 * triangles, (max(proxied), triangles)   # ~12-15k of ICT's 51k shown
    # once still, one more render draws the surface in full, and nothing more
    qtbot.waitUntil(lambda: drawn[-1] == n_faces, timeout=3000)
    count = len(drawn)
    qtbot.wait(600)
    assert len(drawn) == count
    assert not w.viewport.detail.proxy_shown
    # what was drawn is the pose: every vertex kept, in order
    k = w.document.rig.shape_index("jawOpen")
    assert w.document.weights[k] > 0.05
    np.testing.assert_allclose(w.viewport.points(), w.document.surface(), atol=1e-4)
    assert w.viewport.plotter.actors["surface"].GetMapper().GetInput() is w.viewport.mesh
    # the frames the proxy drew left the surface's own normals for later: they are the pose's again
    mesh = w.viewport.mesh
    np.testing.assert_allclose(mesh.point_data["Normals"], w.viewport.normals_function()(mesh.points), atol=1e-6)


def test_the_wireframe_is_drawn_with_the_surfaces_own_faces_while_dragging(qtbot, tmp_path, ict_dir, small_lod):
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    w.viewport.set_wireframe(True)
    wait_until_still(qtbot, w)
    drawn = _drawn_faces(w)
    _drag_jaw(qtbot, w, moves=6)
    assert len(drawn) >= 6 and set(drawn) == {len(w.viewport.shown_faces)}


def test_a_click_right_after_a_drag_picks_the_surfaces_own_vertex(qtbot, tmp_path, ict_dir, small_lod):
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    wait_until_still(qtbot, w)
    vp = w.viewport
    _drag_jaw(qtbot, w, moves=3)
    assert vp.detail.proxy_shown            # the last frame of the drag drew the proxy
    x, y = (int(v) for v in vp.world_to_display(w.document.surface()[[964]])[0][:2])   # ICT's chin
    got = vp.pick(x, y)
    qtbot.waitUntil(lambda: not vp.detail.proxy_shown, timeout=3000)
    qtbot.wait(100)
    still = vp.pick(x, y)                   # the same pose, drawn in full
    assert still is not None and got is not None
    assert (got.face, got.vertex) == (still.face, still.vertex)
    assert np.linalg.norm(w.document.surface()[still.vertex] - w.document.surface()[964]) < 0.5


def test_closing_the_window_stops_a_proxy_being_made(qtbot, tmp_path, ict_dir, small_lod, monkeypatch):
    import threading
    import time

    import widgets.lod as lod
    started = threading.Event()

    def slow_proxy(points, counts, indices, target=None, on_filter=None):   # a decimation that runs until stopped
        decimation_until_stopped(on_filter, started)
    monkeypatch.setattr(lod, "proxy_faces", slow_proxy)
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    assert started.wait(10)
    making = [t for t in threading.enumerate() if t.name == "surface-proxy"]
    assert making and making[0].is_alive()
    t0 = time.monotonic()
    w.viewport.close_viewport()
    assert not making[0].is_alive() and time.monotonic() - t0 < 2


@pytest.mark.parametrize("view", ["shaded", "deformation"])
def test_the_proxy_frame_looks_like_the_full_frame_of_the_same_pose(qtbot, tmp_path, ict_dir, small_lod, view,
                                                                   monkeypatch):
    import widgets.lod as lod
    monkeypatch.setattr(lod, "LOD_TARGET_TRIANGLES", 30_000)    # as a studio rig's proxy is to it: a face's detail
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    vp = w.viewport
    if view == "deformation":     # a colour map over every vertex: its colours are gathered with the points
        sp = w.segmentation_panel
        sp.view.setCurrentIndex(sp.view.findData("deformation"))
        sp.shape.setCurrentIndex(sp.shape.findText("jawOpen"))
        w.segmentation.wait()
        qtbot.waitUntil(lambda: vp.colormap is not None, timeout=10000)
    wait_until_still(qtbot, w)

    def picture():
        return np.asarray(vp.plotter.screenshot(None, return_img=True), dtype=np.float64)

    neutral = picture()
    _drag_jaw(qtbot, w, moves=20)
    assert vp.detail.proxy_shown
    proxy = picture()
    assert vp.detail.proxy_shown
    qtbot.waitUntil(lambda: not vp.detail.proxy_shown, timeout=3000)
    qtbot.wait(100)
    full = picture()
    moved = np.abs(full - neutral).mean()
    off = np.abs(full - proxy).mean()
    assert moved > 0.3, moved                 # the jaw moved on screen
    # the proxy draws that pose, lit and coloured as the surface is (coarser: a proxy left at the neutral pose
    # would differ by about ``moved``, one without the colours or normals by far more)
    assert off < 0.5 * moved, (off, moved)


def test_only_the_decimation_runs_at_the_lowest_priority():
    import os
    import sys
    import threading

    from widgets.lod import _run_at_low_priority
    if not sys.platform.startswith("linux"):
        pytest.skip("a thread's own priority is Linux's")
    seen = []
    before = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    _run_at_low_priority(lambda: seen.append(os.getpriority(os.PRIO_PROCESS, threading.get_native_id())))
    assert seen == [19]
    # the caller (the thread running the numpy around the filter, holding the GIL) keeps its priority
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == before


def test_quitting_while_the_proxy_is_started_stops_it_at_once(qtbot, tmp_path, ict_dir, small_lod, monkeypatch):
    """File ▸ Quit (Ctrl+Q) in the moment after a rig opens, before the decimation filter exists (the surface's
    arrays are copied first: 0.4 s at 422k vertices): the window closes at once and no decimation runs after it (it
    waited 5 s for a stopped decimation that then ran to its end, 6 s at 422k)."""
    import threading
    import time

    from PySide6.QtTest import QTest

    import widgets.lod as lod
    copying, never = threading.Event(), threading.Event()
    aborted = []
    real = lod.proxy_faces

    def slow_start(*args, on_filter=None, **kwargs):
        copying.set()
        never.wait(0.5)                   # the surface's arrays being copied: no filter yet

        def made(decimate):
            on_filter(decimate)
            aborted.append(decimate.GetAbortExecute())    # as it is about to run
        return real(*args, on_filter=made, **kwargs)
    monkeypatch.setattr(lod, "proxy_faces", slow_start)
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    assert copying.wait(10)
    making = [t for t in threading.enumerate() if t.name == "surface-proxy" and t.is_alive()]
    assert making and w.viewport.detail._running[1] is None      # no filter yet
    w.activateWindow()
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is w, timeout=5000)
    t0 = time.monotonic()
    QTest.keyClick(QtWidgets.QApplication.focusWidget() or w, QtCore.Qt.Key_Q, QtCore.Qt.ControlModifier)
    QtWidgets.QApplication.processEvents()
    closed = time.monotonic() - t0
    assert not w.isVisible()
    assert closed < 1.0, closed
    for t in making:
        t.join(timeout=10)
    assert aborted == [1], "the stopped proxy's decimation ran after the window closed"


def _sculpting(qtbot, w):
    """Sculpt mode on ICT (the brow pair posed), the proxy ready and the view still; the canvas and the display
    (Qt) position of a forehead vertex."""
    ctrl = w.correctives
    assert ctrl.start_authoring(["browInnerUp_L", "browInnerUp_R"])
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready and not w.redraw_pending, timeout=60000)
    wait_until_still(qtbot, w)
    vp = w.viewport
    surface = w.document.surface()
    front = np.flatnonzero(np.abs(surface[:, 0]) < 1.0)
    v = int(front[np.argmax(surface[front, 2] + 0.2 * surface[front, 1])])   # the forehead, towards the camera
    xd, yd, _ = vp.world_to_display(surface[[v]])[0]
    return vp.canvas, vp.display_to_qt(xd, yd)


def test_a_brush_hover_leaving_the_face_ends_on_the_full_surface(qtbot, tmp_path, ict_dir, small_lod):
    """Sculpt mode: the brush cursor follows the mouse over the face (each hover picks the surface, then draws the
    cursor: frames close together, the proxy's), then the mouse leaves the face: the cursor is hidden, and the
    next hovers pick nothing and draw nothing. Once still, the full surface is drawn: the hover's pick had put the
    surface's own faces back without a render, and the still render, going by the actors' inputs, never came: the
    proxy's picture stayed on screen."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    canvas, at = _sculpting(qtbot, w)
    drawn = _drawn_faces(w)
    n_faces = w.viewport.mesh.GetNumberOfPolys()
    for dx in range(0, 40, 4):
        mouse(canvas, "move", at + QtCore.QPointF(dx, 0), buttons=QtCore.Qt.NoButton)
        qtbot.wait(20)
    assert min(drawn) < n_faces, drawn           # the hovers over the face drew the proxy
    for k in range(4):                           # off the face: the viewport's corner
        mouse(canvas, "move", QtCore.QPointF(6 + 3 * k, 6), buttons=QtCore.Qt.NoButton)
        qtbot.wait(20)
    assert not w.viewport.plotter.actors["brush_cursor"].GetVisibility()
    qtbot.wait(800)
    assert drawn[-1] == n_faces, drawn[-6:]
    assert not w.viewport.detail.proxy_shown


def test_a_brush_stroke_on_the_proxy_computes_no_normals_of_the_whole_surface(qtbot, tmp_path, ict_dir, small_lod):
    """An inflate stroke: each mouse move picks the surface under the brush (on its own faces) and dabs; its frames,
    close together, are the proxy's, lit by the proxy's normals. The pick needs only the faces: it computed the
    whole surface's normals at each move all the same (47 ms a move at 422k vertices), for frames that never drew
    them. Once still, the surface is drawn in full with its normals for the pose."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    canvas, at = _sculpting(qtbot, w)
    w.correctives.set_brush("inflate")
    vp = w.viewport
    whole = []
    normals_of = vp._arrays._normals_of
    vp._arrays._normals_of = lambda points: (whole.append(1), normals_of(points))[1]
    drawn = _drawn_faces(w)
    mouse(canvas, "press", at)
    counts = []
    for dx in range(2, 26, 2):
        mouse(canvas, "move", at + QtCore.QPointF(dx, 0))
        qtbot.waitUntil(lambda: not w.redraw_pending, timeout=5000)
        counts.append(len(whole))
    mouse(canvas, "release", at + QtCore.QPointF(24, 0))
    n_faces = vp.mesh.GetNumberOfPolys()
    assert sum(1 for n in drawn if n < n_faces) >= 8, drawn       # the stroke drawn by the proxy
    assert counts[-1] - counts[2] == 0, counts
    qtbot.waitUntil(lambda: drawn[-1] == n_faces and not vp.detail.proxy_shown, timeout=3000)
    mesh = vp.mesh
    np.testing.assert_allclose(mesh.point_data["Normals"], vp.normals_function()(mesh.points), atol=1e-6)


def test_export_image_right_after_a_drag_draws_the_full_surface_and_leaves_it(qtbot, tmp_path, ict_dir, small_lod,
                                                                             monkeypatch):
    """File ▸ Export Image (Ctrl+Shift+E, the size dialog's OK clicked) right after a slider drag drawn by
    the proxy: the picture is of the full surface, and so is the view the export leaves. The render putting the view
    back after the picture came close after it: it drew the proxy, and the full surface again 0.3 s later (a full
    and a proxy frame more, and the view flickering to the proxy and back)."""
    from PIL import Image
    from PySide6.QtTest import QTest
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    wait_until_still(qtbot, w)
    vp = w.viewport
    path = tmp_path / "after_drag.png"
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName", lambda *a, **k: (str(path), ""))
    _drag_jaw(qtbot, w, moves=6)
    assert vp.detail.proxy_shown
    drawn = _drawn_faces(w)
    w.activateWindow()
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is w, timeout=3000)
    vp.canvas.setFocus()
    QTest.keyClick(vp.canvas, QtCore.Qt.Key_E, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    qtbot.waitUntil(lambda: w.image_size_dialog is not None and w.image_size_dialog.isVisible(), timeout=3000)
    ok = w.image_size_dialog.findChild(QtWidgets.QDialogButtonBox).button(QtWidgets.QDialogButtonBox.Ok)
    QTest.mouseClick(ok, QtCore.Qt.LeftButton)
    w.jobs.wait()
    qtbot.waitUntil(path.exists, timeout=5000)
    n_faces = vp.mesh.GetNumberOfPolys()
    assert drawn and set(drawn) == {n_faces}, drawn        # the picture's frames and the view's after it
    assert not vp.detail.proxy_shown
    wait_until_still(qtbot, w)
    assert set(drawn) == {n_faces}, drawn                  # and no still render: the view was drawn in full
    still = vp.picture()
    picture = np.asarray(Image.open(path).convert("RGB"))
    assert picture.shape == still.shape
    assert np.abs(picture.astype(float) - still).mean() < 0.5


def test_a_click_adding_a_marker_draws_one_full_frame(qtbot, tmp_path, ict_dir, small_lod):
    """Marker Mode: a click on the face adds a marker, drawn by the click's own frame (VTK renders as the button is
    released). The window's redraw of the unchanged pose drew it again close after: that second frame was the
    proxy's, and the full surface came back 0.3 s later (three frames, the face flickering coarse at every click)."""
    from PySide6.QtTest import QTest
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    QTest.mouseClick(w.marker_mode_button, QtCore.Qt.LeftButton)
    mc = w.markers
    assert mc.mode
    qtbot.waitUntil(lambda: not mc.unfinished_jobs(patience=0.0) and not w.redraw_pending, timeout=30000)
    wait_until_still(qtbot, w)
    vp = w.viewport
    drawn = _drawn_faces(w)
    n_faces = vp.mesh.GetNumberOfPolys()
    surface = w.document.surface()
    import time

    import vtk
    last = [time.monotonic()]
    vp.plotter.ren_win.AddObserver(vtk.vtkCommand.EndEvent, lambda *_: last.__setitem__(0, time.monotonic()))
    for k, v in enumerate((964, 1500)):             # ICT's chin, then a second marker on the face
        xd, yd, _ = vp.world_to_display(surface[[v]])[0]
        at = vp.display_to_qt(xd, yd)
        qtbot.waitUntil(lambda: time.monotonic() - last[0] > 0.5, timeout=5000)   # nothing drawn a moment before
        before = len(drawn)
        mouse(vp.canvas, "press", at)
        mouse(vp.canvas, "release", at)
        qtbot.waitUntil(lambda: len(mc.markers) == k + 1, timeout=3000)
        qtbot.wait(600)
        assert drawn[before:] == [n_faces], ("click", k, drawn[before:])
    assert not vp.detail.proxy_shown


def test_an_orbit_ends_on_the_full_surface_as_the_button_is_released(qtbot, tmp_path, ict_dir, small_lod):
    """The camera turned with the mouse (VTK's trackball renders each move: the proxy's frames), then the button
    released: VTK's frame for the release, the end of the interaction, draws the full surface at once, and no still
    render follows. It drew the proxy, and the full surface 0.3 s later."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    wait_until_still(qtbot, w)
    vp = w.viewport
    drawn = _drawn_faces(w)
    n_faces = vp.mesh.GetNumberOfPolys()
    camera = vp.camera_frame().position
    at = QtCore.QPointF(vp.canvas.width() * 0.3, vp.canvas.height() * 0.5)     # beside the face: the camera turns
    mouse(vp.canvas, "press", at)
    for dx in range(8, 120, 8):
        mouse(vp.canvas, "move", at + QtCore.QPointF(dx, 0))
    assert sum(1 for n in drawn if n < n_faces) >= 8, drawn          # the orbit drawn by the proxy
    before = len(drawn)
    mouse(vp.canvas, "release", at + QtCore.QPointF(112, 0))
    assert drawn[before:] == [n_faces], ("orbit", drawn[before:])
    assert not vp.detail.proxy_shown
    qtbot.wait(600)
    assert len(drawn) == before + 1
    assert not np.allclose(vp.camera_frame().position, camera)
    # a zoom with the right button and a pan with the middle one end so too, and end (the camera stays after them)
    for button in (QtCore.Qt.RightButton, QtCore.Qt.MiddleButton):
        camera = vp.camera_frame().position
        mouse(vp.canvas, "press", at, buttons=button, button=button)
        for dy in range(6, 60, 6):
            mouse(vp.canvas, "move", at + QtCore.QPointF(0, dy), buttons=button, button=button)
        before = len(drawn)
        mouse(vp.canvas, "release", at + QtCore.QPointF(0, 54), buttons=button, button=button)
        assert drawn[before:] == [n_faces], (button, drawn[before:])
        moved = vp.camera_frame().position
        assert not np.allclose(moved, camera)
        mouse(vp.canvas, "move", at + QtCore.QPointF(30, 90), buttons=QtCore.Qt.NoButton)
        np.testing.assert_allclose(vp.camera_frame().position, moved)      # the button's interaction is over


def test_a_texture_shown_again_after_a_drag_under_a_colour_map_is_lit_for_the_pose(qtbot, tmp_path, monkeypatch):
    """The sample's texture chosen, then a colour map (the deformation view) over it: the surface is the plain mesh
    again, and a slider drag is drawn by the proxy, its frames leaving the surface's normals for later. The Shaded
    view back: the textured surface is drawn lit by the normals of the pose it shows. It took the surface's normals
    at each frame of the drag, the deferred ones: lit for the pose before the drag until the next pose change."""
    import widgets.lod as lod
    from tests.test_textures_gui import _choose
    monkeypatch.setattr(lod, "LOD_MIN_TRIANGLES", 10_000)     # the sample's 25k triangles take a proxy
    monkeypatch.setattr(lod, "LOD_TARGET_TRIANGLES", 6_000)
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    _choose(qtbot, w, "band-pass")
    vp = w.viewport
    assert vp.textured
    sp = w.segmentation_panel
    sp.view.setCurrentIndex(sp.view.findData("deformation"))
    w.segmentation.wait()
    qtbot.waitUntil(lambda: vp.colormap is not None and vp.detail.proxy_ready, timeout=60000)
    assert not vp.textured
    wait_until_still(qtbot, w)
    drawn = _drawn_faces(w)
    _drag_jaw(qtbot, w, moves=12)
    assert sum(1 for n in drawn if n < vp.mesh.GetNumberOfPolys()) >= 6, drawn
    sp.view.setCurrentIndex(sp.view.findData("shaded"))
    qtbot.waitUntil(lambda: vp.textured and not w.redraw_pending, timeout=10000)
    textured = vp._textured.mesh
    expected = vp.normals_function()(vp.mesh.points)[vp._textured.vertex]
    np.testing.assert_allclose(textured.point_data["Normals"], expected, atol=1e-5)


def test_a_rig_opened_again_draws_its_proxy_without_decimating_again(qtbot, tmp_path, ict_dir, small_lod,
                                                                     monkeypatch):
    """The window's proxies go through the cache (``widgets.lod.cache_folder``): ICT opened a second time drags with
    its proxy from the first move, no decimation run (7-14 s at 422k vertices)."""
    import widgets.lod as lod
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=60000)
    decimated = []
    real = lod._decimate
    monkeypatch.setattr(lod, "_decimate", lambda *a: decimated.append(1) or real(*a))
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.viewport.detail.proxy_ready, timeout=10000)
    assert decimated == []
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=60000)
    wait_until_still(qtbot, w)
    n_faces = w.viewport.mesh.GetNumberOfPolys()
    drawn = _drawn_faces(w)
    _drag_jaw(qtbot, w, moves=4)
    triangles = int((w.document.rig.face_counts[w.viewport.shown_faces] - 2).sum())
    assert drawn[0] == n_faces and drawn[1] < 0.35 * triangles, drawn   # the second move on: the proxy's faces
