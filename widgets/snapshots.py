"""Pictures of one surface in pose after pose, drawn off screen by VTK alone: a batch's previews.

``SurfaceSnapshots`` draws ``widgets.scene.render_png``'s picture (no colour map, no overlays), pixel for pixel, from
a render window it keeps, without pyvista. Why without: a batch's workers are forked from one fork server that
imports what they need (``model.fork_server``); pyvista and the matplotlib it imports cost that process ~0.7 s of
CPU, and the fork server's imports then ended after the command's own start-up, so the cluster waited for them
(see the README's batch figures). VTK's own modules take ~0.1 s.

The window is set up as ``widgets.scene.offscreen_plotter`` sets up pyvista's (the same multisampling, background,
lights, material and shading, ``widgets.scene.shade_surface_actor``), and the picture is read as pyvista reads a
screenshot (``vtkWindowToImageFilter`` on the front buffer, which VTK resolved from the multisampled one);
``tests/test_batch.py`` compares every pixel with a fresh ``render_png`` of the same pose.
"""
from __future__ import annotations

import numpy as np

from solvers.normals import VertexNormals

from .scene import (AMBIENT, BACKGROUND_BOTTOM, BACKGROUND_TOP, DIFFUSE, EDGE_COLOR, EDGE_WIDTH,
                    FILL_LIGHT_INTENSITY, KEY_LIGHT_INTENSITY, KEY_LIGHT_POSITION, SKIN, SPECULAR_POWER, SurfaceArrays,
                    blend_only_when_needed, camera_placement, polygon_cells, shade_surface_actor,
                    use_offscreen_backend_if_headless)

MULTI_SAMPLES = 8      # pyvista's default anti-aliasing for an off-screen plotter (its theme's ``multi_samples``)


def _rgb(color) -> tuple[float, float, float]:
    """A colour as pyvista passes it to VTK (``pyvista.Color``: 8 bits a channel)."""
    return tuple(round(255 * float(c)) / 255 for c in color)


def _view_for(view, face_counts: np.ndarray):
    """``view`` where it is of as many faces as ``face_counts``, else None."""
    return view if view is not None and len(view.hidden_backs) == len(face_counts) else None


