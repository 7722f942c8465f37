"""Two linked 3D views of a solved take: the blendshape projection with the markers and their error
vectors (left), and the dense result coloured by residual magnitude (right).

Both views are two renderers of ONE render window sharing one camera: a frame is one render pass, which
on software OpenGL is what playback speed hangs on. Topology is uploaded once (``set_surface``), and only the
vertices the drawn faces use; ``show_frame`` writes points, normals and scalars into the meshes' own arrays
and renders. Faces of a studio-scale rig are drawn by one decimated proxy in both views while the frames or the
camera keep changing, and in full once still (``widgets.lod``, as in the main viewport).
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets
from vtkmodules.util.numpy_support import vtk_to_numpy

from solvers.normals import VertexNormals, compact_faces

from .lod import SurfaceDetail
from .scene import ColorMap, SurfaceArrays, add_surface, fit_overlays, rig_mesh, set_camera, style_plotter

MARKER_COLOR = (0.15, 0.85, 0.35)
ERROR_COLOR = (1.0, 0.25, 0.2)
ERROR_SCALE = 10.0  # error vectors are drawn this many times longer than they are


class SideBySideView(QtWidgets.QWidget):
    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        from .native_plotter import NativePlotter
        # No multi-sampling (see Viewport): playback speed on software OpenGL matters more.
        self.plotter = NativePlotter(self, multi_samples=0, shape=(1, 2), border=False)
        self.plotter.resized = self._fit_to_size
        for col in (0, 1):
            self.plotter.subplot(0, col)
            style_plotter(self.plotter, playback=True)  # playback speed: see style_plotter
        self.plotter.enable_trackball_style()
        self.plotter.link_views()  # one camera for both: orbiting either view moves both
        # both surfaces of a studio-scale rig drawn by one proxy of their faces while they change (``widgets.lod``);
        # made after the trackball style, whose button releases it watches
        self.detail = SurfaceDetail(self.plotter.ren_win, self.render)
        self._culled: list = []    # the two surfaces' properties, whose culling follows the camera
        self._forward, self._culling = True, None
        self.plotter.renderers[0].AddObserver("StartEvent", self._update_culling)
        self.setMinimumHeight(200)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.plotter.interactor)
        self.left_mesh = self.right_mesh = None
        self.shown_vertices = np.zeros(0, np.int64)  # the rig vertices the views draw (those the faces use)
        self.marker_cloud = self.error_lines = None
        self.residual_title = "residual (mm)"
        self._focus = None
        self._camera = "front"
        self._framed = None  # the camera position a preset framing left, while the user has not moved it
        self._closed = False  # close_views ran: a reframe queued before it does nothing
        self.plotter.subplot(0, 0)
        self.plotter.add_text(f"blendshape projection, markers, errors x{ERROR_SCALE:g}", position="upper_left",
                              font_size=9, color="white", name="title_left")
        self.plotter.subplot(0, 1)
        self.plotter.add_text("dense result (projection + residual)", position="upper_left", font_size=9,
                              color="white", name="title_right")

    def sizeHint(self) -> QtCore.QSize:  # Qt override: two about-square views, each framing a face
        return QtCore.QSize(680, 340)

    # --- content -----------------------------------------------------------------------------------
    def set_surface(self, points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray, *,
                    focus: np.ndarray | None = None, n_markers: int = 0, clim: tuple[float, float] = (0.0, 1.0),
                    residual_title: str = "residual (mm)", normals: VertexNormals | None = None,
                    keep_camera: bool = False) -> None:
        """Upload a surface's faces with the vertices they use (both views), ``n_markers`` marker spheres and
        error vectors, the colour range. ``normals``: the VertexNormals of these faces renumbered by
        ``compact_faces`` if the caller has one (both views share it; so may the caller's frame cache).
        ``keep_camera``: the views keep where they look (other faces of the same solve), else they frame ``focus``.
        Nothing is drawn: the caller shows a frame next (``show_frame`` renders), one render for the new surface."""
        import pyvista as pv
        p = self.plotter
        self.residual_title = residual_title
        self.shown_vertices, local = compact_faces(face_indices)
        n = len(self.shown_vertices)
        if normals is None or normals.n_points != n:
            normals = VertexNormals(face_counts, local, n)
        shown = np.asarray(points)[self.shown_vertices]
        self.left_mesh = rig_mesh(shown, face_counts, local, normals)
        self.right_mesh = rig_mesh(shown, face_counts, local, normals)
        p.subplot(0, 0)
        add_surface(p, self.left_mesh, name="surface_left", specular=0.0)
        for name in ("markers", "errors"):
            p.remove_actor(name)
        self.marker_cloud = self.error_lines = None
        if n_markers:
            self.marker_cloud = pv.PolyData(np.zeros((n_markers, 3), np.float32))
            p.add_mesh(self.marker_cloud, color=MARKER_COLOR, point_size=6, render_points_as_spheres=True,
                       name="markers", reset_camera=False, lighting=False, render=False)
            lines = np.column_stack([np.full(n_markers, 2), np.arange(n_markers), np.arange(n_markers) + n_markers])
            self.error_lines = pv.PolyData(np.zeros((2 * n_markers, 3), np.float32), lines=lines.ravel())
            p.add_mesh(self.error_lines, color=ERROR_COLOR, line_width=3, name="errors", reset_camera=False,
                       lighting=False, render=False)
            # numpy views of the clouds' own point arrays, rewritten in place each frame
            self._marker_points = vtk_to_numpy(self.marker_cloud.GetPoints().GetData())
            self._line_points = vtk_to_numpy(self.error_lines.GetPoints().GetData())
        p.subplot(0, 1)
        cmap = ColorMap(np.zeros(n, np.float32), title=residual_title, cmap="inferno", clim=clim)
        self._right_actor = add_surface(p, self.right_mesh, cmap, name="surface_right", specular=0.0)
        self._left_arrays = SurfaceArrays(self.left_mesh)
        self._right_arrays = SurfaceArrays(self.right_mesh, scalars="values")
        # Cull the faces turned away from the camera: the views show a face mask from the front, where those
        # are hidden anyway, and software OpenGL then rasterises ~20% less a frame (measured under Xvfb).
        # Which side is "away" follows the winding: the faces' summed normal points forward (+Z) or back.
        # Seen from behind (the user orbited round), culling would hide the whole mask: it is off there.
        self._forward = _faces_forward(shown, normals)
        self._culled = [p.renderers[0].actors["surface_left"].GetProperty(), self._right_actor.GetProperty()]
        self._culling = None
        self._update_culling()
        self.detail.set_meshes([(self.left_mesh, self._left_arrays), (self.right_mesh, self._right_arrays)],
                               face_counts, local, shown)
        self._focus = np.asarray(points if focus is None else focus)
        if not keep_camera:
            self.set_camera(self._camera, render=False)

    def clear(self) -> None:
        """Show nothing: the surfaces, markers, error vectors and residual bar of the last solve go (a new take,
        map or rig was loaded)."""
        p = self.plotter
        self.detail.set_mesh(None)    # a proxy being made for them stops
        for col, names in ((0, ("surface_left", "markers", "errors")), (1, ("surface_right",))):
            p.subplot(0, col)
            for name in names:
                p.remove_actor(name, render=False)
        if self.residual_title in p.scalar_bars:
            p.remove_scalar_bar(self.residual_title, render=False)
        self.left_mesh = self.right_mesh = None
        self.marker_cloud = self.error_lines = None
        self._culled = []
        self.render()

    def show_frame(self, projection: np.ndarray, dense: np.ndarray, residual: np.ndarray,
                   markers: np.ndarray | None = None, fitted: np.ndarray | None = None,
                   normals: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> None:
        """Move both surfaces -- (S, 3) arrays at the shown vertices (``shown_vertices``, in their order: a frame
        cache keeps only those, not the whole rig) -- set the residual scalars (S,) and markers / fitted markers
        (M, 3); render. ``normals``: both surfaces' shading normals there, (S, 3), if already known (else computed
        here)."""
        if self.left_mesh is None:
            return
        proxy = self.detail.expects_proxy()   # a frame the proxy draws computes only the proxy's normals
        self._left_arrays.update(projection, normals[0], defer_normals=proxy)
        self._right_arrays.update(dense, normals[1], residual, defer_normals=proxy)
        if self.marker_cloud is not None and markers is not None:
            m = np.asarray(markers, dtype=np.float32)
            seen = np.isfinite(m).all(axis=1)
            # missing markers sit on their fitted point: no sphere off in space, a zero-length error line
            fit = np.asarray(fitted if fitted is not None else m, dtype=np.float32)
            m = np.where(seen[:, None], m, fit)
            self._marker_points[:] = m
            self._line_points[:len(m)] = fit
            self._line_points[len(m):] = fit + ERROR_SCALE * (m - fit)
            for cloud in (self.marker_cloud, self.error_lines):
                cloud.GetPoints().Modified()
        self.render()

    def _update_culling(self, *_args) -> None:
        """Cull the faces turned away while the camera is in front of the face (+Z side), none from behind."""
        if not self._culled:
            return
        cam = self.plotter.renderers[0].GetActiveCamera()
        front = cam.GetPosition()[2] >= cam.GetFocalPoint()[2]
        if front != self._culling:
            self._culling = front
            for prop in self._culled:
                prop.SetBackfaceCulling(front and self._forward)
                prop.SetFrontfaceCulling(front and not self._forward)

    def culling(self) -> bool:
        """Whether faces turned away are being culled (the camera is in front of the face)."""
        return bool(self._culling)

    def render(self) -> None:
        self.plotter.render()

    # --- queries (tests, screenshots) --------------------------------------------------------------
    def has_residual_bar(self) -> bool:
        return self.residual_title in self.plotter.scalar_bars

    def set_camera(self, name: str, size: tuple[int, int] | None = None, render: bool = True) -> None:
        """Frame both views (one shared camera) from a preset; ``size`` is one view's (w, h); ``render``: draw now."""
        self._camera = name
        if self._focus is not None:
            w, h = self.plotter.window_size
            self.plotter.subplot(0, 0)
            set_camera(self.plotter, name, self._focus, size=size or (max(1, w // 2), h))
            self._framed = None if size else self.plotter.camera_position
            if render:
                self.render()

    def _fit_to_size(self) -> None:
        """The render window took a new size (``NativePlotter.resized``): the residual bar laid out for it and a preset
        framing fitted to it, drawn by the paint the resize brings; a camera the user has orbited or zoomed is left
        alone."""
        if self._closed or self.right_mesh is None:
            return
        self._fit_bar()
        if self._framed is not None and self.plotter.camera_position == self._framed:
            self.set_camera(self._camera, render=False)

    def _fit_bar(self, size: tuple[int, int] | None = None) -> None:
        """The residual bar laid out for the right view at ``size`` (w, h) (default: as it is now)."""
        self.plotter.subplot(0, 1)
        fit_overlays(self.plotter, size)
        self.plotter.subplot(0, 0)

    def grab_image(self, size: tuple[int, int] | None = None) -> np.ndarray:
        """Both views side by side as one (H, W, 3) uint8 image; ``size`` renders each view at (w, h). Drawn in full
        (a proxy is for frames that keep changing), and so is the view it leaves."""
        self.detail.full_only = True
        try:
            self.render()
            if not size:
                return np.asarray(self.plotter.screenshot(return_img=True))[:, :, :3]
            saved = self.plotter.camera_position
            self._fit_bar(size)
            self.set_camera(self._camera, size=size)
            try:
                img = self.plotter.screenshot(return_img=True, window_size=[2 * size[0], size[1]])
                return np.asarray(img)[:, :, :3]
            finally:
                self._fit_bar()
                self.plotter.camera_position = saved
                self.render()
        finally:
            self.detail.full_only = False

    def close_views(self) -> None:
        self._closed = True
        self.detail.stop()      # a proxy being made is stopped and waited for: no VTK thread left at quit
        self.plotter.close()


def _faces_forward(points: np.ndarray, normals: VertexNormals) -> bool:
    """Whether the faces' winding makes their area-weighted normals point toward +Z (the face's front)."""
    return bool(normals.face_normals(points)[:, 2].sum(dtype=np.float64) >= 0)
