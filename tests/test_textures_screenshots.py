"""Screenshots of the sample face with its textures (issue 22): `render --texture band-pass` and `--texture
linear` with the brows raised and a smile at 0.5, against references in tests/reference, each with wrong
pictures that must fail the same comparison (tests.image_compare): linear for band-pass and back (the
forehead lines at half contrast), the untextured face, the textured neutral face (no wrinkles).

The README's comparison (resources/screenshots/texture_band_pass_vs_linear.png) is made from the same two
renders by ``python -m tests.test_textures_screenshots`` (crops of the face, side by side).
"""
from __future__ import annotations

import numpy as np
import pytest

from tests.cli_runner import run_cli
from tests.image_compare import assert_matches_reference, assert_wrong_picture_fails, load_png

SIZE = "960,720"
POSE = ("--weights", "browInnerUp_L=0.5,browInnerUp_R=0.5,mouthSmile_L=0.5,mouthSmile_R=0.5")
SHOTS = {
    "render_sample_texture_band_pass": POSE + ("--texture", "band-pass"),
    "render_sample_texture_linear": POSE + ("--texture", "linear"),
}
UNLIKE = {"render_sample_texture_band_pass": ["render_sample_texture_linear"],
          "render_sample_texture_linear": ["render_sample_texture_band_pass"]}
WRONG = [
    ("render_sample_texture_band_pass", "render_sample_texture_linear"),         # the wrinkles averaged
    ("render_sample_texture_linear", "render_sample_texture_band_pass"),
    ("render_sample_texture_band_pass", POSE),                                   # no texture drawn
    ("render_sample_texture_band_pass", ("--texture", "band-pass")),             # the pose did nothing
    ("render_sample_texture_band_pass", POSE + ("--texture", "band-pass", "--texture-detail", "neutral")),
]


@pytest.fixture(scope="module")
def shoot(tmp_path_factory):
    folder = tmp_path_factory.mktemp("texshots")
    sample = folder / "sample"
    run_cli("sample", "-o", sample)
    shots = {}

    def shoot(args):
        if args not in shots:
            out = folder / f"shot{len(shots)}.png"
            run_cli("render", sample, "-o", out, "--size", SIZE, *args)
            shots[args] = load_png(out)
        return shots[args]
    return shoot


@pytest.mark.parametrize("name", list(SHOTS))
def test_texture_render_matches_its_reference(name, shoot):
    img = shoot(SHOTS[name])
    r, g, b = (img[..., i].astype(int) for i in range(3))
    assert ((r - b) > 25).mean() > 0.1                  # a face, skin-coloured
    assert ((b > r + 30) & (b > 90)).sum() > 30         # the textured eyes' blue irises
    assert_matches_reference(img, name, unlike=UNLIKE[name])


@pytest.mark.parametrize("name, wrong", WRONG, ids=[f"{n}-vs-{w if isinstance(w, str) else ' '.join(w)}"
                                                     for n, w in WRONG])
def test_wrong_texture_render_fails_the_comparison(name, wrong, shoot):
    img = shoot(SHOTS[wrong] if isinstance(wrong, str) else wrong)
    assert_wrong_picture_fails(img, name, unlike=UNLIKE[name])


def test_forehead_lines_are_darker_under_band_pass_in_the_picture(shoot):
    """In the rendered pictures themselves: the forehead's line pixels are further from the skin around them."""
    band, linear = shoot(SHOTS["render_sample_texture_band_pass"]), shoot(SHOTS["render_sample_texture_linear"])
    skin = (band[..., 0].astype(int) - band[..., 2]) > 25                 # the face's pixels, wherever framed
    rows, cols = np.flatnonzero(skin.mean(axis=1) > 0.05), np.flatnonzero(skin.mean(axis=0) > 0.05)
    top, height = rows[0], rows[-1] - rows[0]
    mid, width = (cols[0] + cols[-1]) // 2, cols[-1] - cols[0]
    box = (slice(top + int(0.01 * height), top + int(0.1 * height)),     # the forehead: the face's top tenth
           slice(mid - int(0.25 * width), mid + int(0.25 * width)))

    def line_contrast(img):
        lum = img[box].astype(float).mean(axis=2)
        from scipy.ndimage import uniform_filter
        return float(np.abs(lum - uniform_filter(lum, 9)).mean())

    assert line_contrast(band) > 1.4 * line_contrast(linear)


def write_readme_figure(path="resources/screenshots/texture_band_pass_vs_linear.png") -> None:
    """The README's figure: the two references' faces side by side (band-pass left, linear right)."""
    from tests.image_compare import reference, save_png
    a, b = reference("render_sample_texture_band_pass"), reference("render_sample_texture_linear")
    h, w, _ = a.shape
    crop = (slice(0, int(0.92 * h)), slice(int(0.25 * w), int(0.75 * w)))
    gap = np.full((crop[0].stop - crop[0].start, 8, 3), 255, np.uint8)
    save_png(path, np.concatenate([a[crop], gap, b[crop]], axis=1))


if __name__ == "__main__":
    write_readme_figure()
