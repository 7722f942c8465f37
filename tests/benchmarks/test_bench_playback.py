"""Mocap playback speed in the GUI on ICT FaceKit (26,719 vertices) with the real marker take (358 frames).

Run: xvfb-run -a python -m pytest tests/benchmarks/test_bench_playback.py --benchmark-only
Target: a playback step (set a frame -> both side-by-side views updated and rendered) >= 30 frames/s.
"""
from __future__ import annotations

import itertools

from tests.gui_helpers import make_window, open_and_wait


def test_playback_step_side_by_side(benchmark, qtbot, tmp_path, ict_dir, take_dir):
    from app.mocap_controller import install
    w = make_window(qtbot, tmp_path, size=(1400, 1000))
    mc = install(w)
    open_and_wait(qtbot, w, ict_dir)
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=180000):
        mc.solve()
    mc.precompute()  # playback after the background fill: per-frame surfaces are cached
    frames = itertools.cycle(range(mc.n_frames))

    def step():
        mc.set_frame(next(frames))

    benchmark.pedantic(step, rounds=200, iterations=1, warmup_rounds=5)
    fps = 1.0 / benchmark.stats.stats.mean
    benchmark.extra_info["frames_per_second"] = round(fps, 1)
    print(f"\nside-by-side playback: {fps:.1f} frames/s (two views, 26,719 vertices each)")
    assert fps >= 30, f"playback at {fps:.1f} frames/s, below the 30 frames/s target"
