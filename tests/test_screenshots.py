"""Screenshot tests: `render` and the main window against reference PNGs in tests/reference.

Every screenshot is compared with its reference and, inside the region where the reference differs from
the nearest wrong pictures (the neutral face for a pose, the closed jaw for jawOpen, the shaded face for a
map view, the next hierarchy level for a segmentation), it must side with the reference
(``tests.image_compare``). Each screenshot test has a twin that renders the wrong pictures and shows that
they fail the same comparison. On failure the actual image and a difference image are written to
tests/_failures and their paths printed. Regenerate references with BLENDSHAPE_STUDIO_UPDATE_REFERENCES=1
(then look at them).
"""
from __future__ import annotations

import pytest

from tests.cli_runner import run_cli
from tests.gui_helpers import make_window
from tests.image_compare import assert_matches_reference, assert_wrong_picture_fails, load_png

SIZE = "480,360"
SEGMENT_SAMPLE = ("--view", "segmentation")   # the default threshold (0.5 of the skin that moves)
SEGMENT_ICT = ("--view", "segmentation")

# reference name: (rig, render arguments)
SHOTS = {
    "render_sample_front": ("sample", ()),
    "render_sample_happy_front": ("sample", ("--preset", "happy")),
    "render_sample_three_quarter": ("sample", ("--camera", "three-quarter")),
    "render_sample_jaw_three_quarter": ("sample", ("--weights", "jawOpen=1", "--camera", "three-quarter")),
    "render_sample_segmentation": ("sample", SEGMENT_SAMPLE),
    "render_sample_segmentation_level1": ("sample", SEGMENT_SAMPLE + ("--level", "1")),
    "render_ict_front": ("ict", ()),
    "render_ict_jaw_open": ("ict", ("--weights", "jawOpen=1")),
    "render_ict_deformation": ("ict", ("--view", "deformation", "--threshold", "0.75")),
    "render_ict_deformation-rgb": ("ict", ("--view", "deformation-rgb", "--threshold", "0.75")),
    "render_ict_segmentation": ("ict", SEGMENT_ICT),
    "render_ict_segmentation_level1": ("ict", SEGMENT_ICT + ("--level", "1")),
}

# reference name: the references of the nearest wrong pictures, inside whose difference it must be recognised
UNLIKE = {
    "render_sample_front": ["render_sample_happy_front"],
    "render_sample_happy_front": ["render_sample_front"],
    "render_sample_three_quarter": ["render_sample_jaw_three_quarter"],
    "render_sample_jaw_three_quarter": ["render_sample_three_quarter"],
    "render_sample_segmentation": ["render_sample_segmentation_level1"],
    "render_sample_segmentation_level1": ["render_sample_segmentation"],
    "render_ict_front": ["render_ict_jaw_open"],
    "render_ict_jaw_open": ["render_ict_front"],
    "render_ict_deformation": ["render_ict_front", "render_ict_deformation-rgb"],
    "render_ict_deformation-rgb": ["render_ict_front", "render_ict_deformation"],
    "render_ict_segmentation": ["render_ict_front", "render_ict_segmentation_level1"],
    "render_ict_segmentation_level1": ["render_ict_segmentation"],
}

# (reference, the wrong picture: another reference's name or (rig, render arguments)) -- each must fail
WRONG = [
    ("render_sample_front", "render_sample_happy_front"),
    ("render_sample_happy_front", "render_sample_front"),                    # a preset that did nothing
    ("render_sample_happy_front", ("sample", ("--preset", "sad"))),           # another preset
    ("render_sample_jaw_three_quarter", "render_sample_three_quarter"),      # a weight that did nothing
    ("render_sample_jaw_three_quarter", ("sample", ("--weights", "jawOpen=0.5", "--camera", "three-quarter"))),
    ("render_sample_jaw_three_quarter", ("sample", ("--weights", "jawOpen=1"))),   # the wrong camera
    ("render_sample_three_quarter", "render_sample_jaw_three_quarter"),
    ("render_sample_segmentation", "render_sample_segmentation_level1"),      # the wrong level
    ("render_sample_segmentation", ("sample", ("--view", "segmentation", "--threshold", "0.75"))),  # threshold
    ("render_sample_segmentation_level1", "render_sample_segmentation"),
    ("render_ict_jaw_open", "render_ict_front"),                             # a weight that did nothing
    ("render_ict_jaw_open", ("ict", ("--weights", "jawOpen=0.5"))),           # half the weight
    ("render_ict_front", "render_ict_jaw_open"),
    ("render_ict_deformation", "render_ict_front"),                          # the view did not change
    ("render_ict_deformation", "render_ict_deformation-rgb"),
    ("render_ict_deformation-rgb", "render_ict_front"),
    ("render_ict_deformation-rgb", "render_ict_deformation"),
    ("render_ict_segmentation", "render_ict_front"),
    ("render_ict_segmentation", "render_ict_segmentation_level1"),          # the wrong level (1.8 % of pixels)
    ("render_ict_segmentation", ("ict", ("--view", "segmentation", "--threshold", "0.6"))),     # threshold
    ("render_ict_segmentation_level1", "render_ict_segmentation"),
]


