"""The Mocap Views' frame cache right after a solve (``app.mocap_frames``): a worker fills it from the playhead on,
and the window never computes a frame itself -- on a 106k-vertex rig a frame froze it 0.2-0.46 s, on the 422k one
~1.1 s. While a frame is not filled the views show the nearest filled one (said in the panel); once still they show
the frame's own result. The cache holds the vertices the views draw only; exports take the whole surface from the
solution. Also the Qt-free fill order and nearest frame, against plain references."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from tests.gui_helpers import solved_on_ict


# --- Qt-free: the fill order and the nearest filled frame --------------------------------------------------------
def _reference_fill(ready: list[bool], playhead: int, block: int) -> list[int]:
    """Walk from the playhead round the take to the first frame not ready, then on while frames are not ready."""
    n = len(ready)
    p = min(max(playhead, 0), n - 1)
    for k in range(n):
        f = (p + k) % n
        if not ready[f]:
            out = []
            while f < n and not ready[f] and len(out) < block:
                out.append(f)
                f += 1
            return out
    return []


def _reference_nearest(ready: list[bool], frame: int):
    best = None
    for f, r in enumerate(ready):
        if r and (best is None or abs(f - frame) < abs(best - frame)):
            best = f
    return best


def test_frames_to_fill_and_nearest_ready_match_plain_walks():
    from app.mocap_frames import frames_to_fill, nearest_ready
    rng = np.random.default_rng(7)
    for _ in range(2000):
        n = int(rng.integers(1, 40))
        ready = rng.random(n) < rng.random()
        playhead, block = int(rng.integers(-2, n + 2)), int(rng.integers(1, 6))
        assert frames_to_fill(ready, playhead, block) == _reference_fill(list(ready), playhead, block)
        frame = int(rng.integers(0, n))
        assert nearest_ready(ready, frame) == _reference_nearest(list(ready), frame)
    assert frames_to_fill(np.ones(5, bool), 2, 4) == [] and nearest_ready(np.zeros(5, bool), 2) is None


@pytest.fixture(scope="module")
def ict_solution(ict_rig, take_dir):
    from model.marker_map import load_marker_map
    from model.take_workspace import TakeWorkspace
    ws = TakeWorkspace(ict_rig)
    ws.load_take(take_dir / "take.c3d")
    ws.set_map(load_marker_map(take_dir / "marker_map.json"))
    return ws.solve_detached({}), ws.take


def test_the_cache_follows_the_playhead_and_holds_the_shown_vertices_of_each_frame(ict_rig, ict_solution):
    """A fill starts at the playhead and goes on from wherever it is moved; each frame, filled in a block (one
    matrix product) or alone, is the solution's projection and dense result at the shown vertices."""
    from app.mocap_frames import FrameCache, captured_area_faces, frames_to_fill
    from solvers.normals import VertexNormals, compact_faces
    sol, take = ict_solution
    counts, indices = captured_area_faces(ict_rig, sol.solver.residual_vertices)
    shown, local = compact_faces(indices)
    cache = FrameCache(sol, take, ict_rig.units, normals=VertexNormals(counts, local, len(shown)), shown=shown)
    assert cache.projection.shape == (sol.n_frames, len(shown), 3) and len(shown) < ict_rig.n_vertices
    blocks: list[list[int]] = []
    cache.playhead = 200

    def filled(frames):
        blocks.append(frames)
        if len(blocks) == 3:
            cache.playhead = 40          # the user scrubs: the next block starts there
        if len(blocks) == 5:
            stop.set()
    stop = threading.Event()
    cache.fill(stop, filled)
    assert blocks == [[200, 201, 202, 203], [204, 205, 206, 207], [208, 209, 210, 211], [40, 41, 42, 43],
                      [44, 45, 46, 47]]
    assert cache.ready.sum() == 20 and not cache.is_ready(0)
    cache.frame(0)                                       # one frame alone: the pose, not the batch product
    for f in (0, 41, 203):
        proj, dense = sol.projection(f), sol.dense(f)
        p, d, r = cache.frame(f)
        np.testing.assert_allclose(p, proj[shown], atol=1e-5)
        np.testing.assert_allclose(d, dense[shown], atol=1e-5)
        np.testing.assert_allclose(r, np.linalg.norm(dense - proj, axis=1)[shown] * 10.0, atol=1e-4)   # cm -> mm
        pn, dn = cache.normals(f)
        assert pn.shape == dn.shape == (len(shown), 3) and pn.dtype == np.int8
    assert cache.nearest_ready(100) == 47 and cache.nearest_ready(180) == 200
    assert not cache.wait_ready(300, 0.01) and cache.wait_ready(41, 0.0)
    # playing, the next block starts where the playhead will be once it is computed (wrapping round the take)
    cache.playhead, cache.speed, cache._block_seconds = 355, 60.0, 0.1
    assert cache.fill_start() == 3 and frames_to_fill(cache.ready, cache.fill_start(), 4) == [3, 4, 5, 6]
    cache.speed = 0.0
    assert cache.fill_start() == 355


