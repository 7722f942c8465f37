"""The Texture panel and the viewport's live texture (issue 22): a blend mode chosen in the panel, the texture
following a real slider drag, a preset and undo, the bands shown, mode none back to plain shading."""
from __future__ import annotations

import numpy as np
from PySide6 import QtWidgets

from solvers.texture_blend import blend_once
from tests.gui_helpers import make_window
from tests.image_compare import pixel_difference
from tests.test_gui_main import _drag_slider


def _choose(qtbot, w, mode):
    panel = w.textures.panel
    i = panel.mode.findData(mode)
    if w.textures.blender is None and mode != "none":
        with qtbot.waitSignal(w.textures.textures_ready, timeout=120000):
            panel.mode.setCurrentIndex(i)
    else:
        panel.mode.setCurrentIndex(i)
    qtbot.waitUntil(lambda: not w.redraw_pending)
    QtWidgets.QApplication.processEvents()


def _shown_texture(w) -> np.ndarray:
    """The texels the viewport's texture holds (row 0 the top)."""
    return np.asarray(w.viewport._textured._pixels)[::-1]


def test_band_pass_texture_follows_a_slider_drag_and_undo(qtbot, tmp_path):
    from resources.sample_textures import sample_textures
    w = make_window(qtbot, tmp_path)
    rig = w.document.rig
    assert w.textures.panel.current_mode() == "none" and not w.viewport.textured   # off until chosen
    plain = w.viewport.picture((480, 360))
    _choose(qtbot, w, "band-pass")
    assert w.viewport.textured and w.textures.problems == []
    textured = w.viewport.picture((480, 360))
    assert (pixel_difference(plain, textured) > 32).sum() > 2000     # the skin texture, eyes, hair are drawn
    neutral, shapes, keep = sample_textures()
    k = rig.shape_index("browInnerUp_L")
    forehead = np.abs(shapes["browInnerUp_L"] - neutral).max(axis=2) > 0.05
    before = _shown_texture(w)[forehead].astype(int)
    row = w.shapes_panel.row("browInnerUp_L")
    w.shapes_dock.raise_()
    _drag_slider(row.slider, 0.6)
    qtbot.waitUntil(lambda: not w.redraw_pending)
    weight = w.document.weights[k]
    assert 0.3 < weight < 0.9
    shown = _shown_texture(w)
    expected = blend_once(neutral, [shapes.get(n) for n in rig.shape_names], w.document.weights, keep=keep)
    assert np.abs(shown.astype(int) - np.clip(np.round(expected * 255), 0, 255)).max() <= 1     # the blend for this pose
    assert (before - shown[forehead].astype(int)).mean() > 10                    # the lines darkened the forehead
    w.undo_action.trigger()
    qtbot.waitUntil(lambda: not w.redraw_pending)
    np.testing.assert_array_equal(_shown_texture(w)[forehead].astype(int), before)


