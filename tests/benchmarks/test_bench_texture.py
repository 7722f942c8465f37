"""Texture blending speed (issue 22): band-pass blending of 1024² textures for all 34 shapes of the sample
face while a slider is dragged, in the main window under Xvfb.

Run: python -m pytest tests/benchmarks/test_bench_texture.py --benchmark-only
Target: one drag step (the weight set through the Shapes panel's drag signal, the texture re-blended, the
viewport's points and texture updated and rendered) above 30 frames a second, i.e. under 33 ms of wall time (the
median step). The process's CPU time is printed beside it: it counts llvmpipe's render threads on both cores, so
it exceeds the wall time of a step on an idle machine (a CPU-time assertion failed at 37.6 ms, 27 "fps", where the
window drew more than 30 frames a second).

Every shape has its own texture: the sample's 14 wrinkle maps, and for the 20 other shapes a flush map (the
skin reddened where the shape moves), written beside the sample's OBJs and found by name like a user's.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.interpolate import LinearNDInterpolator
from scipy.ndimage import zoom

from model.textures import write_texture
from widgets.shapes_panel import PoseEdit


def _flush_maps(folder, rig, neutral, shapes) -> int:
    """A texture for every shape without one: the neutral reddened where the shape moves (its UV footprint)."""
    from model.textures import per_vertex_uvs
    uv = per_vertex_uvs(rig)
    size = neutral.shape[0]
    c = (np.arange(128) + 0.5) / 128
    U, V = np.meshgrid(c, c[::-1])
    written = 0
    for k, name in enumerate(rig.shape_names):
        if name in shapes:
            continue
        amount = np.linalg.norm(rig.deltas[k], axis=1)
        amount = amount / max(amount.max(), 1e-9)
        f = LinearNDInterpolator(uv, amount, fill_value=0.0)(U, V)
        m = np.clip(zoom(f, size / 128, order=1), 0, 1)[..., None].astype(np.float32)
        write_texture(folder / f"{name}.png", neutral * (1 - 0.25 * m) + m * 0.25 * np.array([0.9, 0.45, 0.4]))
        written += 1
    return written


@pytest.fixture(scope="module")
def textured_sample(tmp_path_factory):
    from resources.sample_rig import build_sample_rig, write_sample
    from resources.sample_textures import sample_textures, write_sample_textures
    folder = write_sample(tmp_path_factory.mktemp("bench") / "face")
    write_sample_textures(folder)
    rig = build_sample_rig()
    neutral, shapes, _ = sample_textures()
    assert _flush_maps(folder, rig, neutral, shapes) == 20
    return folder


def test_bench_texture_slider_drag(benchmark, qtbot, tmp_path, textured_sample):
    from tests.gui_helpers import make_window, open_and_wait
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, textured_sample)
    rig = w.document.rig
    panel = w.textures.panel
    with qtbot.waitSignal(w.textures.textures_ready, timeout=300000):
        panel.mode.setCurrentIndex(panel.mode.findData("band-pass"))
    b = w.textures.blender
    assert b.size == (1024, 1024) and int(b.textured.sum()) == 34 == rig.n_shapes
    # a busy face: every shape on a little, the brow lines at half; then browInnerUp_L is dragged
    w.set_pose(np.full(rig.n_shapes, 0.15) + 0.35 * np.isin(rig.shape_names, ["browInnerUp_R", "mouthSmile_L"]),
               "pose")
    w.redraw_now()
    k = rig.shape_index("browInnerUp_L")
    w.shapes_panel.pose_edited.emit(PoseEdit("drag-start", k, 0.0))
    step, cpu = [0], []

    def drag_step():
        step[0] += 1
        c = time.process_time()
        w.shapes_panel.pose_edited.emit(PoseEdit("drag", k, 0.02 * (step[0] % 50)))   # re-blends the texture
        w.redraw_now()                                                               # points + render
        cpu.append(time.process_time() - c)

    benchmark.pedantic(drag_step, rounds=40, iterations=1, warmup_rounds=3)
    w.shapes_panel.pose_edited.emit(PoseEdit("drag-end", k, 0.0))
    # the texture followed the drag: it is the blend of the pose the document holds
    from solvers.texture_blend import blend_once
    tex = w.textures.textures
    expected = blend_once(tex.neutral, tex.shape_list(rig.shape_names), w.document.weights, keep=tex.keep)
    assert np.abs(b.image8.astype(int) - np.clip(np.round(expected * 255), 0, 255)).max() <= 1
    # frames a second are wall time; the process's CPU time (llvmpipe's render threads on both cores included)
    # is printed beside it
    median_cpu, median_wall = float(np.median(cpu)), benchmark.stats.stats.median
    benchmark.extra_info["fps (wall)"] = 1.0 / median_wall
    benchmark.extra_info["CPU ms a step"] = median_cpu * 1000
    print(f"\ntextured slider drag step: {median_wall * 1000:.1f} ms wall ({1 / median_wall:.0f} fps), "
          f"{median_cpu * 1000:.1f} ms CPU (median)")
    assert median_wall < 1 / 30, f"{median_wall * 1000:.1f} ms a drag step ({1 / median_wall:.0f} fps)"


def test_bench_texture_blend_only(benchmark, textured_sample):
    """The blend alone for one drag step (one weight changes), without the window."""
    from model.readers import load_rig
    from model.textures import find_texture_files, load_texture_set
    from solvers.texture_blend import TextureBlender
    rig = load_rig(textured_sample)
    tex, problems = load_texture_set(rig, find_texture_files(rig))
    assert problems == [] and len(tex.shapes) == 34
    b = TextureBlender(tex.neutral, tex.shape_list(rig.shape_names), keep=tex.keep)
    w = np.full(rig.n_shapes, 0.15)
    b.set_weights(w)
    k = rig.shape_index("browInnerUp_L")
    step = [0]

    def one():
        step[0] += 1
        w[k] = 0.02 * (step[0] % 50)
        b.set_weights(w)

    cpu = time.process_time()
    benchmark.pedantic(one, rounds=60, iterations=1, warmup_rounds=3)
    assert (time.process_time() - cpu) / 63 < 0.010
