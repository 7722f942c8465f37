"""Mocap Views playback on a studio rig (issue 20's studio scale): the 228-shape projects of
``test_bench_studio_memory`` (ICT subdivided to 106k and 422k vertices; ICT's 26,719 vertices are its first ones, in
place, so ICT's marker map fits it) open in the main window at its default size, the real marker take solved onto
it, the frame cache filled, then the take played through the Mocap Views (two views of the captured area's faces).

Measured in one window: drawn in full every frame (``SurfaceDetail.full_only``, what the views did before), then
with the level of detail (``widgets.lod``: one decimated proxy of the faces shown, drawn by both views while the
frames follow each other). Each way: a playback step (``set_frame``: both views updated and rendered) timed as the
median and the longest of its rounds, and real-time playback by the timeline's timer through the Qt event loop for
4 s: the frames drawn per second and the longest time between two frames shown (the window frozen that long).
Also printed: playback right after the solve, as shipped (the level of detail on), while the frame cache is still
being filled behind it: frames not computed yet are computed as they are shown, on the GUI thread.

``test_bench_studio_mocap_views_right_after_the_solve`` measures that case alone, as a user meets it: the take played
for 4 s at once after the solve, the frame cache not filled; the frames drawn per second (and how many of them were
the frame the playhead was at, not the nearest frame filled, shown meanwhile), the longest time between two frames,
and the longest the window froze (the longest gap between the turns of a 5 ms QTimer probe); then paused, the time
until the views show the paused frame's own result, checked against the solution.

    PYTHONPATH=$PWD python -m pytest tests/benchmarks/test_bench_studio_mocap_views.py --benchmark-only -s
"""
from __future__ import annotations

import itertools
import time

import numpy as np
import pytest

from tests.benchmarks.test_bench_studio_memory import studio_project
from tests.gui_helpers import make_window


def _steps(mc, frames, n: int) -> list[float]:
    """``n`` playback steps (a frame set: both views updated and rendered), each timed."""
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        mc.set_frame(next(frames))
        times.append(time.perf_counter() - t0)
    return times


def _play(qtbot, mc, seconds: float = 4.0) -> tuple[float, float, int]:
    """Real-time playback for ``seconds``: (frames shown per second, the longest time between two, frames shown)."""
    shown: list[float] = []

    def on_frame(_f: int) -> None:
        shown.append(time.perf_counter())
    mc.frame_shown.connect(on_frame)
    mc.play()
    t0 = time.perf_counter()
    qtbot.wait(int(seconds * 1000))   # a real event loop, idle between frames
    mc.pause()
    mc.frame_shown.disconnect(on_frame)
    return len(shown) / (time.perf_counter() - t0), float(np.diff(shown).max()) if len(shown) > 1 else 0.0, len(shown)


@pytest.mark.parametrize("levels", [1, 2])
def test_bench_studio_mocap_views_playback(benchmark, qtbot, tmp_path, take_dir, levels):
    import vtk
    path = studio_project(levels)
    w = make_window(qtbot, tmp_path, size=(1400, 900))   # the main window's default size
    w.open_path(path)
    qtbot.waitUntil(lambda: not w.is_loading, timeout=600000)
    mc = w.mocap
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    t0 = time.perf_counter()
    with qtbot.waitSignal(mc.solved, timeout=1200000):
        mc.solve()
    solved = time.perf_counter() - t0
    mc.panel.loop_check.setChecked(True)
    filling = _play(qtbot, mc)
    mc.precompute()    # playback after the background fill: per-frame surfaces and normals are cached
    views = mc.views
    detail = views.detail
    qtbot.waitUntil(lambda: detail.proxy_ready, timeout=600000)
    qtbot.wait(500)
    left, right = (views.plotter.renderers[c].actors[n] for c, n in ((0, "surface_left"), (1, "surface_right")))
    drawn: list[tuple[int, int]] = []
    views.plotter.ren_win.AddObserver(vtk.vtkCommand.EndEvent, lambda *_: drawn.append(
        (left.GetMapper().GetInput().GetNumberOfPolys(), right.GetMapper().GetInput().GetNumberOfPolys())))
    full_faces = views.left_mesh.GetNumberOfPolys()
    triangles = int((np.asarray(views.left_mesh._faces[0]) - 2).sum())
    frames = itertools.cycle(range(mc.n_frames))

    full_steps, lod_steps, full_play, lod_play = [], [], [], []
    for _ in range(2):      # alternated (the machine is shared): in full, then with the level of detail
        detail.full_only = True
        qtbot.wait(400)
        full_steps += _steps(mc, frames, 20)[2:]
        full_play.append(_play(qtbot, mc))
        detail.full_only = False
        qtbot.wait(400)
        lod_steps += _steps(mc, frames, 20)[2:]
        lod_play.append(_play(qtbot, mc))
    benchmark.pedantic(lambda: mc.set_frame(next(frames)), rounds=20, iterations=1, warmup_rounds=2)
    proxy = min(a for a, _b in drawn)
    qtbot.waitUntil(lambda: not detail.proxy_shown, timeout=5000)
    assert drawn[-1] == (full_faces, full_faces), drawn[-3:]           # the full surfaces once still
    assert proxy < full_faces

    def summary(steps, plays):
        fps = np.median([p[0] for p in plays])
        return np.median(steps) * 1000, max(steps) * 1000, fps, max(p[1] for p in plays) * 1000
    f_med, f_max, f_fps, f_gap = summary(full_steps, full_play)
    l_med, l_max, l_fps, l_gap = summary(lod_steps, lod_play)
    benchmark.extra_info.update(vertices=w.document.rig.n_vertices, full_step_ms=round(f_med, 1),
                                lod_step_ms=round(l_med, 1), full_playback_fps=round(f_fps, 1),
                                lod_playback_fps=round(l_fps, 1), full_longest_ms=round(f_gap),
                                lod_longest_ms=round(l_gap), proxy_triangles=proxy, full_faces=full_faces)
    print(f"\nMocap Views on a {w.document.rig.n_vertices:,}-vertex rig ({len(views.shown_vertices):,} vertices, "
          f"{full_faces:,} faces = {triangles:,} triangles in each view; solved in {solved:.0f} s; views "
          f"{views.plotter.window_size} pixels):\n"
          f"  right after the solve, the cache filling: playback {filling[0]:.1f} fps, longest between frames "
          f"{filling[1] * 1000:.0f} ms\n"
          f"  in full:  step {f_med:.0f} ms median ({1000 / f_med:.1f} fps), longest {f_max:.0f} ms; playback "
          f"{f_fps:.1f} fps, longest between frames {f_gap:.0f} ms\n"
          f"  proxy ({proxy:,} triangles a view): step {l_med:.0f} ms median ({1000 / l_med:.1f} fps), longest "
          f"{l_max:.0f} ms; playback {l_fps:.1f} fps, longest between frames {l_gap:.0f} ms")


