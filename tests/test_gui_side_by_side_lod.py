"""The Mocap Views' level of detail (``widgets.lod`` in ``widgets.side_by_side``): the faces of a studio-scale rig are
drawn by one decimated proxy in both views while a solved take plays or the camera turns, and in full once still.

ICT FaceKit's views (the captured area, ~27k triangles a view) are below the size at which a proxy is drawn (150k
triangles a render, both views together); the tests lower that size, as tests/test_gui_lod.py does for the viewport,
so that ICT's real solve and real playback exercise the code a 106k-vertex rig runs. ICT at the shipped size is drawn
as before: one render a frame, in full.
"""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from PySide6 import QtCore

from tests.gui_helpers import decimation_until_stopped, mouse, solved_on_ict


def _solved(qtbot, tmp_path, ict_dir, take_dir):
    """The main window on ICT with the real marker take solved, its frame cache filled."""
    w, mc = solved_on_ict(qtbot, tmp_path, ict_dir, take_dir)
    mc.precompute()
    return w, mc


def _still(qtbot, views, quiet: float = 0.5) -> None:
    """Wait until the views drew nothing for ``quiet`` seconds: the next frame is the first after a still moment."""
    import vtk
    last = [time.monotonic()]
    window = views.plotter.ren_win
    tag = window.AddObserver(vtk.vtkCommand.StartEvent, lambda *_: last.__setitem__(0, time.monotonic()))
    try:
        qtbot.waitUntil(lambda: time.monotonic() - last[0] >= quiet, timeout=30000)
    finally:
        window.RemoveObserver(tag)


def _surfaces(views):
    return views.plotter.renderers[0].actors["surface_left"], views.plotter.renderers[1].actors["surface_right"]


def _drawn(views) -> list[tuple[int, int]]:
    """The number of faces each render of the views drew in the left and the right view, recorded as it ends."""
    import vtk
    drawn: list[tuple[int, int]] = []
    left, right = _surfaces(views)
    views.plotter.ren_win.AddObserver(vtk.vtkCommand.EndEvent, lambda *_: drawn.append(
        (left.GetMapper().GetInput().GetNumberOfPolys(), right.GetMapper().GetInput().GetNumberOfPolys())))
    return drawn


def _play(qtbot, mc, views, frames: int = 20) -> tuple[list, list[int]]:
    """Play the take until ``frames`` frames are shown, then pause: (what each render drew, ``_drawn``, the frames
    shown); the renders are recorded on, the frames not."""
    drawn = _drawn(views)
    shown: list[int] = []
    record = shown.append
    mc.frame_shown.connect(record)
    mc.play()
    qtbot.waitUntil(lambda: len(shown) >= frames, timeout=10000)
    mc.pause()
    mc.frame_shown.disconnect(record)
    return drawn, shown


def _array(dataset, name: str) -> np.ndarray:
    from vtkmodules.util.numpy_support import vtk_to_numpy
    return vtk_to_numpy(dataset.GetPointData().GetArray(name))


def _points(dataset) -> np.ndarray:
    from vtkmodules.util.numpy_support import vtk_to_numpy
    return vtk_to_numpy(dataset.GetPoints().GetData())


def test_playing_a_take_draws_both_views_by_one_proxy_then_in_full_once_still(qtbot, tmp_path, ict_dir, take_dir,
                                                                              small_lod):
    w, mc = _solved(qtbot, tmp_path, ict_dir, take_dir)
    views = mc.views
    qtbot.waitUntil(lambda: views.detail.proxy_ready, timeout=60000)
    _still(qtbot, views)
    n_faces = views.left_mesh.GetNumberOfPolys()
    triangles = int(np.maximum(np.asarray(views.left_mesh._faces[0]) - 2, 0).sum())
    drawn, shown = _play(qtbot, mc, views)
    playing = list(drawn)
    assert len(playing) == len(shown), (len(playing), len(shown))      # one render a frame, never two
    assert playing[0] == (n_faces, n_faces), "the first frame follows a still moment: drawn in full"
    proxied = playing[1:]
    assert all(a == b < n_faces for a, b in proxied), proxied          # both views by the proxy
    assert max(a for a, _b in proxied) < 0.35 * triangles, (proxied[-1], triangles)   # ~6k of ~27k
    # the proxy's picture: each view's own surface at the proxy's vertices, the frame shown
    assert views.detail.proxy_shown
    kept = views.detail.proxy_vertices
    left, right = (actor.GetMapper().GetInput() for actor in _surfaces(views))
    assert left is not views.left_mesh and right is not views.right_mesh
    assert left.GetNumberOfPoints() == right.GetNumberOfPoints() == len(kept)
    proj, dense, residual = mc.cache.frame(mc.frame)
    at = kept            # the frame cache holds the shown vertices only: the proxy's are its rows ``kept``
    np.testing.assert_array_equal(_points(left), _points(views.left_mesh)[kept])
    np.testing.assert_array_equal(_points(right), _points(views.right_mesh)[kept])
    np.testing.assert_allclose(_points(left), proj[at], atol=1e-6)
    np.testing.assert_allclose(_points(right), dense[at], atol=1e-6)
    np.testing.assert_array_equal(_array(left, "Normals"), _array(views.left_mesh, "Normals")[kept])
    np.testing.assert_array_equal(_array(right, "Normals"), _array(views.right_mesh, "Normals")[kept])
    np.testing.assert_array_equal(_array(right, "values"), _array(views.right_mesh, "values")[kept])
    np.testing.assert_allclose(_array(right, "values"), residual[at], atol=1e-6)
    # once still, one more render draws both surfaces in full, and nothing more
    qtbot.waitUntil(lambda: len(drawn) > len(playing), timeout=3000)
    qtbot.wait(600)
    assert drawn[len(playing):] == [(n_faces, n_faces)], drawn[len(playing):]
    assert not views.detail.proxy_shown
    left, right = (actor.GetMapper().GetInput() for actor in _surfaces(views))
    assert left is views.left_mesh and right is views.right_mesh


