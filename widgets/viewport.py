"""The 3D viewport: a VTK plotter (native window, see native_plotter) showing the rig surface, its colour maps and overlays.

It shows what it is given and turns gestures into requests; it holds no algorithm. Tools (marker dragging,
sculpt brushes) use its gesture API and never its VTK internals:

- ``push_tool(tool)`` / ``remove_tool(tool)``: the tool (a ``ViewportTool``) is offered every mouse press on
  the view, most recently pushed first. The tool that takes a press (``press`` returns True) owns the gesture:
  it gets its ``drag`` and ``release`` and the camera stays still. Moves with no button held are ``hover``s.
  A press no tool takes turns the camera; a click (press and release within a few pixels) that no tool took
  emits ``picked`` with the surface point under it.
- Each call gets a ``Gesture``: the display position, the button, the surface point under the cursor
  (``SurfacePoint``: vertex, face, world position; picked only when read) and the view-plane ``motion`` since
  the press (the world-space displacement in the plane through the gesture's anchor facing the camera).
- Overlays (``add_overlay`` / ``remove_overlay``): meshes drawn over the surface, never picked, never reframed.
  A tool that moves one asks for a render (``request_render``): one render on the event loop's next turn, or none
  if the view renders before then. The window's pose changes ask the same way (``before_render`` uploads the pose):
  a tool's overlay and the pose the same mouse move changed are drawn by one render.
- Camera and conversions: ``camera_frame()``, ``world_to_display``, ``display_to_world``, ``display_to_qt``,
  ``view_plane_point``; ``canvas`` is the Qt widget that receives the mouse.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import numpy as np
from PySide6 import QtCore, QtWidgets

from model.parts import subset_faces
from model.rig_prep import framed_points

from .lod import SurfaceDetail
from .picking import FacePicker, display_to_world
from .scene import ColorMap, SurfaceArrays, add_surface, copy_cached_background, drop_cached_background, fit_overlays, \
    overlay_room, rig_mesh, set_camera, style_plotter, surface_face

CLICK_SLOP_PX = 3   # a press and release this close (display pixels, |dx| + |dy|) is a click


@dataclass(frozen=True)
class SurfacePoint:
    """A point on the shown surface: the picked face (the rig's polygon index), its vertex nearest the point,
    and the point itself (world coordinates)."""

    vertex: int
    face: int
    position: np.ndarray


@dataclass(frozen=True)
class CameraFrame:
    """Where the camera is and which way it looks: unit ``forward`` (eye to focal point), ``up`` and ``right``."""

    position: np.ndarray
    focal_point: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    right: np.ndarray


class Gesture:
    """One mouse event of a gesture, as a tool sees it: ``kind`` ("press", "drag", "release", "hover"),
    display pixel ``x``, ``y`` (VTK's: bottom-left origin, device pixels), the ``button`` pressed (a
    Qt.MouseButton; NoButton for a hover) and the display position of the ``start`` (the press)."""

    def __init__(self, viewport: "Viewport", kind: str, x: int, y: int, button, start: tuple[int, int],
                 anchor: np.ndarray | None) -> None:
        self.viewport, self.kind, self.x, self.y, self.button, self.start = viewport, kind, x, y, button, start
        self._anchor = anchor

    @cached_property
    def point(self) -> SurfacePoint | None:
        """The surface point under the cursor, or None off the surface (picked on first use)."""
        return self.viewport.pick(self.x, self.y)

    @property
    def anchor(self) -> np.ndarray | None:
        """The world point the gesture drags: by default the surface point under the press. A tool that takes
        a press may set it (a marker's position) so that ``motion`` is measured in the plane through it."""
        if self._anchor is None and self.kind == "press" and self.point is not None:
            self._anchor = np.asarray(self.point.position, dtype=np.float64)
        return self._anchor

    @anchor.setter
    def anchor(self, world) -> None:
        self._anchor = np.asarray(world, dtype=np.float64)

    @property
    def motion(self) -> np.ndarray:
        """(3,) world-space displacement from the press to now in the plane through ``anchor`` facing the
        camera (zero without an anchor)."""
        if self.anchor is None:
            return np.zeros(3)
        vp = self.viewport
        return vp.view_plane_point(self.x, self.y, self.anchor) - vp.view_plane_point(*self.start, self.anchor)


class ViewportTool:
    """What a viewport tool implements (every method optional). ``press`` returns True to take the gesture."""

    def press(self, gesture: Gesture) -> bool:
        return False

    def drag(self, gesture: Gesture) -> None:
        pass

    def release(self, gesture: Gesture) -> None:
        pass

    def hover(self, gesture: Gesture) -> None:
        pass


class Viewport(QtWidgets.QWidget):
    """A VTK view of one surface. Update points in place for animation (no re-upload of topology)."""

    picked = QtCore.Signal(int, object)  # (vertex index, picked point xyz) on a left click no tool took

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        from .native_plotter import NativePlotter
        # No multi-sampling: on software OpenGL (Xvfb, llvmpipe) 4x MSAA makes a frame of ICT FaceKit
        # cost ~150 ms instead of ~30 ms; interactive speed matters more here than smooth edges.
        self.plotter = NativePlotter(self, multi_samples=0)
        self.plotter.resized = self._fit_to_size
        style_plotter(self.plotter)
        copy_cached_background(self.plotter.renderer)   # the gradient copied into each frame, not drawn anew
        # Translucent overlays (the sculpt brush's cursor, a wireframe at 30% opacity) blended as drawn, not by VTK's
        # order-independent translucency: its extra full-window passes cost ~9 ms a frame of ICT on llvmpipe, for a
        # picture within 2 of 255 levels of the same (one translucent layer over the opaque surface).
        self.plotter.renderer.SetUseOIT(False)
        self.plotter.enable_trackball_style()
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.plotter.interactor)
        self.mesh = None
        self._arrays: SurfaceArrays | None = None
        self._given_normals: tuple[np.ndarray, np.ndarray] | None = None   # use_normals
        self._focus = None
        self._framed = None   # the last framing: (points or None: the focus, direction or None: the preset's,
        #                       camera position, room)
        self._colormap: ColorMap | None = None
        self._wireframe = False
        self._textured = None   # widgets.texture_view.TexturedSurface while a texture is shown
        self._texture_split = None   # its model.textures.DisplaySplit (of every face)
        self._face_counts: np.ndarray | None = None   # of the faces drawn
        self._all_faces: tuple[np.ndarray, np.ndarray] | None = None   # the surface's faces, every part
        self._prepared = None   # the default view's faces prepared off the GUI thread (``model.rig_prep.DefaultView``)
        self._shown_faces: np.ndarray | None = None   # the faces drawn (set_parts), None: all
        self._base_colors: np.ndarray | None = None   # the parts' colours (set_parts)
        self._camera = "front"
        self._tools: list[ViewportTool] = []
        self._owner: ViewportTool | None = None      # the tool whose gesture is under way
        self._press: tuple | None = None             # that gesture's (start, button, anchor)
        self._click: tuple[int, int] | None = None   # a left press no tool took: a click if released near it
        self._picker = None    # widgets.picking.FacePicker, made at the first pick
        self._render_requested = False   # request_render
        self._after_render: list[Callable[[], None]] = []   # what waits for the requested render (``when_drawn``)
        # the owner brings what the view shows up to date before each render (the window: the pose, ``render``)
        self.before_render: Callable[[], None] = lambda: None
        # an expose while a render is requested shows the last picture until that render (NativePlotter.paintEvent)
        self.plotter.render_pending = lambda: self._render_requested
        self.plotter.interactor.installEventFilter(self)
        # a studio-scale surface is drawn by fewer faces while it keeps changing (``widgets.lod``)
        self.detail = SurfaceDetail(self.plotter.ren_win, self.render,
                                    allowed=lambda: not self._wireframe and not self.textured)

    @property
    def canvas(self) -> QtWidgets.QWidget:
        """The Qt widget the view is drawn in and that receives the mouse."""
        return self.plotter.interactor

    # --- content -----------------------------------------------------------------------------------
    def set_surface(self, points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
                    focus: np.ndarray | None = None, *, reset_camera: bool = True,
                    shown_faces: np.ndarray | None = None, base_colors: np.ndarray | None = None,
                    prepared=None, render: bool = True) -> None:
        """Show a new surface (a new rig): topology is uploaded once here. ``shown_faces`` and ``base_colors``:
        see ``set_parts``. ``prepared``: ``model.rig_prep.DefaultView``, made off the GUI thread: its hidden back
        faces and normals are used whenever the faces drawn are its faces. ``render`` False: drawn by the caller's
        next render (the window's, on the event loop's next turn)."""
        self._focus = None if focus is None else np.asarray(focus, dtype=np.float64).reshape(-1, 3)
        self._prepared = prepared
        if self._colormap is not None and len(self._colormap.scalars) != len(points):
            self._colormap = None   # the last rig's colours: its owner sets the new rig's when they are ready
        self._all_faces = (np.asarray(face_counts), np.asarray(face_indices))
        self._texture_split = None   # a new rig: its owner sets its texture when it is ready
        self._textured = None
        self._build_mesh(points, shown_faces, base_colors)
        if reset_camera:
            self.set_camera(self._camera, render=False)   # one render for the new surface, not two
        if render:
            self.render()

    def set_parts(self, shown_faces: np.ndarray | None, base_colors: np.ndarray | None) -> None:
        """Draw only the polygons ``shown_faces`` (indices into the surface's faces, in order; None: all of them)
        and colour the plain shaded surface by ``base_colors`` ((V, 3) uint8, each part in its material's colour;
        None: the one skin colour). Every vertex stays (vertex order is sacred); a hidden part is not drawn or
        picked (``model.parts``). Keeps the camera, the pose, the colour map and the texture."""
        if self.mesh is None:
            return
        self._build_mesh(self._arrays.points, shown_faces, base_colors)   # rig_mesh copies them
        self.render()

    @property
    def shown_faces(self) -> np.ndarray | None:
        """The surface's faces drawn (indices into its faces), None when all are."""
        return self._shown_faces

    def _build_mesh(self, points, shown_faces, base_colors) -> None:
        self.detail.set_mesh(None)
        counts, indices = subset_faces(*self._all_faces, shown_faces)
        self._shown_faces = None if shown_faces is None else np.asarray(shown_faces, dtype=np.int64)
        self._base_colors = base_colors
        known = self._prepared
        if known is not None and not known.is_for(self._shown_faces, len(counts)):
            known = None   # prepared for other faces
        self.mesh = rig_mesh(points, counts, indices, normals=known.normals if known is not None else None,
                             layout=known.layout if known is not None else None)
        if known is not None:     # ``scene._back_sides`` takes them
            object.__setattr__(self.mesh, "_hidden_faces", known.hidden_backs)
            object.__setattr__(self.mesh, "_back_layout", known.backs)
        self._face_counts = np.asarray(counts)
        self._arrays = SurfaceArrays(self.mesh)
        if self._texture_split is not None and self._textured is not None:
            image8 = np.ascontiguousarray(self._textured.pixels_top_down())
            self._textured = self._textured_surface(self._texture_split, image8)
        self._redraw_surface()
        self.detail.set_mesh(self.mesh, counts, indices, points, self._arrays)

    def _textured_surface(self, split, image8):
        from .texture_view import TexturedSurface
        self.detail.show_full()     # its normals up to date
        return TexturedSurface(self._arrays.points, self._arrays.normals, self._face_counts,
                               split.of_faces(self._all_faces[0], self._shown_faces), image8)

    def update_points(self, points: np.ndarray, *, render: bool = True) -> None:
        """Move the surface's vertices (same order and count) and redraw (``render`` False: drawn by the render
        under way, from its ``before_render``)."""
        if self.mesh is None:
            return
        given, self._given_normals = self._given_normals, None
        given = given[1] if given is not None and given[0] is points else None
        # a frame the proxy will draw computes only the proxy's normals (``widgets.lod``); a texture, even one a colour
        # map covers now, takes the surface's at each update: they are computed
        self._arrays.update(points, given, defer_normals=given is None and self._textured is None
                            and self.detail.expects_proxy())
        if self._textured is not None:
            self._textured.update_points(self._arrays.points, self._arrays.normals)
        if render:
            self.render()

    def use_normals(self, points: np.ndarray, normals: np.ndarray) -> None:
        """The next ``update_points(points)`` with this very array takes ``normals`` ((V, 3) float32, computed by
        ``normals_function()`` for ``points``) instead of computing them; any other update computes its own."""
        self._given_normals = (points, normals)

    def normals_function(self):
        """The function giving the shown surface's display normals for points (thread-safe: numpy only), or None
        without a surface."""
        return None if self.mesh is None else self.mesh._display_normals

    def points(self) -> np.ndarray | None:
        """A copy of the drawn vertices (the mesh's own array is rewritten in place on each update)."""
        return None if self.mesh is None else np.array(self.mesh.points)

    @property
    def colormap(self) -> ColorMap | None:
        """The colour map the surface shows (None: plain shading)."""
        return self._colormap

    def set_colormap(self, colormap: ColorMap | None) -> None:
        """Colour the surface by ``colormap`` (None: plain shading). When its legend or bar takes another side of the
        view than the last framing left clear, or more of it, an untouched framing is made again beside them
        (``_reframe_if_untouched``); a legend that only narrows (a threshold dragged) leaves the camera still."""
        self._colormap = colormap
        if self.mesh is not None:
            self._redraw_surface()
            if self._framed is not None:
                room, framed = overlay_room(self.plotter), self._framed[3]
                if any((a > 0) != (b > 0) or a > b for a, b in zip(room, framed)):
                    self._reframe_if_untouched()
            self.render()

    def set_texture(self, split, image8: np.ndarray | None) -> None:
        """Show ``image8`` ((H, W, 3) uint8, row 0 the top) on the surface through ``split``
        (``model.textures.DisplaySplit``); None: plain shading again. A colour map, while set, is shown instead."""
        self._texture_split = split
        self._textured = None if image8 is None or self.mesh is None else self._textured_surface(split, image8)
        if self.mesh is not None:
            self._redraw_surface()
            self.render()

    def update_texture(self, image8: np.ndarray, boxes=None) -> None:
        """New texels for the shown texture (only ``boxes``, (row slice, column slice) pairs, when given);
        drawn at the next render."""
        if self._textured is not None:
            self._textured.update_image(image8, boxes)

    @property
    def textured(self) -> bool:
        """Whether the surface shows a texture (set and not covered by a colour map)."""
        return self._textured is not None and self._colormap is None

    def set_wireframe(self, on: bool) -> None:
        self._wireframe = bool(on)
        if self.mesh is not None:
            self._redraw_surface()
            self.render()

    @property
    def wireframe(self) -> bool:
        return self._wireframe

    def _redraw_surface(self) -> None:
        self.detail.show_full()   # the actors are made anew over the mesh's own faces
        self.plotter.remove_scalar_bar(render=False) if self.plotter.scalar_bars else None   # (pyvista renders)
        # the previous colour map's legend and its title go with it (they stayed up in Shaded view)
        self.plotter.remove_legend(render=False)
        self.plotter.remove_actor("legend_title", render=False)
        # point data from a previous colour map must not leak into the next one
        for key in ("values", "colors"):
            if key in self.mesh.point_data:
                del self.mesh.point_data[key]
        if self._textured is not None and self._colormap is None:
            self.plotter.remove_actor("surface_backs", render=False)   # add_surface's second actor
            self._textured.add_to(self.plotter, wireframe=self._wireframe)
        else:
            add_surface(self.plotter, self.mesh, self._colormap, wireframe=self._wireframe, cull_hidden=True,
                        base_colors=self._base_colors)

    # --- overlays ----------------------------------------------------------------------------------
    def add_overlay(self, name: str, mesh, **style):
        """Draw ``mesh`` (a pyvista dataset) over the surface under ``name`` (the same name replaces it), with
        pyvista's ``add_mesh`` style keywords; overlays are never picked and never reframe the camera. Returns
        the actor (its ``visibility`` can be toggled). Nothing is rendered until ``render``."""
        actor = self.plotter.add_mesh(mesh, name=name, pickable=False, reset_camera=False, render=False, **style)
        actor.SetPickable(False)
        return actor

    def remove_overlay(self, name: str) -> None:
        self.plotter.remove_actor(name, render=False)

    # --- picking -----------------------------------------------------------------------------------
    def pick(self, x: int, y: int) -> SurfacePoint | None:
        """The surface point under display pixel (x, y from the bottom-left), or None."""
        if self.mesh is None:
            return None
        self.detail.show_full(normals=False)   # picked on the surface's own faces, not a proxy's
        if self._picker is None:
            self._picker = FacePicker()
        hit = self._picker.pick(self.plotter.renderer, x, y)   # VTK's cell picker, over the faces near the ray
        if hit is None:
            return None
        data, cell, point = hit
        shown = self._textured.mesh if self.textured else self.mesh
        if data is None or data.GetNumberOfPoints() != shown.n_points:
            return None
        face = cell if shown is not self.mesh else surface_face(self.mesh, data, cell)   # a two-sided part's back
        ids = np.asarray(shown.get_cell(face).point_ids)
        pts = np.asarray(shown.points)[ids]
        nearest = int(ids[np.argmin(np.linalg.norm(pts - point, axis=1))])
        if self._shown_faces is not None:
            face = int(self._shown_faces[face])     # the surface's own face number, hidden parts counted
        return SurfacePoint(int(self._textured.vertex[nearest]) if shown is not self.mesh else nearest, face, point)

    # --- tools: the gesture API --------------------------------------------------------------------
    def push_tool(self, tool: ViewportTool) -> None:
        """Offer the view's mouse presses to ``tool`` first (until ``remove_tool``); pushing it again is a no-op."""
        if tool not in self._tools:
            self._tools.append(tool)

    def remove_tool(self, tool: ViewportTool) -> None:
        """Stop offering the mouse to ``tool``; a gesture it owns ends without a release."""
        if tool in self._tools:
            self._tools.remove(tool)
        if self._owner is tool:
            self._owner, self._press = None, None

    def has_tool(self, tool: ViewportTool) -> bool:
        return tool in self._tools

    def eventFilter(self, obj, event) -> bool:  # Qt override: the canvas's mouse, before VTK sees it
        if obj is self.plotter.interactor:
            t = event.type()
            if t == QtCore.QEvent.MouseButtonPress:
                return self._mouse_press(event)
            if t == QtCore.QEvent.MouseMove:
                return self._mouse_move(event)
            if t == QtCore.QEvent.MouseButtonRelease:
                return self._mouse_release(event)
        return super().eventFilter(obj, event)

    def _event_xy(self, event) -> tuple[int, int]:
        return self.qt_to_display(event.position().x(), event.position().y())

    def _mouse_press(self, event) -> bool:
        if self._owner is not None:
            return True      # another button during a tool's gesture: the tool keeps it, the camera stays
        x, y = self._event_xy(event)
        g = Gesture(self, "press", x, y, event.button(), (x, y), None)
        for tool in reversed(self._tools):
            if tool.press(g):
                self._owner, self._press = tool, ((x, y), event.button(), g.anchor)
                self._click = None
                return True
        self._click = (x, y) if event.button() == QtCore.Qt.LeftButton else None
        return False

    def _mouse_move(self, event) -> bool:
        x, y = self._event_xy(event)
        if self._owner is not None:
            start, button, anchor = self._press
            self._owner.drag(Gesture(self, "drag", x, y, button, start, anchor))
            return True
        if self._tools and event.buttons() == QtCore.Qt.NoButton:
            g = Gesture(self, "hover", x, y, QtCore.Qt.NoButton, (x, y), None)
            for tool in reversed(self._tools):
                tool.hover(g)
        return False

    def _mouse_release(self, event) -> bool:
        x, y = self._event_xy(event)
        if self._owner is not None:
            owner, (start, button, anchor) = self._owner, self._press
            self._owner, self._press = None, None
            owner.release(Gesture(self, "release", x, y, button, start, anchor))
            return True
        click, self._click = self._click, None
        if click is not None and event.button() == QtCore.Qt.LeftButton \
                and abs(x - click[0]) + abs(y - click[1]) <= CLICK_SLOP_PX:
            hit = self.pick(x, y)
            if hit is not None:
                self.picked.emit(hit.vertex, hit.position)
                self._without_vtk_render()
        return False

    def _without_vtk_render(self) -> None:
        """VTK's interactor does not render for the event it is given next (the release of a click: its camera
        style renders as the button is released). What a click on the surface changes (a marker added, a region
        selected) is drawn by its owner's render, on the event loop's next turn; the interactor's render before it
        was one full frame more of the same picture (0.1-0.16 s at 422k vertices), and with the level of detail the
        owner's frame, close after it, was the proxy's: the face flickered coarse at every click for 0.3 s."""
        iren = self.plotter.iren.interactor
        iren.EnableRenderOff()
        QtCore.QTimer.singleShot(0, self, lambda: None if self.plotter._closed else iren.EnableRenderOn())

    # --- coordinates -------------------------------------------------------------------------------
    def pixel_ratio(self) -> float:
        return float(self.plotter.interactor.devicePixelRatioF())

    def qt_to_display(self, x: float, y: float) -> tuple[int, int]:
        """Widget-local Qt position → VTK display pixel (as QVTKRenderWindowInteractor maps events)."""
        s = self.pixel_ratio()
        return int(round(x * s)), int(round((self.plotter.interactor.height() - y - 1) * s))

    def display_to_qt(self, x: float, y: float) -> QtCore.QPointF:
        """VTK display pixel → widget-local Qt position of the canvas."""
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
        """The world point at display pixel (x, y) and depth ``z`` (0 the near plane, 1 the far)."""
        return display_to_world(self.plotter.renderer, x, y, z)

    def view_plane_point(self, x: float, y: float, origin: np.ndarray) -> np.ndarray:
        """Where the ray under display pixel (x, y) meets the plane through ``origin`` facing the camera."""
        near, far = self.display_to_world(x, y, 0.0), self.display_to_world(x, y, 1.0)
        n = self.camera_frame().forward
        d = far - near
        denom = float(d @ n)
        if abs(denom) < 1e-12:
            return np.asarray(origin, dtype=np.float64).copy()
        t = float((np.asarray(origin) - near) @ n) / denom
        return near + t * d

    # --- camera ------------------------------------------------------------------------------------
    def camera_frame(self) -> CameraFrame:
        """The camera's position, focal point and axes now (``up`` as the camera holds it)."""
        cam = self.plotter.camera
        position, focal = np.array(cam.position, dtype=float), np.array(cam.focal_point, dtype=float)
        up = np.array(cam.up, dtype=float)
        forward = focal - position
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, up)
        right /= np.linalg.norm(right)
        return CameraFrame(position, focal, up, forward, right)

    def set_camera(self, name: str, render: bool = True) -> None:
        """Look at the face (or the whole surface as posed, ``focus_points``) from camera preset ``name``;
        ``render=False``: the caller renders (once) after."""
        self._camera = name
        if self.focus_points() is not None:
            self._frame(None, None)
            if render:
                self.render()

    def reset_view(self) -> None:
        self.set_camera(self._camera)

    def focus_points(self) -> np.ndarray | None:
        """The points the camera presets frame: the face (the vertices the shapes move, as ``set_surface`` was given
        them) with the vertices a colour map paints (``model.rig_prep.framed_points``), else the whole surface as
        drawn now; None without a surface."""
        marked = None if self._colormap is None else self._colormap.marked
        if self._focus is None or marked is None or self.mesh is None:
            return self._focus if self._focus is not None else self.points()
        return framed_points(self._focus, self.mesh.points, marked)   # and the regions a segmentation view paints

    def frame_points(self, points: np.ndarray | None = None) -> None:
        """Frame ``points`` (default: ``focus_points``) from where the camera looks now (Maya's F and A)."""
        pts = self.focus_points() if points is None else np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if pts is None or not len(pts):
            return
        cam = self.camera_frame()
        self._frame(None if points is None else pts, (-cam.forward, cam.up))
        self.render()

    def _frame(self, points: np.ndarray | None, direction: tuple | None, size: tuple[int, int] | None = None) -> None:
        """Frame ``points`` (None: ``focus_points``, as they are whenever the framing is made again: a segmentation
        view's regions come into a preset's framing with its legend) from the preset's direction (None) or
        ``direction`` (``scene.set_camera``), beside the legend and bar, and remember it (``_reframe_if_untouched``)
        unless it is for a picture of another ``size``."""
        set_camera(self.plotter, self._camera, self.focus_points() if points is None else points, size=size,
                   direction=direction)
        if size is None:
            self._framed = (points, direction, self.plotter.camera_position, overlay_room(self.plotter))

    def _reframe_if_untouched(self, size: tuple[int, int] | None = None) -> bool:
        """Frame again what the last framing framed (a camera preset, Frame All or Selected), for ``size`` (w, h)
        pixels (default: the view's) and the colour map's legend and bar as they are now, if the camera has not
        moved since (a camera the user orbited or zoomed is left alone). Whether it did."""
        if self._framed is None or self.plotter._closed or self.plotter.camera_position != self._framed[2]:
            return False
        self._frame(*self._framed[:2], size=size)
        return True

    def render(self) -> None:
        """Render now (a requested render still to come is then dropped: this one draws what it was for). The owner's
        ``before_render`` runs first, so that every render shows what the owner shows now (the window's pose)."""
        self._render_requested = False    # this render draws what a request was for
        self.before_render()
        self.plotter.render()
        waiting, self._after_render = self._after_render, []
        for fn in waiting:
            QtCore.QTimer.singleShot(1, self, fn)

    def request_render(self, *, after_input: bool = False) -> None:
        """Render once this turn of the event loop is over, unless a render comes first: what changes until then (a
        burst of pose changes from a slider or marker drag, a tool's overlay, a sculpt stroke's cursor and surface)
        is drawn by one render. ``after_input``: after the input and timers that are waiting too (a timer of 1 ms: a
        call queued for 0 ms runs before them), when this turn was long already and the render will be (a new studio
        rig: 0.1 s each at 422k vertices). The view's one coalesced render: the window's pose changes and the tools
        both ask here, and an expose meanwhile shows the last picture (``NativePlotter.render_pending``)."""
        if not self._render_requested:
            self._render_requested = True
            QtCore.QTimer.singleShot(1 if after_input else 0, self, self._render_if_requested)

    def _render_if_requested(self) -> None:
        # a render since the request (playback draws its frame at once) drew this change: never twice
        if self._render_requested:
            self.render()

    @property
    def render_pending(self) -> bool:
        """Whether a requested render (``request_render``) has not happened yet."""
        return self._render_requested

    def when_drawn(self, fn: Callable[[], None]) -> None:
        """Call ``fn`` once the view shows what has changed: after the pending render, and after the input and timers
        waiting then (a timer of 1 ms); at once when none is pending."""
        if self._render_requested:
            self._after_render.append(fn)
        else:
            fn()

    def picture(self, size: tuple[int, int] | None = None) -> np.ndarray:
        """The view as shown (camera, colour map and bar, wireframe) as (h, w, 3) uint8 pixels at ``size`` (w, h)
        (default: the view's), drawn by VTK on this thread: File ▸ Export Image's picture, which its caller encodes
        and writes off the GUI thread. The legend, bar and titles are laid out for the picture's size
        (``scene.overlay_layout``), and a framing the user has not moved since is made again for it, beside them; a
        camera the user moved is kept, and a size narrower than the view widens the view angle so that what is seen
        across stays in the picture."""
        w, h = size or tuple(self.plotter.window_size)
        vw, vh = self.plotter.window_size
        cam = self.plotter.camera
        angle, saved = cam.view_angle, self.plotter.camera_position
        if size:
            fit_overlays(self.plotter, (int(w), int(h)))
        reframed = bool(size) and self._reframe_if_untouched((int(w), int(h)))
        if not reframed and vw > 0 and vh > 0 and w * vh < vw * h:   # narrower than the view: keep its horizontal field
            half = np.arctan(np.tan(np.radians(angle) / 2) * (vw / vh) / (w / h))
            cam.view_angle = float(np.degrees(2 * half))
        self.detail.full_only = True
        try:
            self.render()
            window_size = [int(w), int(h)] if size else None
            return np.asarray(self.plotter.screenshot(None, return_img=True, window_size=window_size))[:, :, :3]
        finally:
            try:
                fit_overlays(self.plotter)
                cam.view_angle = angle
                self.plotter.camera_position = saved
                self.render()       # the view back as it was: in full too (the proxy's, close after the picture's)
            finally:
                self.detail.full_only = False

    def _fit_to_size(self) -> None:
        """The render window took a new size (``NativePlotter.resized``): the legend and bar laid out for it, and an
        untouched framing made again for it, drawn by the paint the resize brings (one render: a second one, on the
        event loop's next turn, made the first solve's opening of the Mocap Views dock a frozen window)."""
        if self.mesh is None or self.plotter._closed:
            return
        fit_overlays(self.plotter)
        self._reframe_if_untouched()

    def close_viewport(self) -> None:
        self.detail.stop()
        self._tools.clear()
        self._owner = None
        self._picker = None
        if not self.plotter._closed:
            drop_cached_background(self.plotter.renderer)   # its frame buffer, while the window is open
        self.plotter.close()