def _probed_play(qtbot, mc, seconds: float = 4.0) -> dict:
    """Real-time playback for ``seconds`` with a 5 ms QTimer probe: frames shown per second, those that were their
    own frame per second (the views may show the nearest filled frame meanwhile: ``views_frame``), the longest time
    between two frames shown and the longest between two turns of the probe (the window frozen that long)."""
    from PySide6 import QtCore
    shown: list[float] = []
    own: list[bool] = []
    turns: list[float] = []

    def on_frame(f: int) -> None:
        shown.append(time.perf_counter())
        own.append(getattr(mc, "views_frame", f) == f)   # the code before this change showed every frame itself
    probe = QtCore.QTimer()
    probe.setInterval(5)
    probe.timeout.connect(lambda: turns.append(time.perf_counter()))
    mc.frame_shown.connect(on_frame)
    probe.start()
    mc.play()
    t0 = time.perf_counter()
    qtbot.wait(int(seconds * 1000))
    mc.pause()
    elapsed = time.perf_counter() - t0
    probe.stop()
    mc.frame_shown.disconnect(on_frame)
    return {"fps": len(shown) / elapsed, "own_fps": sum(own) / elapsed,
            "longest_between_frames_ms": 1000 * float(np.diff(shown).max()) if len(shown) > 1 else 1000 * elapsed,
            "longest_freeze_ms": 1000 * float(np.diff([t0, *turns]).max()) if turns else 1000 * elapsed}


@pytest.mark.parametrize("levels", [1, 2])
def test_bench_studio_mocap_views_right_after_the_solve(benchmark, qtbot, tmp_path, take_dir, levels):
    path = studio_project(levels)
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    w.open_path(path)
    qtbot.waitUntil(lambda: not w.is_loading, timeout=600000)
    mc = w.mocap
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=1200000):
        mc.solve()
    mc.panel.loop_check.setChecked(True)
    t_solved = time.perf_counter()
    r = benchmark.pedantic(lambda: _probed_play(qtbot, mc), rounds=1, iterations=1)
    t0 = time.perf_counter()
    qtbot.waitUntil(lambda: getattr(mc, "views_frame", mc.frame) == mc.frame, timeout=60000)
    settled = time.perf_counter() - t0
    f, sol = mc.frame, mc.solution
    at = mc.views.shown_vertices
    np.testing.assert_allclose(np.asarray(mc.views.left_mesh.points), sol.projection(f)[at], atol=1e-4)
    np.testing.assert_allclose(np.asarray(mc.views.right_mesh.points), sol.dense(f)[at], atol=1e-4)
    cache = mc.cache
    qtbot.waitUntil(lambda: bool(cache.ready.all()), timeout=600000)
    filled = time.perf_counter() - t_solved
    benchmark.extra_info.update(vertices=w.document.rig.n_vertices, **{k: round(v, 1) for k, v in r.items()},
                                paused_frame_shown_ms=round(1000 * settled), cache_filled_s=round(filled, 1))
    print(f"\nRight after the solve on a {w.document.rig.n_vertices:,}-vertex rig ({len(at):,} vertices drawn), "
          f"the frame cache not filled: playback {r['fps']:.1f} fps ({r['own_fps']:.1f} fps of their own frame), "
          f"longest between frames {r['longest_between_frames_ms']:.0f} ms, longest freeze (5 ms probe) "
          f"{r['longest_freeze_ms']:.0f} ms; paused: its own frame shown after {1000 * settled:.0f} ms; "
          f"cache filled {filled:.1f} s after the solve")
