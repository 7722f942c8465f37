"""Two linked 3D views of a solved take: the blendshape projection with the markers and their error
vectors (left), and the dense result coloured by residual magnitude (right).

Topology is uploaded once (``set_surface``); ``show_frame`` moves points and scalars in place and renders
both views. The two renderers share one vtkCamera, so orbiting either view moves both.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from .scene import ColorMap, add_surface, rig_mesh, set_camera, set_points, style_plotter

MARKER_COLOR = (0.15, 0.85, 0.35)
ERROR_COLOR = (1.0, 0.25, 0.2)
ERROR_SCALE = 10.0  # error vectors are drawn this many times longer than they are


class SideBySideView(QtWidgets.QWidget):
    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        from pyvistaqt import QtInteractor
        self.splitter = QtWidgets.QSplitter(QtCore.Qt.Horizontal, self)
        # No multi-sampling (see Viewport): playback speed on software OpenGL matters more.
        self.left = QtInteractor(self.splitter, auto_update=False, multi_samples=0)
        self.right = QtInteractor(self.splitter, auto_update=False, multi_samples=0)
        for p in (self.left, self.right):
            style_plotter(p)
            p.enable_trackball_style()
            self.splitter.addWidget(p.interactor)
        self.splitter.setSizes([1, 1])
        self.setMinimumHeight(340)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.splitter)
        self.right.renderer.SetActiveCamera(self.left.renderer.GetActiveCamera())  # linked cameras
        self.left.iren.add_observer("InteractionEvent", lambda *a: self.right.render())
        self.right.iren.add_observer("InteractionEvent", lambda *a: self.left.render())
        self.left_mesh = self.right_mesh = None
        self.marker_cloud = self.error_lines = None
        self.residual_title = "residual (mm)"
        self._focus = None
        self.left.add_text(f"blendshape projection, markers, errors x{ERROR_SCALE:g}", position="upper_left", font_size=9,
                           color="white", name="title")
        self.right.add_text("dense result (projection + residual)", position="upper_left", font_size=9,
                            color="white", name="title")

    # --- content -----------------------------------------------------------------------------------
    def set_surface(self, points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray, *,
                    focus: np.ndarray | None = None, n_markers: int = 0, clim: tuple[float, float] = (0.0, 1.0),
                    residual_title: str = "residual (mm)") -> None:
        """Upload a surface (both views), ``n_markers`` marker spheres and error vectors, the colour range."""
        self.residual_title = residual_title
        self.left_mesh = rig_mesh(points, face_counts, face_indices)
        self.right_mesh = rig_mesh(points, face_counts, face_indices)
        add_surface(self.left, self.left_mesh)
        cmap = ColorMap(np.zeros(self.right_mesh.n_points, np.float32), title=residual_title, cmap="inferno",
                        clim=clim)
        add_surface(self.right, self.right_mesh, cmap)
        import pyvista as pv
        for name in ("markers", "errors"):
            self.left.remove_actor(name)
        self.marker_cloud = self.error_lines = None
        if n_markers:
            pts = np.zeros((n_markers, 3), np.float32)
            self.marker_cloud = pv.PolyData(pts.copy())
            self.left.add_mesh(self.marker_cloud, color=MARKER_COLOR, point_size=6, render_points_as_spheres=True,
                               name="markers", reset_camera=False, lighting=False)
            lines = np.column_stack([np.full(n_markers, 2), np.arange(n_markers), np.arange(n_markers) + n_markers])
            self.error_lines = pv.PolyData(np.zeros((2 * n_markers, 3), np.float32), lines=lines.ravel())
            self.left.add_mesh(self.error_lines, color=ERROR_COLOR, line_width=3, name="errors",
                               reset_camera=False, lighting=False)
        self._focus = np.asarray(points if focus is None else focus)
        set_camera(self.left, "front", self._focus)
        self.render()

    def set_clim(self, clim: tuple[float, float]) -> None:
        actor = self.right.actors.get("surface")
        if actor is not None:
            actor.mapper.scalar_range = clim

    def show_frame(self, projection: np.ndarray, dense: np.ndarray, residual: np.ndarray,
                   markers: np.ndarray | None = None, fitted: np.ndarray | None = None) -> None:
        """Move both surfaces (V, 3), the residual scalars (V,) and markers / fitted markers (M, 3); render."""
        if self.left_mesh is None:
            return
        set_points(self.left_mesh, projection)
        set_points(self.right_mesh, dense)
        values = self.right_mesh.point_data["values"]
        values[:] = residual
        self.right_mesh.GetPointData().GetArray("values").Modified()
        if self.marker_cloud is not None and markers is not None:
            m = np.asarray(markers, dtype=np.float32)
            seen = np.isfinite(m).all(axis=1)
            # missing markers sit on their fitted point: no sphere off in space, a zero-length error line
            fit = np.asarray(fitted if fitted is not None else m, dtype=np.float32)
            m = np.where(seen[:, None], m, fit)
            self.marker_cloud.points = m
            self.error_lines.points = np.concatenate([fit, fit + ERROR_SCALE * (m - fit)])
        self.render()

    def render(self) -> None:
        self.left.render()
        self.right.render()

    # --- queries (tests, screenshots) --------------------------------------------------------------
    def has_residual_bar(self) -> bool:
        return self.residual_title in self.right.scalar_bars

    def set_camera(self, name: str) -> None:
        if self._focus is not None:
            set_camera(self.left, name, self._focus)
            self.right.reset_camera_clipping_range()
            self.render()

    def grab_image(self, size: tuple[int, int] | None = None) -> np.ndarray:
        """Both views side by side as one (H, W, 3) uint8 image; ``size`` renders each view at (w, h)."""
        self.render()
        kw = {"window_size": list(size)} if size else {}
        a = np.asarray(self.left.screenshot(return_img=True, **kw))[:, :, :3]
        b = np.asarray(self.right.screenshot(return_img=True, **kw))[:, :, :3]
        h = min(a.shape[0], b.shape[0])
        return np.concatenate([a[:h], b[:h]], axis=1)

    def close_views(self) -> None:
        self.left.close()
        self.right.close()
