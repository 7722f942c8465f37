"""Screenshot comparison with a tolerance; on failure the actual and a difference image are written."""
from __future__ import annotations

from pathlib import Path

import numpy as np

REFERENCE_DIR = Path(__file__).parent / "reference"
FAILURE_DIR = Path(__file__).parent / "_failures"


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


def image_difference(actual: np.ndarray, expected: np.ndarray) -> tuple[float, np.ndarray]:
    """(fraction of pixels that differ by more than 32 in some channel, per-pixel max difference)."""
    if actual.shape != expected.shape:
        return 1.0, np.full(expected.shape[:2], 255, np.uint8)
    d = np.abs(actual.astype(np.int16) - expected.astype(np.int16)).max(axis=2)
    return float((d > 32).mean()), d.astype(np.uint8)


def assert_matches_reference(actual: np.ndarray, name: str, tolerance: float = 0.02) -> None:
    """Compare against tests/reference/<name>.png: at most ``tolerance`` of the pixels may differ.

    Set BLENDSHAPE_STUDIO_UPDATE_REFERENCES=1 to (re)write the reference instead.
    """
    import os
    ref_path = REFERENCE_DIR / f"{name}.png"
    if os.environ.get("BLENDSHAPE_STUDIO_UPDATE_REFERENCES") == "1":
        REFERENCE_DIR.mkdir(exist_ok=True)
        save_png(ref_path, actual)
        return
    expected = load_png(ref_path)
    fraction, diff = image_difference(actual, expected)
    if fraction > tolerance:
        FAILURE_DIR.mkdir(exist_ok=True)
        a, d = FAILURE_DIR / f"{name}-actual.png", FAILURE_DIR / f"{name}-diff.png"
        save_png(a, actual)
        save_png(d, np.repeat(np.minimum(diff.astype(int) * 4, 255).astype(np.uint8)[:, :, None], 3, axis=2))
        raise AssertionError(f"screenshot '{name}' differs from {ref_path} in {fraction:.1%} of pixels "
                             f"(tolerance {tolerance:.1%}); actual: {a}, difference: {d}")
