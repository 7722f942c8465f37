"""Screenshots of ICT FaceKit's segmentation at the default settings: level 0 and a middle level of the
hierarchy, against reference PNGs in tests/reference, each with a wrong-picture twin that must NOT match.

Regenerate the references with BLENDSHAPE_STUDIO_UPDATE_REFERENCES=1 (then look at them).
"""
from __future__ import annotations

import numpy as np
import pytest

from tests.cli_runner import run_cli
from tests.image_compare import assert_matches_reference, image_difference, load_png

SIZE = "480,360"
MIDDLE = 2          # ICT's default hierarchy has levels 0–4: mouth+chin, jaw, upper face
TOLERANCE = 0.02    # as assert_matches_reference's default


def _render(tmp_path, rig, name, *args):
    out = tmp_path / f"{name}.png"
    run_cli("render", rig, "-o", out, "--size", SIZE, "--view", "segmentation", *args)
    return load_png(out)


def _colourful(img):
    """Pixels right of the legend that carry a region colour (saturated), not the grey head or backdrop."""
    sat = img.max(axis=2).astype(int) - img.min(axis=2)
    return (sat > 80)[:, int(0.3 * img.shape[1]):]


@pytest.fixture(scope="module")
def ict_renders(ict_dir, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("seg_shots")
    return {name: _render(tmp, ict_dir, name, *args) for name, args in {
        "level0": ("--level", "0"),
        "middle": ("--level", str(MIDDLE)),
        "old_t": ("--level", "0", "--threshold", "0.75"),
    }.items()}


def test_ict_level0_screenshot(ict_renders):
    img = ict_renders["level0"]
    assert _colourful(img).mean() > 0.05   # the regions cover the face, not only the legend
    assert_matches_reference(img, "segmentation_ict_level0")


def test_ict_middle_level_screenshot(ict_renders):
    img = ict_renders["middle"]
    assert _colourful(img).mean() > 0.05
    assert_matches_reference(img, f"segmentation_ict_level{MIDDLE}")


def test_wrong_pictures_do_not_match(ict_renders):
    """The twins: the middle level against level 0's reference, level 0 against the middle level's, and
    the old threshold t = 0.75 (fewer regions, the eyes in the background) against level 0's: each differs
    by more than the tolerance, so the references above would catch these mistakes."""
    from tests.image_compare import REFERENCE_DIR
    ref0 = load_png(REFERENCE_DIR / "segmentation_ict_level0.png")
    refm = load_png(REFERENCE_DIR / f"segmentation_ict_level{MIDDLE}.png")
    for wrong, ref in ((ict_renders["middle"], ref0), (ict_renders["level0"], refm), (ict_renders["old_t"], ref0)):
        fraction, _ = image_difference(wrong, ref)
        assert fraction > TOLERANCE
    assert not np.array_equal(ict_renders["level0"], ict_renders["old_t"])
