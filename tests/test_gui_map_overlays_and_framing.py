"""What the camera frames and where a colour map's legend and bar go.

- In the main window at 1600x1000 (the audit's screen; the window opens at the screen's size) on ICT FaceKit, the
  Segmentation view's legend and the deformation map's colour bar lie beside the face on screen, not over it, and
  the face still fills most of the view's height (framed, not the head and shoulders).
- File ▸ Export Image's legend rows are readable in a 600x300 picture and not huge in a 2400x1600 one.
- The camera presets and ``render`` show the whole of a model whose shapes act across it (the third-party glTF cube,
  one side of which its one shape moves): every vertex inside the picture.
"""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtWidgets

from tests.cli_runner import run_cli
from tests.conftest import DATA, require_data
from tests.gui_helpers import make_window, open_and_wait
from tests.image_compare import assert_large_and_whole, load_png

CUBE = DATA / "thirdparty" / "gltf" / "singleBlendshapeCube_sparse.glb"
LEGEND_BOX = np.array([26, 26, 31])     # the legend's backdrop, (0.1, 0.1, 0.12) (widgets.scene.add_surface)


def _settle(qtbot, w):
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=30000)
    for _ in range(5):
        QtWidgets.QApplication.processEvents()
        qtbot.wait(20)


def _rect(actor, renderer):
    """(x0, y0, x1, y1) display pixels of a 2D actor's box."""
    x0, y0 = actor.GetPositionCoordinate().GetComputedDisplayValue(renderer)
    x1, y1 = actor.GetPosition2Coordinate().GetComputedDisplayValue(renderer)
    return x0, y0, x1, y1


def _face_box(w):
    """(x0, y0, x1, y1) display pixels of the projected face (the vertices the camera presets frame)."""
    d = w.viewport.world_to_display(w.viewport.focus_points())
    return d[:, 0].min(), d[:, 1].min(), d[:, 0].max(), d[:, 1].max()


def _apart(a, b) -> bool:
    return a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1]


def _set_view(qtbot, w, view, shape=None):
    sp = w.segmentation_panel
    sp.view.setCurrentIndex(sp.view.findData(view))
    if shape is not None:
        sp.shape.setCurrentIndex(sp.shape.findText(shape))
    w.segmentation.wait()
    _settle(qtbot, w)


