"""Colour maps of the deformation maps and the segmentation, for the viewport and ``render``.

The numbers come from solvers (Joshi §2–3); this module only turns them into colours and legends.
"""
from __future__ import annotations

import numpy as np

from model.errors import RigInputError
from model.rig import Rig
from model.segmentation import (Segmentation, SegmentationCache, SegmentationSettings, check_rig_deforms,
                                segment_rig)
from model.wording import count
from solvers.deformation_maps import deformation_maps, vector_colors
from widgets.scene import ColorMap

BACKGROUND_GREY = np.array([0.55, 0.55, 0.57])


def region_palette(n: int) -> np.ndarray:
    """(n, 3) distinct, saturated colours in [0, 1] (golden-ratio hues, alternating lightness)."""
    import colorsys
    hues = (np.arange(n) * 0.6180339887 + 0.07) % 1.0
    return np.array([colorsys.hsv_to_rgb(h, 0.70 if i % 2 else 0.55, 0.95 if i % 3 else 0.80)
                     for i, h in enumerate(hues)]).reshape(n, 3)


def segmentation_colors(seg: Segmentation, level: int, highlight: int | None = None) -> np.ndarray:
    """(V, 3) uint8: each vertex blends its regions' colours by the partition of unity, so the overlap
    shows as a gradient between neighbours; the background is grey; a highlighted region stays bright."""
    lvl = seg.levels[level]
    colors = np.vstack([region_palette(lvl.n_regions), BACKGROUND_GREY])
    if highlight is not None:
        dim = np.full(len(colors), 0.35)
        dim[highlight] = 1.0
        colors = colors * dim[:, None] + (1 - dim[:, None]) * 0.25
    rgb = np.asarray(lvl.blend @ colors)
    return np.clip(rgb * 255, 0, 255).astype(np.uint8)


def check_level(seg: Segmentation, level: int) -> int:
    if not 0 <= level < len(seg.levels):
        raise RigInputError(f"--level {level} does not exist: this segmentation has levels 0 to {len(seg.levels) - 1}.")
    return level


def deformation_colormap(cache: SegmentationCache, rig: Rig, kind: str, shape: int | None = None,
                         map_kind: str = "laplacian") -> ColorMap:
    """Scalar map (combined or one shape's) with a colour bar in rig units, or the RGB vector view."""
    maps = cache.maps()
    if kind == "deformation-rgb":
        mag = np.abs(maps.vector)
        scale = float(np.percentile(mag[mag > 0], 98)) if (mag > 0).any() else None
        rgb = vector_colors(maps.vector, scale)
        return ColorMap(scalars=(rgb * 255).astype(np.uint8), rgb=True,
                        title=f"Laplacian vector of the strongest shape ({rig.units})",
                        legend=[("+x = red", (1.0, 0.5, 0.5)), ("+y = green", (0.5, 1.0, 0.5)),
                                ("+z = blue", (0.5, 0.5, 1.0))])
    if map_kind == "displacement":
        values = np.linalg.norm(rig.deltas[shape], axis=1) if shape is not None else maps.displacement
        title = f"{'displacement of ' + rig.shape_names[shape] if shape is not None else 'max displacement'}\n({rig.units})"
    else:
        if shape is not None and shape >= maps.per_shape.shape[1]:
            # a shape added after the maps were made (Save as new shape keeps the segmentation and its maps): its map
            values = deformation_maps(cache.laplacian(), rig.deltas[shape:shape + 1]).per_shape[:, 0]
        else:
            values = maps.per_shape[:, shape] if shape is not None else maps.combined
        title = f"{'Laplacian of ' + rig.shape_names[shape] if shape is not None else 'max Laplacian'}\n({rig.units})"
    # Saturate the top few percent so the structure of the map is visible, not only its peaks.
    top = float(np.percentile(values[values > 0], 97)) if (values > 0).any() else 1.0
    return ColorMap(scalars=values, title=title, cmap="inferno", clim=(0.0, top))


def segmentation_colormap(seg: Segmentation, level: int, highlight: int | None = None) -> ColorMap:
    lvl = seg.levels[check_level(seg, level)]
    palette = region_palette(lvl.n_regions)
    legend = [(f"region {i}: {r.core.size} vertices", tuple(palette[i])) for i, r in enumerate(lvl.regions)]
    legend.append((f"background: {lvl.background.size} vertices", tuple(BACKGROUND_GREY)))
    title = (f"level {level} of {len(seg.levels) - 1}: {count(lvl.n_regions, 'region')}"
             + (f", t = {seg.threshold_t:g}" if seg.method == "threshold" else ", region growing"))
    marked = np.flatnonzero(lvl.core_labels() >= 0)
    return ColorMap(scalars=segmentation_colors(seg, level, highlight), rgb=True, title=title, legend=legend,
                    marked=marked)


def map_colormap(rig: Rig, view: str, *, threshold: float | None = None, level: int = 0,
                 settings: SegmentationSettings | None = None) -> ColorMap:
    """The colour map of a view for the command line (computes what it needs once)."""
    if view in ("deformation", "deformation-rgb"):     # not "nothing to segment": no segmentation was asked for
        check_rig_deforms(np.asarray(rig.deltas), "there is no deformation to show")
    cache = SegmentationCache()
    cache.bind(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas)
    if view in ("deformation", "deformation-rgb"):
        return deformation_colormap(cache, rig, view)
    s = settings or (SegmentationSettings() if threshold is None else SegmentationSettings(t=threshold))
    seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, s, cache=cache)
    return segmentation_colormap(seg, level)
