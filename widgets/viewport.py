"""The 3D viewport: a pyvistaqt interactor showing the rig surface, its colour maps and overlays.

It shows what it is given and turns gestures into signals; it holds no algorithm.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from .scene import ColorMap, add_surface, rig_mesh, set_camera, style_plotter


class Viewport(QtWidgets.QWidget):
    """A VTK view of one surface. Update points in place for animation (no re-upload of topology)."""

    picked = QtCore.Signal(int, object)  # (vertex index, picked point xyz) on a left click

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        from pyvistaqt import QtInteractor
        self.plotter = QtInteractor(self, auto_update=False)
        style_plotter(self.plotter)
        self.plotter.enable_trackball_style()
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.plotter.interactor)
        self.mesh = None
        self._faces = None
        self._focus = None
        self._colormap: ColorMap | None = None
        self._wireframe = False
        self._camera = "front"
        self._press_pos = None
        iren = self.plotter.iren
        iren.add_observer("LeftButtonPressEvent", self._on_left_press)
        iren.add_observer("LeftButtonReleaseEvent", self._on_left_release)

    # --- content -----------------------------------------------------------------------------------
    def set_surface(self, points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
                    focus: np.ndarray | None = None, *, reset_camera: bool = True) -> None:
        """Show a new surface (a new rig): topology is uploaded once here."""
        self._faces = (face_counts, face_indices)
        self._focus = focus if focus is not None else points
        self.mesh = rig_mesh(points, face_counts, face_indices)
        self._redraw_surface()
        if reset_camera:
            self.set_camera(self._camera)
        self.render()

    def update_points(self, points: np.ndarray) -> None:
        """Move the surface's vertices (same order and count) and redraw."""
        if self.mesh is None:
            return
        self.mesh.points = np.asarray(points, dtype=np.float32)
        self.render()

    def points(self) -> np.ndarray | None:
        return None if self.mesh is None else np.asarray(self.mesh.points)

    def set_colormap(self, colormap: ColorMap | None) -> None:
        self._colormap = colormap
        if self.mesh is not None:
            self._redraw_surface()
            self.render()

    def set_wireframe(self, on: bool) -> None:
        self._wireframe = bool(on)
        if self.mesh is not None:
            self._redraw_surface()
            self.render()

    @property
    def wireframe(self) -> bool:
        return self._wireframe

    def _redraw_surface(self) -> None:
        self.plotter.remove_scalar_bar() if self.plotter.scalar_bars else None
        # point data from a previous colour map must not leak into the next one
        for key in ("values", "colors"):
            if key in self.mesh.point_data:
                del self.mesh.point_data[key]
        add_surface(self.plotter, self.mesh, self._colormap, wireframe=self._wireframe)

    # --- picking -----------------------------------------------------------------------------------
    def pick(self, x: int, y: int):
        """(vertex index, point) under display pixel (x, y from the bottom-left), or None."""
        import vtk
        if self.mesh is None:
            return None
        picker = vtk.vtkCellPicker()
        picker.SetTolerance(0.0005)
        if not picker.Pick(x, y, 0, self.plotter.renderer) or picker.GetCellId() < 0:
            return None
        if picker.GetDataSet() is None or picker.GetDataSet().GetNumberOfPoints() != self.mesh.n_points:
            return None
        point = np.array(picker.GetPickPosition())
        cell = self.mesh.get_cell(picker.GetCellId())
        ids = np.asarray(cell.point_ids)
        pts = np.asarray(self.mesh.points)[ids]
        return int(ids[np.argmin(np.linalg.norm(pts - point, axis=1))]), point

    def _on_left_press(self, *args) -> None:
        self._press_pos = self.plotter.iren.get_event_position()

    def _on_left_release(self, *args) -> None:
        pos = self.plotter.iren.get_event_position()
        if self._press_pos is not None and abs(pos[0] - self._press_pos[0]) + abs(pos[1] - self._press_pos[1]) <= 3:
            hit = self.pick(*pos)
            if hit is not None:
                self.picked.emit(hit[0], hit[1])
        self._press_pos = None

    # --- camera ------------------------------------------------------------------------------------
    def set_camera(self, name: str) -> None:
        self._camera = name
        if self._focus is not None:
            set_camera(self.plotter, name, self._focus)
            self.render()

    def reset_view(self) -> None:
        self.set_camera(self._camera)

    def render(self) -> None:
        self.plotter.render()

    def grab_image(self) -> np.ndarray:
        """The rendered image as an (H, W, 3) uint8 array."""
        self.render()
        return np.asarray(self.plotter.screenshot(return_img=True))

    def close_viewport(self) -> None:
        self.plotter.close()