def _legend_rows(img, n_rows):
    """Height in pixels of a legend row in a picture: the legend's backdrop rows at its left, over its rows."""
    near = (np.abs(img[:, : img.shape[1] // 2].astype(int) - LEGEND_BOX) <= 3).all(axis=2)
    rows = np.flatnonzero(near.sum(axis=1) >= 0.08 * img.shape[1])
    assert rows.size, "no legend in the picture"
    return (rows.max() - rows.min() + 1) / n_rows


def test_legend_and_colour_bar_beside_the_face_and_readable_in_exports(qtbot, tmp_path, ict_dir):
    w = make_window(qtbot, tmp_path, (1600, 1000), sample=False)
    open_and_wait(qtbot, w, ict_dir)
    _settle(qtbot, w)
    renderer = w.viewport.plotter.renderer
    vw, vh = w.viewport.plotter.window_size

    _set_view(qtbot, w, "segmentation")
    w.segmentation_panel.level.setValue(2)
    _settle(qtbot, w)
    legend = w.viewport.plotter.legend
    assert legend is not None and legend.GetVisibility()
    face = _face_box(w)
    assert face[3] - face[1] > 0.75 * vh          # still the face, framed: not the head and shoulders
    assert 0 <= face[0] and face[2] <= vw         # the whole face in the view
    assert _apart(_rect(legend, renderer), face), (_rect(legend, renderer), face)

    n_rows = legend.GetNumberOfEntries()
    small, big = tmp_path / "small.png", tmp_path / "big.png"
    assert w.save_image(small, (600, 300)) and w.save_image(big, (2400, 1600))   # File ▸ Export Image
    w.jobs.wait()
    assert 14 <= _legend_rows(load_png(small), n_rows) <= 30    # was 7 px a row at 600x300
    assert 14 <= _legend_rows(load_png(big), n_rows) <= 30      # and 36 at 2400x1600

    _set_view(qtbot, w, "deformation", "jawOpen")
    bars = list(w.viewport.plotter.scalar_bars.values())
    assert len(bars) == 1
    face = _face_box(w)
    assert face[3] - face[1] > 0.75 * vh and 0 <= face[0] and face[2] <= vw
    x0, y0, x1, y1 = _rect(bars[0], renderer)
    assert _apart((x0, y0, x1, y1), face), ((x0, y0, x1, y1), face)
    # nor over the side of the head: no point of the surface lies under the bar and its labels
    d = w.viewport.world_to_display(w.viewport.points())
    under = (d[:, 0] >= x0) & (d[:, 0] <= x1) & (d[:, 1] >= y0) & (d[:, 1] <= y1)
    assert not under.any(), f"{under.sum()} points under the colour bar"


def _inside(d, size) -> bool:
    return bool((d[:, 0] >= 0).all() and (d[:, 0] <= size[0]).all() and (d[:, 1] >= 0).all()
                and (d[:, 1] <= size[1]).all())


def test_camera_presets_show_the_whole_sparse_cube(qtbot, tmp_path):
    cube = require_data(CUBE)
    w = make_window(qtbot, tmp_path, (1600, 1000), sample=False)
    open_and_wait(qtbot, w, cube)
    _settle(qtbot, w)
    size = w.viewport.plotter.window_size
    points = w.viewport.points()
    assert _inside(w.viewport.world_to_display(points), size)      # as it opens
    actions = {a.text().replace("&", ""): a for a in w.findChildren(type(w.frame_all_action))}
    for label in ("Front Camera", "Three-Quarter Camera", "Left Side Camera"):
        actions[label].trigger()
        _settle(qtbot, w)
        d = w.viewport.world_to_display(points)
        assert _inside(d, size), label
        # framed, not lost in the distance: the cube spans most of the view's height or width
        assert max((d[:, 0].max() - d[:, 0].min()) / size[0], (d[:, 1].max() - d[:, 1].min()) / size[1]) > 0.6


@pytest.mark.parametrize("args", [(), ("--camera", "three-quarter"), ("--weights", "blendShape1.pCube2=1")],
                         ids=["front", "three-quarter", "posed"])
def test_render_shows_the_whole_sparse_cube(tmp_path, args):
    cube = require_data(CUBE)
    out = tmp_path / "cube.png"
    run_cli("render", cube, "-o", out, "--size", "400,300", *args)
    # the cube, large in the picture, nothing cut at its edges (before, the left half of the cube was out of it)
    assert_large_and_whole(load_png(out))


def _region_vertices(w):
    seg = w.segmentation.segmentation
    return np.flatnonzero(seg.levels[w.segmentation.level].core_labels(w.document.rig.n_vertices) >= 0)


def test_a_segmentation_view_frames_its_regions_whole(qtbot, tmp_path, ict_dir):
    """ICT's forehead regions reach 2.4 cm above the box of the vertices the shapes move most, which the camera
    framed alone: in File > Export Image's 4:3 pictures (as in ``render``'s) the regions' tops were cut off."""
    w = make_window(qtbot, tmp_path, (1400, 900), sample=False)     # the window's default size
    open_and_wait(qtbot, w, ict_dir)
    _settle(qtbot, w)
    _set_view(qtbot, w, "segmentation")
    size = w.viewport.plotter.window_size
    regions = w.viewport.points()[_region_vertices(w)]
    actions = {a.text().replace("&", ""): a for a in w.findChildren(type(w.frame_all_action))}
    actions["Front Camera"].trigger()
    _settle(qtbot, w)
    assert _inside(w.viewport.world_to_display(regions), size)       # on screen
    face = _face_box(w)
    assert face[3] - face[1] > 0.6 * size[1]       # still the face, beside the legend, not the head and shoulders
    out = tmp_path / "seg.png"
    assert w.save_image(out, (640, 480))                              # File > Export Image
    w.jobs.wait()
    _assert_regions_whole(load_png(out))
    _set_view(qtbot, w, "shaded")                  # the shaded view frames the face alone, as before
    assert w.viewport.focus_points().shape[0] < regions.shape[0]


def _saturated(img) -> np.ndarray:
    """Pixels of a region's colour: the head is grey, the background grey-blue, the legend's text white."""
    rgb = img.astype(int)
    return rgb.max(axis=2) - rgb.min(axis=2) > 60


@pytest.mark.parametrize("size", [(640, 480), (800, 600)])
def test_render_of_a_segmentation_shows_every_region_whole(tmp_path, ict_dir, size):
    out = tmp_path / "seg.png"
    run_cli("render", ict_dir, "-o", out, "--view", "segmentation", "--size", f"{size[0]},{size[1]}")
    _assert_regions_whole(load_png(out))


def _assert_regions_whole(img):
    coloured = _saturated(img)
    coloured[: img.shape[0] // 2, : int(0.45 * img.shape[1]) + 20] = False    # the legend's swatches
    assert coloured.sum() > 0.1 * coloured.size                             # the regions are there, large
    edges = np.concatenate([coloured[:2].ravel(), coloured[-2:].ravel(), coloured[:, -2:].ravel()])
    assert not edges.any(), f"{edges.sum()} region pixels on the picture's edges"   # was: the forehead's cut
