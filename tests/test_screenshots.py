"""Screenshot tests: `render` and the main window against reference PNGs in tests/reference.

On failure the actual image and a difference image are written to tests/_failures and their paths
printed. Regenerate references with BLENDSHAPE_STUDIO_UPDATE_REFERENCES=1 (then look at them).
"""
from __future__ import annotations

import pytest

from tests.cli_runner import run_cli
from tests.gui_helpers import make_window
from tests.image_compare import assert_matches_reference, load_png

SIZE = "480,360"


def _render(tmp_path, rig, name, *args):
    out = tmp_path / f"{name}.png"
    run_cli("render", rig, "-o", out, "--size", SIZE, *args)
    return load_png(out)


@pytest.fixture(scope="module")
def sample_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sample") / "sample"
    run_cli("sample", "-o", out)
    return out


def _face_fraction(img):
    """Fraction of pixels that are not the grey-blue gradient background."""
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return float(((r - b) > 25).mean())


def test_render_sample_front(sample_dir, tmp_path):
    img = _render(tmp_path, sample_dir, "render_sample_front")
    assert _face_fraction(img) > 0.1
    assert_matches_reference(img, "render_sample_front")


def test_render_sample_jaw_open_three_quarter(sample_dir, tmp_path):
    img = _render(tmp_path, sample_dir, "render_sample_jaw", "--weights", "jawOpen=1", "--camera", "three-quarter")
    assert_matches_reference(img, "render_sample_jaw_three_quarter")


def test_render_ict_jaw_open(ict_dir, tmp_path):
    img = _render(tmp_path, ict_dir, "render_ict_jaw", "--weights", "jawOpen=1")
    assert _face_fraction(img) > 0.1
    assert_matches_reference(img, "render_ict_jaw_open")


def test_main_window_viewport(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path, size=(1000, 700))
    w.apply_preset("happy")
    w.redraw_now()
    img = w.viewport.grab_image(size=(640, 480))
    assert img.shape == (480, 640, 3)
    assert _face_fraction(img) > 0.1
    assert_matches_reference(img, "window_viewport_happy", tolerance=0.03)


def test_comparison_catches_an_empty_viewport(qtbot, tmp_path, monkeypatch):
    """An empty viewport (no surface drawn) must fail the comparison, or the tests prove nothing."""
    monkeypatch.delenv("BLENDSHAPE_STUDIO_UPDATE_REFERENCES", raising=False)
    w = make_window(qtbot, tmp_path, size=(1000, 700))
    w.apply_preset("happy")
    w.redraw_now()
    w.viewport.plotter.remove_actor("surface")
    img = w.viewport.grab_image(size=(640, 480))
    assert _face_fraction(img) < 0.01
    with pytest.raises(AssertionError, match="differs from"):
        assert_matches_reference(img, "window_viewport_happy", tolerance=0.03)


@pytest.mark.parametrize("view", ["deformation", "deformation-rgb", "segmentation"])
def test_render_ict_map_views_with_legend(ict_dir, tmp_path, view):
    img = _render(tmp_path, ict_dir, f"ict_{view}", "--view", view, "--threshold", "0.75")
    h, w, _ = img.shape
    if view == "deformation":
        # the colour bar on the right runs from black to the bright yellow of the inferno map
        bar = img[int(0.1 * h):int(0.9 * h), int(0.78 * w):]
        assert ((bar[..., 0] > 200) & (bar[..., 1] > 200) & (bar[..., 2] < 150)).sum() > 20
    else:
        # the legend box (upper left) holds saturated colour swatches
        box = img[: int(0.45 * h), : int(0.3 * w)].astype(int)
        saturation = box.max(axis=2) - box.min(axis=2)
        assert (saturation > 80).sum() > 30
    assert _face_fraction(img) > 0.02 or view != "shaded"
    assert_matches_reference(img, f"render_ict_{view}")


def test_render_sample_segmentation(sample_dir, tmp_path):
    img = _render(tmp_path, sample_dir, "sample_seg", "--view", "segmentation", "--threshold", "0.9")
    colourful = (img.max(axis=2).astype(int) - img.min(axis=2)) > 80
    assert colourful[:, int(0.3 * img.shape[1]):].mean() > 0.02  # regions drawn on the face, not only the legend
    assert_matches_reference(img, "render_sample_segmentation")
