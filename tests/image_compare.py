"""Screenshot comparison that fails on the nearest wrong picture; on failure the actual and a difference
image are written to tests/_failures.

A picture matches its reference when

1. overall, at most ``tolerance`` of its pixels differ from the reference by more than ``LEVELS`` levels in
   some channel (catches a wrong camera, a missing surface, another view), and
2. for every *wrong picture* named in ``unlike`` (the neutral face for a pose, another hierarchy level for a
   segmentation, ...): inside the region where the reference differs from that wrong picture -- the pixels
   the pose or the setting changes -- at least ``agree`` of the pixels side with the reference: within
   ``LEVELS`` of it and nearer to it than to the wrong picture. A pose whose weights did nothing covers only
   a small share of the whole image (a neutral face is 0.6 % off the "happy" one), but it fails here, since
   inside the region the smile changes it looks like the neutral, not like the reference.

The region must hold at least ``MIN_CHANGED`` pixels: a reference (re)generated while the feature did
nothing would not differ from the wrong picture, and fails every comparison instead of passing them all.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

REFERENCE_DIR = Path(__file__).parent / "reference"
FAILURE_DIR = Path(__file__).parent / "_failures"
LEVELS = 32          # a pixel differs when some channel is more than this many levels (of 255) off
AGREE = 0.8          # share of the changed region that must side with the reference
MIN_CHANGED = 200    # pixels the reference must differ from each wrong picture in


def load_png(path) -> np.ndarray:
    from PySide6.QtGui import QImage
    img = QImage(str(path))
    if img.isNull():
        raise FileNotFoundError(f"cannot read image {path}")
    img = img.convertToFormat(QImage.Format_RGB888)
    w, h, bpl = img.width(), img.height(), img.bytesPerLine()
    arr = np.frombuffer(img.constBits(), dtype=np.uint8, count=bpl * h).reshape(h, bpl)
    return arr[:, : w * 3].reshape(h, w, 3).copy()


def save_png(path, image: np.ndarray) -> None:
    from PySide6.QtGui import QImage
    image = np.ascontiguousarray(image, dtype=np.uint8)
    h, w, _ = image.shape
    QImage(image.data, w, h, 3 * w, QImage.Format_RGB888).copy().save(str(path))


def pixel_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(H, W) the largest per-channel difference of two images of one size, in levels."""
    return np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=2)


def image_difference(actual: np.ndarray, expected: np.ndarray) -> tuple[float, np.ndarray]:
    """(fraction of pixels that differ by more than LEVELS in some channel, per-pixel max difference)."""
    if actual.shape != expected.shape:
        return 1.0, np.full(expected.shape[:2], 255, np.uint8)
    d = pixel_difference(actual, expected)
    return float((d > LEVELS).mean()), d.astype(np.uint8)


def reference(name: str) -> np.ndarray:
    return load_png(REFERENCE_DIR / f"{name}.png")


def side_with_reference(actual: np.ndarray, expected: np.ndarray, wrong: np.ndarray) -> tuple[int, float]:
    """(pixels where ``expected`` differs from ``wrong``, the share of them where ``actual`` sides with
    ``expected``: within LEVELS of it and nearer to it than to ``wrong``)."""
    changed = pixel_difference(expected, wrong) > LEVELS
    n = int(changed.sum())
    if n == 0 or actual.shape != expected.shape:
        return n, 0.0
    to_ref, to_wrong = pixel_difference(actual, expected)[changed], pixel_difference(actual, wrong)[changed]
    return n, float(((to_ref <= LEVELS) & (to_ref < to_wrong)).mean())


def compare_to_reference(actual: np.ndarray, name: str, tolerance: float = 0.02, unlike=(),
                         agree: float = AGREE) -> tuple[list[str], np.ndarray]:
    """(what is wrong with ``actual`` as tests/reference/<name>.png -- empty when it matches --, difference
    image). ``unlike`` names the references of the nearest wrong pictures (see the module's docstring)."""
    expected = reference(name)
    fraction, diff = image_difference(actual, expected)
    problems = []
    if fraction > tolerance:
        problems.append(f"differs from {name}.png in {fraction:.1%} of pixels (tolerance {tolerance:.1%})")
    for other in unlike:
        n, share = side_with_reference(actual, expected, reference(other))
        if n < MIN_CHANGED:
            problems.append(f"the reference {name}.png differs from the wrong picture {other}.png in only {n} "
                            f"pixels (at least {MIN_CHANGED} needed): the reference does not show the change")
        elif share < agree:
            problems.append(f"where {name}.png differs from the wrong picture {other}.png ({n} pixels) only "
                            f"{share:.0%} of the pixels side with {name}.png (at least {agree:.0%} needed)")
    return problems, diff


def _write_failure(actual: np.ndarray, diff: np.ndarray, name: str) -> tuple[Path, Path]:
    FAILURE_DIR.mkdir(exist_ok=True)
    a, d = FAILURE_DIR / f"{name}-actual.png", FAILURE_DIR / f"{name}-diff.png"
    save_png(a, actual)
    save_png(d, np.repeat(np.minimum(diff.astype(int) * 4, 255).astype(np.uint8)[:, :, None], 3, axis=2))
    return a, d


def assert_matches_reference(actual: np.ndarray, name: str, tolerance: float = 0.02, unlike=(),
                             agree: float = AGREE) -> None:
    """Compare against tests/reference/<name>.png (see the module's docstring); raise AssertionError naming
    what is wrong and where the actual and difference images were written.

    Set BLENDSHAPE_STUDIO_UPDATE_REFERENCES=1 to (re)write the reference instead (then look at it).
    """
    if os.environ.get("BLENDSHAPE_STUDIO_UPDATE_REFERENCES") == "1":
        REFERENCE_DIR.mkdir(exist_ok=True)
        save_png(REFERENCE_DIR / f"{name}.png", actual)
        return
    problems, diff = compare_to_reference(actual, name, tolerance, unlike, agree)
    if problems:
        a, d = _write_failure(actual, diff, name)
        raise AssertionError(f"screenshot '{name}': " + "; ".join(problems) + f"; actual: {a}, difference: {d}")


def assert_wrong_picture_fails(wrong: np.ndarray, name: str, tolerance: float = 0.02, unlike=(),
                               agree: float = AGREE) -> list[str]:
    """The twin of ``assert_matches_reference``: a wrong picture must NOT pass as tests/reference/<name>.png
    with the same settings. Returns the reasons it fails."""
    problems, _ = compare_to_reference(wrong, name, tolerance, unlike, agree)
    assert problems, f"a wrong picture passed as the screenshot '{name}' (unlike {list(unlike)})"
    return problems


def assert_large_and_whole(img: np.ndarray) -> None:
    """The shaded surface (warm skin tone: red well above blue, not the grey-blue backdrop) covers more than 15% of
    ``img`` and touches none of its edges: the model framed whole, nothing cut at the picture's sides."""
    i = np.asarray(img).astype(int)
    skin = i[..., 0] - i[..., 2] > 25
    assert skin.mean() > 0.15
    rows, cols = np.flatnonzero(skin.any(axis=1)), np.flatnonzero(skin.any(axis=0))
    assert rows.min() > 2 and rows.max() < skin.shape[0] - 3 and cols.min() > 2 and cols.max() < skin.shape[1] - 3