def test_linear_differs_from_band_pass_on_the_face_and_none_is_plain(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.set_pose(w.document.rig.weights_from_dict({"browInnerUp_L": 0.5, "browInnerUp_R": 0.5,
                                                  "mouthSmile_L": 0.5, "mouthSmile_R": 0.5}), "pose")
    qtbot.waitUntil(lambda: not w.redraw_pending)
    plain = w.viewport.picture((640, 480))           # the same pose, untextured
    _choose(qtbot, w, "band-pass")
    qtbot.waitUntil(lambda: not w.redraw_pending)
    band = w.viewport.picture((640, 480))
    detail_band = w.textures.blender.bands()[1]
    _choose(qtbot, w, "linear")
    linear = w.viewport.picture((640, 480))
    # the blend's detail band holds less in linear mode (the wrinkles averaged away)
    assert np.abs(w.textures.blender.bands()[1]).mean() < np.abs(detail_band).mean()
    assert (pixel_difference(band, linear) > 24).sum() > 100
    _choose(qtbot, w, "none")
    assert not w.viewport.textured
    assert (pixel_difference(w.viewport.picture((640, 480)), plain) > 32).sum() < 0.01 * plain[..., 0].size


def test_panel_shows_the_bands_and_the_source(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    w.textures.dock.show()
    w.textures.dock.raise_()
    _choose(qtbot, w, "band-pass")
    panel = w.textures.panel
    assert "14 shape textures" in panel.source.text() and "generated" in panel.source.text()
    w.apply_preset("surprised")
    qtbot.waitUntil(lambda: not w.redraw_pending)
    for key in ("image", "low", "detail"):
        pm = panel.bands[key].pixmap()
        assert pm is not None and not pm.isNull()
    assert "browInnerUp" in panel.dominant.text() or "browOuterUp" in panel.dominant.text()
    # the mask check box reaches the blend: without the mask the masked texels may change
    assert panel.mask.isEnabled() and panel.mask.isChecked()
    assert w.textures.blender.keep is not None
    panel.mask.setChecked(False)
    assert w.textures.blender.keep is None


def test_picking_on_the_textured_surface_gives_rig_vertices(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    _choose(qtbot, w, "band-pass")
    vp = w.viewport
    rig = w.document.rig
    tip = int(np.argmax(rig.neutral[:, 2]))            # the nose tip faces the front camera
    x, y = vp.world_to_display(rig.neutral[[tip]])[0][:2]
    p = vp.pick(int(round(x)), int(round(y)))
    assert p is not None and 0 <= p.vertex < rig.n_vertices
    assert np.linalg.norm(rig.neutral[p.vertex] - rig.neutral[tip]) < 0.5


def test_textures_found_beside_a_folder_come_back_with_its_project(qtbot, tmp_path):
    """Opened from a folder, its textures are found by name; a project saved from it lists them, so they come
    back when the project is opened from another folder. A wrong-size texture is a sentence in the panel."""
    import shutil

    from model.textures import write_texture
    from resources.sample_rig import write_sample
    from resources.sample_textures import write_sample_textures
    from tests.gui_helpers import open_and_wait
    folder = write_sample(tmp_path / "face")
    write_sample_textures(folder)
    write_texture(folder / "noseSneer_R.png", np.zeros((64, 64, 3)))
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, folder)
    _choose(qtbot, w, "band-pass")
    assert w.viewport.textured and "13 shape textures" in w.textures.panel.source.text()
    assert any("noseSneer_R.png" in p and "64x64" in p for p in w.textures.problems)
    assert "noseSneer_R.png" in w.textures.panel.problems.text()
    assert w.save_to(tmp_path / "p.bsproj")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(tmp_path / "p.bsproj", elsewhere / "p.bsproj")
    with qtbot.waitSignal(w.textures.textures_ready, timeout=120000):
        open_and_wait(qtbot, w, elsewhere / "p.bsproj")
    assert w.viewport.textured and "13 shape textures" in w.textures.panel.source.text()
    assert str(folder / "neutral.png") in str(w.document.project.sections["textures"]["neutral"])


def test_texture_follows_a_live_link_face_take_as_it_plays(qtbot, tmp_path, llf_csv):
    from resources.sample_textures import sample_textures
    w = make_window(qtbot, tmp_path)
    _choose(qtbot, w, "band-pass")
    mc = w.mocap
    assert mc.load_take(llf_csv)
    neutral, shapes, keep = sample_textures()
    rig = w.document.rig
    seen = set()
    for frame in (0, 120, 240):
        mc.set_frame(frame)
        qtbot.waitUntil(lambda: not w.redraw_pending)
        w.redraw_now()
        expected = blend_once(neutral, [shapes.get(n) for n in rig.shape_names], w.document.weights, keep=keep)
        shown = _shown_texture(w)
        assert np.abs(shown.astype(int) - np.clip(np.round(expected * 255), 0, 255)).max() <= 1
        seen.add(shown.tobytes())
    assert len(seen) == 3   # the texture changed with the frames


def test_texture_weights_of_a_regional_pose_are_each_shapes_largest():
    from app.texture_controller import texture_weights
    g = np.array([0.1, 0.2, 0.0])
    np.testing.assert_array_equal(texture_weights(g), g)
    W = np.array([[0.9, 0.0, 0.1], [0.0, 0.4, 0.0], [0.1, 0.2, 0.0]])
    np.testing.assert_array_equal(texture_weights(g, W), [0.9, 0.4, 0.1])


def test_a_rig_without_textures_says_so_and_nothing_about_its_uvs(qtbot, tmp_path, ict_dir):
    """Band-pass chosen on ICT FaceKit, which has no textures beside its OBJs: the panel says none were found, and no
    warning that 54,268 face corners have UVs outside 0–1 '(tiles or a damaged file); the texture repeats there' (in
    the panel and the status bar) about a texture that is not there."""
    from tests.gui_helpers import open_and_wait
    w = make_window(qtbot, tmp_path, sample=False)
    open_and_wait(qtbot, w, ict_dir)
    with qtbot.waitSignal(w.textures.textures_ready, timeout=120000):
        w.textures.panel.mode.setCurrentIndex(w.textures.panel.mode.findData("band-pass"))
    QtWidgets.QApplication.processEvents()
    texts = [label.text() for label in w.textures.panel.findChildren(QtWidgets.QLabel)]
    assert "none found beside the rig" in texts
    assert not any("UV" in t for t in texts) and "UV" not in w.statusBar().currentMessage()
    assert w.textures.problems == [] and not w.viewport.textured
