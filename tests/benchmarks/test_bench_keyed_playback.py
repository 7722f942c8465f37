"""Keyed playback keeps real time on ICT FaceKit (26,719 vertices) at 24 and 60 frames/s (issue 18).

Run: python -m pytest tests/benchmarks/test_bench_keyed_playback.py --benchmark-only -s
The measure is the clock, not the frame count: Space plays a 2-second keyed animation (no loop) in the main
window at its default size, and it must end 2 seconds later (within a quarter of a second), showing the last
frame; frames whose time passed while the previous one was drawn are dropped. The animation plays three times,
each from its start frame; printed for each play: the wall time and the frames shown of the animation's frames --
the start frame (drawn before Space; playback does not draw it again) and each frame a tick of the playback clock
drew --; then the mean time to draw one frame outside playback, and the floor under it: VTK's render of the
surface alone (wall and CPU time; llvmpipe rasterises on every core). Issue 20 asks for every frame shown at
60 fps (README, Benchmarks). The figure is the best of the three plays, as a benchmark's minimum is: on this
shared machine other processes only ever take time away (VTK's render alone varies 11-17 ms by the minute), so
a play's dropped frames measure the minute as much as the application; every play's count is printed and kept.
"""
from __future__ import annotations

import os
import time

import numpy as np
import pytest
from PySide6 import QtCore

from tests.gui_helpers import make_window, open_and_wait
from tests.test_gui_editor_habits import _focus


@pytest.mark.parametrize("fps,kind", [(24.0, "global"), (60.0, "global"), (60.0, "marker-keyed")])
def test_keyed_playback_keeps_real_time_on_ict(benchmark, qtbot, tmp_path, ict_dir, fps, kind):
    """``kind`` "marker-keyed": the same three keys as per-region poses of segmentation level 2 (every region the
    same weights but the mouth's, which smiles less), as marker drags at that level leave them."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))   # the window's size before it is maximised
    open_and_wait(qtbot, w, ict_dir)
    # as a user presses Space: not within the 0.1 s after the rig opened, while its segmentation runs on the other
    # core (the slider benchmark waits the same way); pressed then, the first frames take 25-50 ms and three drop
    w.segmentation.wait()
    qtbot.wait(300)
    kf, rig = w.keyframes, w.document.rig
    kf.set_settings(fps=fps)
    level = None
    if kind == "marker-keyed":
        from app.document import PoseState
        level = w.segmentation.segmentation.levels[2]
    for t, pose in ((0.0, {}), (1.0, {"jawOpen": 0.8, "mouthSmile_L": 0.6, "browInnerUp_L": 1.0}), (2.0, {})):
        weights = np.zeros(rig.n_shapes)
        for name, v in pose.items():
            weights[rig.shape_index(name)] = v
        if level is None:
            w.set_pose(weights, "pose")
        else:
            W = np.tile(weights, (level.blend.shape[1], 1))
            W[0] *= 0.5
            w.document.set_pose_state(PoseState(np.zeros(rig.n_shapes), W, level.blend, 2))
        kf.set_key(t)
    assert (kf.blend is None) == (level is None)
    assert kf.duration == 2.0 and kf.fps == fps
    kf.playback.loop = False
    drawn: list[int] = []
    kf.playback.ticked.connect(drawn.append)
    plays: list[tuple[float, set[int]]] = []    # each play's wall time and the frames it showed

    def play() -> None:
        drawn.clear()
        kf.scrub(0.0)
        w.redraw_now()                  # the start frame is on screen before Space
        _focus(qtbot, w.viewport.canvas)
        t0 = time.perf_counter()
        qtbot.keyClick(w.viewport.canvas, QtCore.Qt.Key_Space)
        assert kf.playing
        qtbot.waitUntil(lambda: not kf.playing, timeout=20000)
        plays.append((time.perf_counter() - t0, {0} | set(drawn)))   # the start frame, then the clock's
        assert kf.time == pytest.approx(2.0)                         # it ended on the last frame

    benchmark.pedantic(play, rounds=3, iterations=1)
    n_frames = len(kf.frame_times())
    elapsed, shown = max(plays, key=lambda p: (len(p[1]), -p[0]))  # the best play: the most frames shown
    dropped = sorted(set(range(n_frames)) - shown)
    # the cost of drawing one frame (pose + render), outside playback
    t0 = time.perf_counter()
    for f in range(0, n_frames, max(1, n_frames // 12)):
        kf.scrub(f / fps)
        w.redraw_now()
    per_frame = (time.perf_counter() - t0) / len(range(0, n_frames, max(1, n_frames // 12)))
    # the floor: VTK's render of the same surface alone (its points and normals marked changed, as a frame's are),
    # no pose, no normals, no Qt: what software OpenGL takes here whatever the application does
    render_window = w.viewport.plotter.ren_win
    inputs = [p.GetMapper().GetInput() for p in w.viewport.plotter.renderer.GetViewProps()
              if p.IsA("vtkActor") and p.GetVisibility()]
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(30):
        for data in inputs:
            data.GetPoints().Modified()
            data.GetPointData().GetNormals().Modified()
        render_window.Render()
    render_ms, render_cpu_ms = (time.perf_counter() - t0) / 30 * 1000, (time.process_time() - c0) / 30 * 1000
    benchmark.extra_info.update(elapsed_s=round(elapsed, 3), frames_shown=len(shown), dropped=dropped,
                                plays=[(round(t, 3), len(f)) for t, f in plays], frames=n_frames,
                                draw_ms=round(per_frame * 1000, 1), render_ms=round(render_ms, 1),
                                render_cpu_ms=round(render_cpu_ms, 1))
    each = "; ".join(f"{t:.3f} s, {len(f)}" for t, f in plays)
    print(f"\n{kind} keyed playback at {fps:g} fps on ICT: the best of 3 plays of a 2.000 s animation showed "
          f"{len(shown)} of {n_frames} frames in {elapsed:.3f} s (dropped: {', '.join(map(str, dropped)) or 'none'}; "
          f"each play: {each} frames), {per_frame * 1000:.1f} ms to draw a frame; VTK's render alone "
          f"{render_ms:.1f} ms ({render_cpu_ms:.1f} ms of CPU on {os.cpu_count()} cores; a frame at {fps:g} fps has "
          f"{1000 / fps:.1f} ms)")
    for t, _f in plays:
        assert abs(t - 2.0) < 0.25, f"a 2 s animation took {t:.2f} s"
