"""What a view shows: the posed points plus an optional colour map, for the viewport and ``render``.

A view is computed here (app layer, calling solvers) and drawn by widgets.scene.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from model.errors import RigInputError
from model.pose import PoseEvaluator
from model.rig import Rig
from model.segmentation import SegmentationSettings
from model.rig_prep import focus_vertices, framed_points, shape_reach
from widgets.scene import ColorMap

VIEWS = ("shaded", "deformation", "deformation-rgb", "segmentation")


@dataclass
class View:
    points: np.ndarray
    focus: np.ndarray | None   # what the camera frames (model.rig_prep.focus_vertices); None: the posed points
    colormap: ColorMap | None
    title: str


def build_view(rig: Rig, weights: np.ndarray, view: str = "shaded", *, level: int = 0,
               settings: SegmentationSettings | None = None) -> View:
    if view not in VIEWS:
        raise RigInputError(f"Unknown view '{view}': use one of {', '.join(VIEWS)}.")
    points = PoseEvaluator(rig).evaluate(weights)
    focus = focus_vertices(rig.neutral, shape_reach(rig))
    if view == "shaded":
        return View(points, focus, None, "shaded")
    from app.map_views import map_colormap
    colormap = map_colormap(rig, view, level=level, settings=settings)
    return View(points, framed_points(focus, points, colormap.marked), colormap, view)