class SurfaceSnapshots:
    """``render_png``'s picture (front camera by default, no colour map, no overlays) of one surface in pose after
    pose, from one off-screen render window kept between pictures: only the points and normals change
    (``SurfaceArrays``), then the camera frames ``focus`` and the picture is taken (``image``, or ``png`` for a PNG
    file's bytes). A batch worker draws every take's preview through one of these.

    Why not ``render_png`` each time: a new window is a new OpenGL context, whose shaders llvmpipe compiles again
    (LLVM) in its first render, and the faces' back sides are found again (``solvers.mesh.hidden_back_faces``):
    on ICT at 480x360 a picture took ~0.18 s that way and ~0.06 s here (see the README's batch figures). The back
    sides are found once, on the first pose, as the viewport finds them on the rig it loads, or come found with
    ``view`` (``model.rig_prep.DefaultView``, as a batch's job carries them). ``matches`` tells
    whether a surface's faces, picture size and camera are this one's."""

    def __init__(self, face_counts: np.ndarray, face_indices: np.ndarray, *, size=(1024, 768), camera: str = "front",
                 view=None):
        use_offscreen_backend_if_headless()
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (VTK's OpenGL classes behind the render window)
        from vtkmodules.vtkRenderingCore import vtkLight, vtkRenderer, vtkRenderWindow
        self.face_counts, self.face_indices = np.array(face_counts), np.array(face_indices)
        self.view = _view_for(view, self.face_counts)
        self.size, self.camera = tuple(int(v) for v in size), camera
        self.window = vtkRenderWindow()
        self.window.SetMultiSamples(MULTI_SAMPLES)
        self.window.SetBorders(True)
        self.window.SetOffScreenRendering(1)
        self.window.SetSize(*self.size)
        self.renderer = vtkRenderer()
        self.renderer.AutomaticLightCreationOff()
        self.renderer.GetCullers().RemoveAllItems()        # as ``style_plotter``: a face is always in view
        self.renderer.SetBackground(*_rgb(BACKGROUND_BOTTOM))
        self.renderer.SetBackground2(*_rgb(BACKGROUND_TOP))
        self.renderer.SetGradientBackground(True)
        self.window.AddRenderer(self.renderer)
        blend_only_when_needed(self.renderer)
        key = vtkLight()                                   # ``style_plotter``'s two lights
        key.SetLightTypeToCameraLight()
        key.SetPosition(*KEY_LIGHT_POSITION)
        key.SetFocalPoint(0.0, 0.0, 0.0)
        key.SetIntensity(KEY_LIGHT_INTENSITY)
        fill = vtkLight()
        fill.SetLightTypeToHeadlight()
        fill.SetIntensity(FILL_LIGHT_INTENSITY)
        for light in (key, fill):
            light.SetPositional(False)
            self.renderer.AddLight(light)
        self._mesh = self._arrays = None

    def matches(self, face_counts, face_indices, size, camera: str) -> bool:
        return (tuple(int(v) for v in size) == self.size and camera == self.camera
                and np.array_equal(face_counts, self.face_counts) and np.array_equal(face_indices, self.face_indices))

    def set_faces(self, face_counts: np.ndarray, face_indices: np.ndarray, view=None) -> None:
        """Draw a surface of other faces from the next picture on, in the same window: its OpenGL context and the
        shader programs it compiled stay (VTK keeps a window's programs by their source, which depends on the
        material and lighting, not on the mesh). ``app.cli_batch.warm_up_preview`` draws a stand-in first so that
        a worker's first take does not wait for them (~0.12 s on ICT). ``view``: as for the constructor."""
        self.renderer.RemoveAllViewProps()
        self.face_counts, self.face_indices = np.array(face_counts), np.array(face_indices)
        self.view = _view_for(view, self.face_counts)
        self._mesh = self._arrays = None

    def _add_surface(self, points: np.ndarray) -> None:
        """The surface as ``add_surface`` adds it without a colour map (material, per-vertex lighting, backs)."""
        from vtkmodules.util.numpy_support import numpy_to_vtk
        from vtkmodules.vtkCommonCore import vtkPoints
        from vtkmodules.vtkCommonDataModel import vtkPolyData
        from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper
        mesh = vtkPolyData()
        pts = vtkPoints()
        pts.SetData(numpy_to_vtk(np.array(points, dtype=np.float32), deep=True))
        mesh.SetPoints(pts)
        view = self.view if self.view is not None and self.view.normals.n_points == len(points) else None
        mesh.SetPolys(polygon_cells(self.face_counts, self.face_indices, view.layout if view is not None else None))
        normals = view.normals if view is not None else VertexNormals(self.face_counts, self.face_indices, len(points))
        mesh._display_normals = normals
        mesh._faces = (self.face_counts, self.face_indices)
        if view is not None:       # ``scene._back_sides`` takes them instead of finding them
            mesh._hidden_faces, mesh._back_layout = view.hidden_backs, view.backs
        n = numpy_to_vtk(normals(np.asarray(points, dtype=np.float32)).astype(np.float32), deep=True)
        n.SetName("Normals")
        mesh.GetPointData().SetNormals(n)
        mapper = vtkPolyDataMapper()
        mapper.SetInputData(mesh)
        mapper.ScalarVisibilityOff()
        actor = vtkActor()
        actor.SetMapper(mapper)
        prop = actor.GetProperty()
        prop.SetColor(*_rgb(SKIN))
        prop.SetInterpolationToGouraud()
        prop.SetSpecular(0.25)                             # ``add_surface``'s default
        prop.SetSpecularPower(SPECULAR_POWER)
        prop.SetDiffuse(DIFFUSE)
        prop.SetAmbient(AMBIENT)
        prop.SetEdgeColor(*_rgb(EDGE_COLOR))
        prop.SetLineWidth(EDGE_WIDTH)
        self.renderer.AddActor(actor)
        back = shade_surface_actor(self.renderer, mesh, actor, cull_hidden=True)
        if back is not None:
            self.renderer.AddActor(back)
        self._mesh, self._arrays = mesh, SurfaceArrays(mesh)

    def image(self, points: np.ndarray, *, focus: np.ndarray | None = None) -> np.ndarray:
        """The picture of the surface at ``points`` (V, 3), (h, w, 3) uint8, top row first."""
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkRenderingCore import vtkWindowToImageFilter
        points = np.asarray(points, dtype=np.float32)
        if self._mesh is None:
            self._add_surface(points)
        else:
            self._arrays.update(points)
        center, position, up = camera_placement(self.camera, points if focus is None else focus, self.size)
        cam = self.renderer.GetActiveCamera()
        cam.SetViewAngle(30.0)
        cam.SetFocalPoint(*center)
        cam.SetPosition(*position)
        cam.SetViewUp(*up)
        self.renderer.ResetCameraClippingRange()
        self.window.Render()
        grab = vtkWindowToImageFilter()
        grab.SetInput(self.window)
        grab.FixBoundaryOn()
        grab.ShouldRerenderOff()
        grab.SetInputBufferTypeToRGB()
        grab.ReadFrontBufferOn()
        grab.Update()
        out = grab.GetOutput()
        w, h, _ = out.GetDimensions()
        return vtk_to_numpy(out.GetPointData().GetScalars()).reshape(h, w, -1)[::-1]

    def png(self, points: np.ndarray, *, focus: np.ndarray | None = None, compress_level: int | None = None) -> bytes:
        """The picture of the surface at ``points`` as a PNG file's bytes. ``compress_level``: the PNG's zlib level
        (0-9; Pillow's default 6 if None)."""
        import io

        from PIL import Image
        buf = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(self.image(points, focus=focus))).save(
            buf, format="PNG", **({} if compress_level is None else {"compress_level": compress_level}))
        return buf.getvalue()

    def close(self) -> None:
        self.renderer.RemoveAllViewProps()
        self.window.Finalize()
