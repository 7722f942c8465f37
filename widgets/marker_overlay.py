"""Viewport glyphs for markers (ALGORITHMS.md §8): a sphere on the surface per marker, its target in
another colour and a line between them. Shows what it is given; points are updated in place. Drawn as the
viewport's overlays (``Viewport.add_overlay``)."""
from __future__ import annotations

import numpy as np

MARKER_COLOR = (0.15, 0.75, 1.0)
SELECTED_COLOR = (1.0, 0.85, 0.1)
TARGET_COLOR = (1.0, 0.25, 0.3)
LINE_COLOR = (1.0, 1.0, 1.0)


class MarkerOverlay:
    """Marker and target glyphs on a Viewport (sphere impostors: cheap to move every frame)."""

    def __init__(self, viewport, point_size: float = 14.0) -> None:
        self.viewport = viewport
        self.point_size = point_size
        self._meshes: dict[str, object] = {}
        self._count = -1

    def _actor(self, name: str, mesh, color, size: float, lines: bool = False):
        kw = dict(color=color, lighting=not lines)
        if lines:
            actor = self.viewport.add_overlay(f"marker_overlay_{name}", mesh, line_width=2, **kw)
        else:
            actor = self.viewport.add_overlay(f"marker_overlay_{name}", mesh, render_points_as_spheres=True,
                                              point_size=size, **kw)
        self._meshes[name] = mesh
        return actor

    def clear(self) -> None:
        for name in list(self._meshes):
            self.viewport.remove_overlay(f"marker_overlay_{name}")
        self._meshes.clear()
        self._count = -1

    def show(self, positions: np.ndarray, targets: np.ndarray | None = None, selected: int | None = None) -> None:
        """Markers at ``positions`` (M, 3); if ``targets`` (M, 3) is given, target glyphs and lines too."""
        import pyvista as pv
        P = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
        M = P.shape[0]
        want_targets = targets is not None and M > 0
        key = (M, want_targets, selected)
        if key != self._count:  # the glyph set changed: rebuild (cheap, a few points)
            self.clear()
            self._count = key
            if M == 0:
                return
            self._actor("markers", pv.PolyData(P.copy()), MARKER_COLOR, self.point_size)
            if selected is not None and 0 <= selected < M:
                self._actor("selected", pv.PolyData(P[selected:selected + 1].copy()), SELECTED_COLOR,
                            self.point_size * 1.3)
            if want_targets:
                T = np.asarray(targets, dtype=np.float32).reshape(-1, 3)
                self._actor("targets", pv.PolyData(T.copy()), TARGET_COLOR, self.point_size * 0.8)
                line = pv.PolyData(np.vstack([P, T]))
                line.lines = np.column_stack([np.full(M, 2), np.arange(M), np.arange(M) + M]).reshape(-1)
                self._actor("lines", line, LINE_COLOR, 1.0, lines=True)
            return
        if M == 0:
            return
        self._meshes["markers"].points = P
        if "selected" in self._meshes:
            self._meshes["selected"].points = P[selected:selected + 1]
        if want_targets:
            T = np.asarray(targets, dtype=np.float32).reshape(-1, 3)
            self._meshes["targets"].points = T
            self._meshes["lines"].points = np.vstack([P, T])

    @property
    def n_markers(self) -> int:
        m = self._meshes.get("markers")
        return 0 if m is None else m.n_points