def test_an_orbit_of_the_views_draws_the_proxy_and_ends_in_full_as_the_button_is_released(
        qtbot, tmp_path, ict_dir, take_dir, small_lod):
    w, mc = _solved(qtbot, tmp_path, ict_dir, take_dir)
    views = mc.views
    qtbot.waitUntil(lambda: views.detail.proxy_ready, timeout=60000)
    _still(qtbot, views)
    n_faces = views.left_mesh.GetNumberOfPolys()
    camera = views.plotter.camera_position
    drawn = _drawn(views)
    canvas = views.plotter.interactor
    at = QtCore.QPointF(canvas.width() * 0.1, canvas.height() * 0.5)
    mouse(canvas, "press", at)
    for dx in range(8, 120, 8):
        mouse(canvas, "move", at + QtCore.QPointF(dx, 0))
    assert sum(1 for a, b in drawn if a == b < n_faces) >= 8, drawn       # the orbit drawn by the proxy
    before = len(drawn)
    mouse(canvas, "release", at + QtCore.QPointF(112, 0))
    assert drawn[before:] == [(n_faces, n_faces)], drawn[before:]       # the release's frame in full
    qtbot.wait(600)
    assert len(drawn) == before + 1 and not views.detail.proxy_shown
    assert views.plotter.camera_position != camera


def test_ict_views_are_drawn_in_full_one_render_a_frame_without_a_proxy(qtbot, tmp_path, ict_dir, take_dir):
    w, mc = _solved(qtbot, tmp_path, ict_dir, take_dir)
    views = mc.views
    assert not [t for t in threading.enumerate() if t.name == "surface-proxy"]   # no decimation made
    _still(qtbot, views)        # the dock's first paint after the solve drawn
    n_faces = views.left_mesh.GetNumberOfPolys()
    drawn, shown = _play(qtbot, mc, views)
    qtbot.wait(600)
    assert len(drawn) == len(shown) and set(drawn) == {(n_faces, n_faces)}, (len(drawn), len(shown), set(drawn))
    assert not views.detail.proxy_ready and not views.detail.proxy_shown


@pytest.mark.parametrize("how", ["a new take", "the window closed"])
def test_a_new_take_or_closing_the_window_stops_the_views_proxy_being_made(qtbot, tmp_path, ict_dir, take_dir,
                                                                           small_lod, monkeypatch, how):
    import widgets.lod as lod
    started = threading.Event()
    aborted, making = [], []
    real = lod.proxy_faces

    def slow_proxy(points, counts, indices, target=None, on_filter=None):
        """The viewport's proxy (of the rig's every vertex) made as ever; the views' (of the captured area's
        vertices) a decimation that runs until stopped."""
        if len(points) == 26_719:       # ICT's every vertex
            return real(points, counts, indices, target=target, on_filter=on_filter)
        making.append(threading.current_thread())
        aborted.append(decimation_until_stopped(on_filter, started))
    monkeypatch.setattr(lod, "proxy_faces", slow_proxy)
    w, mc = _solved(qtbot, tmp_path, ict_dir, take_dir)
    assert started.wait(10)
    assert len(making) == 1 and making[0].is_alive()
    t0 = time.monotonic()
    if how == "a new take":
        assert mc.load_take(take_dir / "take.c3d")
        assert mc.views.left_mesh is None
        making[0].join(timeout=5)
    else:
        w.close()
    assert not making[0].is_alive() and time.monotonic() - t0 < 2
    assert aborted == [1]
