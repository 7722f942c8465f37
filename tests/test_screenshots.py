"""Screenshot tests: `render` and the main window against reference PNGs in tests/reference.

On failure the actual image and a difference image are written to tests/_failures and their paths
printed. Regenerate references with BLENDSHAPE_STUDIO_UPDATE_REFERENCES=1 (then look at them).
"""
from __future__ import annotations

import numpy as np
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
    img = w.viewport.grab_image()
    assert _face_fraction(img) > 0.1
    assert_matches_reference(img, "window_viewport_happy", tolerance=0.03)


def test_comparison_catches_an_empty_viewport(qtbot, tmp_path, monkeypatch):
    """An empty viewport (no surface drawn) must fail the comparison, or the tests prove nothing."""
    monkeypatch.delenv("BLENDSHAPE_STUDIO_UPDATE_REFERENCES", raising=False)
    w = make_window(qtbot, tmp_path, size=(1000, 700))
    w.apply_preset("happy")
    w.redraw_now()
    w.viewport.plotter.remove_actor("surface")
    img = w.viewport.grab_image()
    assert _face_fraction(img) < 0.01
    with pytest.raises(AssertionError, match="differs from"):
        assert_matches_reference(img, "window_viewport_happy", tolerance=0.03)