# --- the window -----------------------------------------------------------------------------------------------------
def _solved_with_a_slow_cache(qtbot, tmp_path, ict_dir, take_dir, monkeypatch):
    """The window on ICT with the marker take solved, each frame-cache computation made 0.25 s slower (a studio rig's
    frame) and recorded with whether it ran on the GUI thread."""
    from app.mocap_frames import FrameCache
    on_gui: list[bool] = []
    original = FrameCache._compute

    def slow(self, *args, **kwargs):
        on_gui.append(threading.current_thread() is threading.main_thread())
        time.sleep(0.25)
        return original(self, *args, **kwargs)
    monkeypatch.setattr(FrameCache, "_compute", slow)
    w, mc = solved_on_ict(qtbot, tmp_path, ict_dir, take_dir)
    return w, mc, on_gui


def _assert_shows_its_own_frame(qtbot, mc) -> None:
    """Once still, the views come to show the frame the playhead is at: the solution's own surfaces there."""
    qtbot.waitUntil(lambda: getattr(mc, "views_frame", mc.frame) == mc.frame, timeout=20000)
    f, sol, views = mc.frame, mc.solution, mc.views
    at = views.shown_vertices
    proj, dense = sol.projection(f), sol.dense(f)
    np.testing.assert_allclose(np.asarray(views.left_mesh.points), proj[at], atol=1e-4)
    np.testing.assert_allclose(np.asarray(views.right_mesh.points), dense[at], atol=1e-4)
    np.testing.assert_allclose(np.asarray(views.right_mesh.point_data["values"]),
                               np.linalg.norm(dense - proj, axis=1)[at] * 10.0, atol=1e-3)
    np.testing.assert_allclose(np.asarray(views.marker_cloud.points)[:len(sol.labels)],
                               np.where(np.isfinite(mc.cache.markers[f]), mc.cache.markers[f], mc.cache.fitted[f]),
                               atol=1e-4)


def test_right_after_a_solve_playing_and_scrubbing_never_compute_a_frame_on_the_gui_thread(
        qtbot, tmp_path, ict_dir, take_dir, monkeypatch):
    from PySide6 import QtCore
    w, mc, on_gui = _solved_with_a_slow_cache(qtbot, tmp_path, ict_dir, take_dir, monkeypatch)
    solved_status = mc.panel.status_label.text()
    assert solved_status.startswith("Solved 358 frames")
    on_gui.clear()
    turns: list[float] = []
    probe = QtCore.QTimer()
    probe.setInterval(5)
    probe.timeout.connect(lambda: turns.append(time.perf_counter()))
    probe.start()
    shown: list[int] = []
    said: list[str] = []
    mc.frame_shown.connect(shown.append)
    mc.frame_shown.connect(lambda _f: said.append(mc.panel.status_label.text()))
    mc.play()
    qtbot.waitUntil(lambda: len(shown) >= 30, timeout=20000)
    mc.pause()
    _assert_shows_its_own_frame(qtbot, mc)
    for f in (300, 120, 7, 250):                   # scrubbed: the slider, the curves, the keyboard all set_frame
        mc.set_frame(f)
        qtbot.wait(20)
        assert mc.frame == f
        _assert_shows_its_own_frame(qtbot, mc)
    probe.stop()
    assert True not in on_gui, "a frame of the cache was computed on the GUI thread"
    assert on_gui and len(shown) >= 30          # the worker computed them
    # the window kept turning: no wait longer than the scrub's short one (0.1 s) plus a render, never a frame's 0.25 s
    assert np.diff(turns).max() < 0.2, np.diff(turns).max()
    assert any(text.startswith("Computing frame ") for text in said), said     # the frames shown meanwhile, said
    assert mc.panel.status_label.text() == solved_status                       # and unsaid once the frame is shown


def test_a_point_cache_export_right_after_a_solve_reads_the_solution_not_the_views_cache(
        qtbot, tmp_path, ict_dir, take_dir, monkeypatch):
    """The frame cache holds the drawn vertices only: a PC2 export is the whole dense result, in blocks from the
    solution (before, the cache's frames not filled yet were computed one by one on the GUI thread)."""
    from model.pc2 import read_pc2
    w, mc, on_gui = _solved_with_a_slow_cache(qtbot, tmp_path, ict_dir, take_dir, monkeypatch)
    on_gui.clear()
    assert mc.export_pc2(tmp_path / "take.pc2")
    assert True not in on_gui
    data, _, _ = read_pc2(tmp_path / "take.pc2")
    sol = mc.solution
    assert data.shape == (358, w.document.rig.n_vertices, 3)
    for f in (0, 200, 357):
        np.testing.assert_allclose(data[f], sol.dense(f), atol=1e-4)
