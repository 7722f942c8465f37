"""Band-pass blending of per-shape textures (Joshi, Tien, Desbrun, Pighin 2003, "Learning Controls for
Blend Shape Based Realistic Facial Animation", §5; ALGORITHMS.md §10). Functions over arrays, Qt-free.

Blending the textures of the shapes linearly, ``T(α) = T_0 + Σ_k α_k (T_k − T_0)``, averages fine detail
away: two shapes at 0.5 each show their wrinkles at half contrast. Joshi splits every texture into two
bands of a Laplacian pyramid,

    L_k = G_σ * T_k          (low band: a Gaussian blur of σ texels)
    D_k = T_k − L_k          (detail band; L_k + D_k = T_k exactly),

blends only the low bands by the weights and takes the detail band whole from one shape:

    T(α) = L_0 + Σ_k α_k (L_k − L_0) + D_s                                  (Joshi §5)

The detail source ``s`` is the neutral, the dominant shape (the largest α_k among the shapes that have a
texture), or — per texel, the "per-region choice" — the shape with the largest ``α_k m_k`` where ``m_k`` is
where shape k's texture differs from the neutral's (its own support); where no shape has a positive score the
neutral's detail stays. Texels under the keep mask ``M`` (hair, neck, ears: what must not change) show the
neutral: ``T ← T + M (T_0 − T)``. The two levels are kept at full resolution (a Laplacian stack, no
decimation), so the bands add back exactly and a blend needs no upsampling.

``TextureBlender`` evaluates this live: each shape's difference from the neutral is stored only over the box
where it differs, and a weight change recomputes only the boxes of the shapes whose weights changed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

MODES = ("band-pass", "linear")
DETAIL_SOURCES = ("regional", "dominant", "neutral")
TRUNCATE = 3.0          # Gaussian kernel radius in σ
SUPPORT_TOL = 1.0 / 64  # a texel belongs to a shape's support where its texture differs by more than this


def low_pass(image: np.ndarray, sigma: float) -> np.ndarray:
    """``G_σ * image`` per channel (edges repeated), float32."""
    image = np.asarray(image, dtype=np.float32)
    s = (sigma, sigma) + (0,) * (image.ndim - 2)
    return gaussian_filter(image, sigma=s, mode="nearest", truncate=TRUNCATE)


def split_bands(image: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """The two-level Laplacian pyramid ``(L, D)`` of an image: ``L = G_σ * T``, ``D = T − L``."""
    image = np.asarray(image, dtype=np.float32)
    low = low_pass(image, sigma)
    return low, image - low


def default_sigma(size: int) -> float:
    """The low band's blur for a texture ``size`` texels across: 8 texels at 1024 (about 2 mm on a face; a
    wrinkle line is finer, the spacing of forehead lines coarser)."""
    return max(1.0, size / 128.0)


def support(shape: np.ndarray, neutral: np.ndarray, sigma: float) -> np.ndarray:
    """``m_k`` in [0, 1]: where a shape's texture differs from the neutral's (its largest channel
    difference, blurred by σ, over SUPPORT_TOL, clipped)."""
    diff = np.abs(np.asarray(shape, np.float32) - np.asarray(neutral, np.float32))
    diff = diff.max(axis=2) if diff.ndim == 3 else diff
    return np.clip(low_pass(diff, sigma) / SUPPORT_TOL, 0.0, 1.0)


@dataclass
class _Shape:
    k: int                   # index into the weights
    box: tuple[slice, slice]
    dlow: np.ndarray         # (L_k − L_0) over box
    ddetail: np.ndarray      # (D_k − D_0) over box
    m: np.ndarray            # support over box


def _box_of(mask: np.ndarray, pad: int) -> tuple[slice, slice] | None:
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return None
    H, W = mask.shape
    return (slice(max(rows[0] - pad, 0), min(rows[-1] + 1 + pad, H)),
            slice(max(cols[0] - pad, 0), min(cols[-1] + 1 + pad, W)))


def _intersect(a: tuple[slice, slice], b: tuple[slice, slice]):
    """(the intersection in image coordinates, in a's coordinates, in b's coordinates) or None."""
    r0, r1 = max(a[0].start, b[0].start), min(a[0].stop, b[0].stop)
    c0, c1 = max(a[1].start, b[1].start), min(a[1].stop, b[1].stop)
    if r0 >= r1 or c0 >= c1:
        return None
    return ((slice(r0 - a[0].start, r1 - a[0].start), slice(c0 - a[1].start, c1 - a[1].start)),
            (slice(r0 - b[0].start, r1 - b[0].start), slice(c0 - b[1].start, c1 - b[1].start)))


class TextureBlender:
    """Live band-pass (or linear) blending of a neutral texture and per-shape textures (module docstring).

    ``neutral`` (H, W, 3) in [0, 1]; ``shapes`` a list of K images of the neutral's size or None (a shape
    without its own texture keeps the neutral's); ``keep`` (H, W) in [0, 1], 1 where the neutral must stay.
    ``set_weights`` updates ``image`` (float32) and ``image8`` (uint8, what a viewport uploads) in place and
    returns the boxes it rewrote; ``bands()`` gives the current low and detail bands.
    """

    def __init__(self, neutral: np.ndarray, shapes: list[np.ndarray | None], *, sigma: float | None = None,
                 keep: np.ndarray | None = None, mode: str = "band-pass", detail: str = "regional") -> None:
        neutral = np.asarray(neutral, dtype=np.float32)
        if neutral.ndim != 3 or neutral.shape[2] != 3:
            raise ValueError("the neutral texture must be an (H, W, 3) image")
        H, W = neutral.shape[:2]
        self.sigma = float(sigma if sigma is not None else default_sigma(max(H, W)))
        self.neutral = neutral
        self.low0, detail0 = split_bands(neutral, self.sigma)
        del detail0
        self.keep = None if keep is None else np.clip(np.asarray(keep, np.float32), 0, 1)
        if self.keep is not None and self.keep.shape != (H, W):
            raise ValueError("the keep mask must have the neutral texture's size")
        self.n_shapes = len(shapes)
        self.shapes: list[_Shape] = []
        pad = int(TRUNCATE * self.sigma + 1.5)
        for k, img in enumerate(shapes):
            if img is None:
                continue
            img = np.asarray(img, dtype=np.float32)
            if img.shape != neutral.shape:
                raise ValueError(f"shape texture {k} is {img.shape[1]}x{img.shape[0]}, the neutral's {W}x{H}")
            box = _box_of(np.abs(img - neutral).max(axis=2) > 0.5 / 255, pad)
            if box is None:
                continue   # the neutral's texture again: nothing to blend
            sub, sub0 = img[box], neutral[box]
            diff = sub - sub0
            dlow = low_pass(diff, self.sigma)   # L_k − L_0 = G_σ * (T_k − T_0); the box reaches 3σ beyond
            ddetail = diff - dlow               # the differences, so the blur over the box is exact
            self.shapes.append(_Shape(k, box, dlow, ddetail, support(sub, sub0, self.sigma)))
        self.textured = np.zeros(self.n_shapes, bool)
        self.textured[[s.k for s in self.shapes]] = True
        self.mode, self.detail = "band-pass", "regional"
        self.weights = np.zeros(self.n_shapes)
        self.image = neutral.copy()
        self.low = self.low0.copy()
        self.image8 = np.empty((H, W, 3), np.uint8)
        self._full = (slice(0, H), slice(0, W))
        self.set_mode(mode, detail)

    # --- state ----------------------------------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        return self.neutral.shape[1], self.neutral.shape[0]

    def set_mode(self, mode: str, detail: str | None = None) -> None:
        """Switch between 'band-pass' and 'linear' (and the detail source); recomputes the whole image."""
        if mode not in MODES:
            raise ValueError(f"unknown texture blend '{mode}': use one of {', '.join(MODES)}")
        detail = self.detail if detail is None else detail
        if detail not in DETAIL_SOURCES:
            raise ValueError(f"unknown detail source '{detail}': use one of {', '.join(DETAIL_SOURCES)}")
        self.mode, self.detail = mode, detail
        self._recompute(self._full)

    def set_keep(self, keep: np.ndarray | None) -> None:
        """A new keep mask (None: none); recomputes the whole image."""
        self.keep = None if keep is None else np.clip(np.asarray(keep, np.float32), 0, 1)
        self._recompute(self._full)

    def dominant(self, weights: np.ndarray | None = None) -> int:
        """The textured shape with the largest positive weight, or -1 (the neutral)."""
        w = self.weights if weights is None else np.asarray(weights, dtype=np.float64)
        if not self.textured.any():
            return -1
        masked = np.where(self.textured, w, -np.inf)
        k = int(np.argmax(masked))
        return k if masked[k] > 0 else -1

    def set_weights(self, weights: np.ndarray) -> list[tuple[slice, slice]]:
        """Blend for new weights, rewriting only what they change; returns the rewritten boxes."""
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (self.n_shapes,):
            raise ValueError(f"{w.size} weights for {self.n_shapes} shapes")
        changed = (w != self.weights) & self.textured
        boxes = [s.box for s in self.shapes if changed[s.k]]
        if self.mode == "band-pass" and self.detail == "dominant":
            old, new = self.dominant(), self.dominant(w)
            if old != new:
                boxes += [s.box for s in self.shapes if s.k in (old, new)]
        self.weights = w.copy()
        boxes = _merge(boxes)
        for box in boxes:
            self._recompute(box)
        return boxes

    def bands(self) -> tuple[np.ndarray, np.ndarray]:
        """The current blend's (low band, detail band), float32 (H, W, 3); they add up to ``image``."""
        return self.low, self.image - self.low

    # --- evaluation -----------------------------------------------------------------------------------
    def _recompute(self, box: tuple[slice, slice]) -> None:
        low = self.low0[box].copy()
        w = self.weights
        linear = self.mode == "linear"
        detail = np.zeros_like(low) if linear or self.detail != "neutral" else None
        best = np.zeros(low.shape[:2], np.float32) if not linear and self.detail == "regional" else None
        dom = self.dominant() if not linear and self.detail == "dominant" else -2
        for s in self.shapes:
            cut = _intersect(box, s.box)
            if cut is None:
                continue
            here, there = cut
            wk = w[s.k]
            if wk != 0:
                low[here] += np.float32(wk) * s.dlow[there]
            if linear:
                if wk != 0:
                    detail[here] += np.float32(wk) * s.ddetail[there]
            elif best is not None and wk > 0:
                score = np.float32(wk) * s.m[there]
                better = score > best[here]
                np.maximum(best[here], score, out=best[here])
                np.copyto(detail[here], s.ddetail[there], where=better[..., None])
            elif s.k == dom:
                detail[here] = s.ddetail[there]
        d0 = self.neutral[box] - self.low0[box]
        image = low + d0
        if detail is not None:
            image += detail
        if self.keep is not None:
            keep = self.keep[box][..., None]
            image += keep * (self.neutral[box] - image)
            low += keep * (self.low0[box] - low)
        self.low[box] = low
        self.image[box] = image
        np.clip(image * 255.0 + 0.5, 0, 255, out=image)
        self.image8[box] = image


def _merge(boxes: list[tuple[slice, slice]]) -> list[tuple[slice, slice]]:
    """Overlapping boxes joined into their bounding box (a texel is never recomputed twice)."""
    boxes = list(dict.fromkeys((b[0].start, b[0].stop, b[1].start, b[1].stop) for b in boxes))
    merged = True
    while merged and len(boxes) > 1:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]:
                    boxes[i] = (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return [(slice(r0, r1), slice(c0, c1)) for r0, r1, c0, c1 in boxes]


def blend_once(neutral: np.ndarray, shapes: list[np.ndarray | None], weights: np.ndarray, *, mode: str = "band-pass",
               detail: str = "regional", sigma: float | None = None, keep: np.ndarray | None = None) -> np.ndarray:
    """One blend (float32 (H, W, 3)), for a render or a test: ``TextureBlender`` without the live state."""
    b = TextureBlender(neutral, shapes, sigma=sigma, keep=keep, mode=mode, detail=detail)
    b.set_weights(weights)
    return b.image