@pytest.fixture(scope="module")
def sample_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sample") / "sample"
    run_cli("sample", "-o", out)
    return out


@pytest.fixture(scope="module")
def shoot(tmp_path_factory, sample_dir, request):
    """shoot(rig, args) -> the rendered image, rendered once per module for the same arguments."""
    shots, folder = {}, tmp_path_factory.mktemp("shots")

    def shoot(rig, args):
        if (rig, args) not in shots:
            path = request.getfixturevalue("ict_dir") if rig == "ict" else sample_dir
            out = folder / f"shot{len(shots)}.png"
            run_cli("render", path, "-o", out, "--size", SIZE, *args)
            shots[rig, args] = load_png(out)
        return shots[rig, args]
    return shoot


def _face_fraction(img):
    """Fraction of pixels that are not the grey-blue gradient background."""
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return float(((r - b) > 25).mean())


def _check_content(name, img):
    """What a user sees in each picture, beside the comparison: a face, a legend, regions on the face."""
    h, w, _ = img.shape
    if name == "render_ict_deformation":
        # the colour bar on the right runs from black to the bright yellow of the inferno map
        bar = img[int(0.1 * h):int(0.9 * h), int(0.78 * w):]
        assert ((bar[..., 0] > 200) & (bar[..., 1] > 200) & (bar[..., 2] < 150)).sum() > 20
    elif "deformation-rgb" in name or "segmentation" in name:
        # the legend box (upper left) holds saturated colour swatches
        box = img[: int(0.45 * h), : int(0.3 * w)].astype(int)
        saturation = box.max(axis=2) - box.min(axis=2)
        assert (saturation > 80).sum() > 30
        if "segmentation" in name:   # regions drawn on the face, not only the legend
            colourful = (img.max(axis=2).astype(int) - img.min(axis=2)) > 80
            assert colourful[:, int(0.3 * w):].mean() > 0.02
    else:
        assert _face_fraction(img) > 0.1


@pytest.mark.parametrize("name", list(SHOTS))
def test_render_matches_its_reference(name, shoot):
    img = shoot(*SHOTS[name])
    _check_content(name, img)
    assert_matches_reference(img, name, unlike=UNLIKE[name])


@pytest.mark.parametrize("name, wrong", WRONG, ids=[f"{n}-vs-{w if isinstance(w, str) else ' '.join(w[1])}"
                                                     for n, w in WRONG])
def test_wrong_render_fails_the_comparison(name, wrong, shoot):
    img = shoot(*(SHOTS[wrong] if isinstance(wrong, str) else wrong))
    assert_wrong_picture_fails(img, name, unlike=UNLIKE[name])


# --- the main window's viewport ----------------------------------------------------------------------
WINDOW_UNLIKE = {"window_viewport_happy": ["window_viewport_neutral"],
                 "window_viewport_neutral": ["window_viewport_happy"]}


def _viewport_shot(qtbot, tmp_path, preset=None):
    w = make_window(qtbot, tmp_path, size=(1000, 700))
    if preset:
        w.apply_preset(preset)
    w.redraw_now()
    img = w.viewport.picture((640, 480))
    assert img.shape == (480, 640, 3)
    return w, img


@pytest.mark.parametrize("preset, name", [("happy", "window_viewport_happy"), (None, "window_viewport_neutral")])
def test_main_window_viewport(qtbot, tmp_path, preset, name):
    _, img = _viewport_shot(qtbot, tmp_path, preset)
    assert _face_fraction(img) > 0.1
    assert_matches_reference(img, name, tolerance=0.03, unlike=WINDOW_UNLIKE[name])


@pytest.mark.parametrize("preset, name", [(None, "window_viewport_happy"), ("sad", "window_viewport_happy"),
                                          ("happy", "window_viewport_neutral")])
def test_main_window_viewport_wrong_pose_fails(qtbot, tmp_path, preset, name):
    """A preset that did nothing (the neutral face), or another preset, is not the happy face."""
    _, img = _viewport_shot(qtbot, tmp_path, preset)
    assert_wrong_picture_fails(img, name, tolerance=0.03, unlike=WINDOW_UNLIKE[name])


def test_comparison_catches_an_empty_viewport(qtbot, tmp_path):
    """An empty viewport (no surface drawn) must fail the comparison, or the tests prove nothing."""
    w, _ = _viewport_shot(qtbot, tmp_path, "happy")
    for name in ("surface", "surface_backs"):   # the surface, and the back sides of its two-sided parts
        w.viewport.plotter.remove_actor(name)
    img = w.viewport.picture((640, 480))
    assert _face_fraction(img) < 0.01
    assert_wrong_picture_fails(img, "window_viewport_happy", tolerance=0.03, unlike=WINDOW_UNLIKE["window_viewport_happy"])
