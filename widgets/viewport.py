"""The 3D viewport: a VTK plotter (native window, see native_plotter) showing the rig surface, its colour maps and overlays.

It shows what it is given and turns gestures into signals; it holds no algorithm.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from .scene import ColorMap, SurfaceArrays, add_surface, rig_mesh, set_camera, style_plotter


class Viewport(QtWidgets.QWidget):
    """A VTK view of one surface. Update points in place for animation (no re-upload of topology)."""

    picked = QtCore.Signal(int, object)  # (vertex index, picked point xyz) on a left click

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        from .native_plotter import NativePlotter
        # No multi-sampling: on software OpenGL (Xvfb, llvmpipe) 4x MSAA makes a frame of ICT FaceKit
        # cost ~150 ms instead of ~30 ms; interactive speed matters more here than smooth edges.
        self.plotter = NativePlotter(self, multi_samples=0)
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
        self._mouse_filters: list = []
        self.plotter.interactor.installEventFilter(self)
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
        self._arrays = SurfaceArrays(self.mesh)
        self._redraw_surface()
        if reset_camera:
            self.set_camera(self._camera)
        self.render()

    def update_points(self, points: np.ndarray) -> None:
        """Move the surface's vertices (same order and count) and redraw."""
        if self.mesh is None:
            return
        self._arrays.update(points)
        self.render()

    def points(self) -> np.ndarray | None:
        """A copy of the drawn vertices (the mesh's own array is rewritten in place on each update)."""
        return None if self.mesh is None else np.array(self.mesh.points)

    @property
    def colormap(self) -> ColorMap | None:
        """The colour map the surface shows (None: plain shading)."""
        return self._colormap

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

    # --- mouse hooks (marker dragging) -------------------------------------------------------------
    def add_mouse_filter(self, handler) -> None:
        """``handler(kind, x, y, button) -> bool`` sees every mouse press/move/release on the view first,
        with (x, y) in VTK display pixels (bottom-left origin, device pixels). Returning True consumes the
        event, so the camera does not move (e.g. while a marker is dragged)."""
        self._mouse_filters.append(handler)

    def eventFilter(self, obj, event) -> bool:  # Qt override
        kinds = {QtCore.QEvent.MouseButtonPress: "press", QtCore.QEvent.MouseMove: "move",
                 QtCore.QEvent.MouseButtonRelease: "release"}
        kind = kinds.get(event.type())
        if kind is not None and self._mouse_filters and obj is self.plotter.interactor:
            x, y = self.qt_to_display(event.position().x(), event.position().y())
            for handler in self._mouse_filters:
                if handler(kind, x, y, event.button()):
                    return True
        return super().eventFilter(obj, event)

    def pixel_ratio(self) -> float:
        return float(self.plotter.interactor.devicePixelRatioF())

    def qt_to_display(self, x: float, y: float) -> tuple[int, int]:
        """Widget-local Qt position → VTK display pixel (as QVTKRenderWindowInteractor maps events)."""
        s = self.pixel_ratio()
        return int(round(x * s)), int(round((self.plotter.interactor.height() - y - 1) * s))

    def display_to_qt(self, x: float, y: float) -> QtCore.QPointF:
        """VTK display pixel → widget-local Qt position of the interactor widget."""
        s = self.pixel_ratio()
        return QtCore.QPointF(x / s, self.plotter.interactor.height() - 1 - y / s)

    def world_to_display(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points → (N, 3) display coordinates (x, y in pixels, z depth in [0, 1])."""
        ren = self.plotter.renderer
        out = []
        for p in np.asarray(points, dtype=np.float64).reshape(-1, 3):
            ren.SetWorldPoint(float(p[0]), float(p[1]), float(p[2]), 1.0)
            ren.WorldToDisplay()
            out.append(ren.GetDisplayPoint())
        return np.array(out).reshape(-1, 3)

    def display_to_world(self, x: float, y: float, z: float) -> np.ndarray:
        ren = self.plotter.renderer
        ren.SetDisplayPoint(float(x), float(y), float(z))
        ren.DisplayToWorld()
        p = np.array(ren.GetWorldPoint())
        return p[:3] / p[3]

    def view_plane_point(self, x: float, y: float, origin: np.ndarray) -> np.ndarray:
        """Where the ray under display pixel (x, y) meets the plane through ``origin`` facing the camera."""
        near, far = self.display_to_world(x, y, 0.0), self.display_to_world(x, y, 1.0)
        cam = self.plotter.camera
        n = np.array(cam.focal_point) - np.array(cam.position)
        n /= np.linalg.norm(n)
        d = far - near
        denom = float(d @ n)
        if abs(denom) < 1e-12:
            return np.asarray(origin, dtype=np.float64).copy()
        t = float((np.asarray(origin) - near) @ n) / denom
        return near + t * d

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

    def grab_image(self, size: tuple[int, int] | None = None) -> np.ndarray:
        """The rendered image as an (H, W, 3) uint8 array; ``size`` renders it at (w, h) pixels, framed
        by the current camera preset as a viewport of that size would be."""
        self.render()
        if not size:
            return np.asarray(self.plotter.screenshot(return_img=True))[:, :, :3]
        saved = self.plotter.camera_position
        if self._focus is not None:
            set_camera(self.plotter, self._camera, self._focus, size=size)
        try:
            return np.asarray(self.plotter.screenshot(return_img=True, window_size=list(size)))[:, :, :3]
        finally:
            self.plotter.camera_position = saved
            self.render()

    def close_viewport(self) -> None:
        self.plotter.close()
