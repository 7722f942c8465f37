"""Scene building shared by the GUI viewport and the headless ``render`` command.

Turns rig arrays into pyvista meshes, sets the look (skin material, lights, cameras) and colour maps
with legends. Holds no algorithm: scalars to colour by are computed elsewhere and passed in.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from solvers.mesh import bounds, cell_layout, reversed_faces
from solvers.normals import VertexNormals, dequantise

SKIN = (0.86, 0.70, 0.60)
BACKGROUND_TOP = (0.33, 0.35, 0.40)
BACKGROUND_BOTTOM = (0.12, 0.12, 0.14)
BACKGROUND_FLAT = (0.20, 0.21, 0.24)
CAMERAS = ("front", "left", "right", "three-quarter")
# The surface's material (``add_surface``) and the default view's lights (``style_plotter``); a batch's previews
# draw the same look on the CPU (``app.cli_batch.preview_image``).
EDGE_COLOR, EDGE_WIDTH = (0.15, 0.15, 0.18), 0.5
DIFFUSE, AMBIENT, SPECULAR_POWER = 0.85, 0.12, 20
SURFACE_SPECULAR = 0.25      # the skin's specular coefficient (``add_surface``'s default)
KEY_LIGHT_POSITION, KEY_LIGHT_INTENSITY, FILL_LIGHT_INTENSITY = (-0.6, 0.8, 1.0), 0.75, 0.45


def use_offscreen_backend_if_headless() -> None:
    """Without an X display, let VTK render through EGL instead of failing on X (call before importing VTK)."""
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def polygon_cells(face_counts: np.ndarray, face_indices: np.ndarray, layout=None):
    """The polygons, in order, as a ``vtkCellArray`` of their offsets and flat indices (VTK's own layout,
    ``solvers.mesh.cell_layout``; ``layout``: made beforehand, off the GUI thread, ``model.rig_prep``), copied
    into VTK's arrays (a few ms at 422k vertices). Through VTK's legacy padded format [n, i0, ..., n, ...],
    which a pyvista ``PolyData(points, faces)`` is given, it took 0.05 s at 422k vertices: building the padded
    array, then VTK parsing it."""
    return cell_array(*(layout if layout is not None else cell_layout(face_counts, face_indices)))


def cell_array(offsets: np.ndarray, connectivity: np.ndarray):
    """A ``vtkCellArray`` of cells in VTK's layout (int64 ``offsets`` and ``connectivity``, ``solvers.mesh``),
    both copied into VTK's own arrays."""
    from vtkmodules.util.numpy_support import numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonDataModel import vtkCellArray
    cells = vtkCellArray()
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True), numpy_to_vtkIdTypeArray(connectivity, deep=True))
    return cells


def polygon_mesh(points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray, layout=None):
    """A pyvista PolyData of float32 ``points`` (a copy) and these polygons only (``polygon_cells``): given its
    points at construction, pyvista would add a vertex cell for each point."""
    import pyvista as pv
    mesh = pv.PolyData()
    mesh.points = np.array(points, dtype=np.float32)
    mesh.SetPolys(polygon_cells(face_counts, face_indices, layout))
    return mesh


def rig_mesh(points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
             normals: VertexNormals | None = None, layout=None):
    """A pyvista PolyData of the surface (float32 points for display) with smooth-shading normals.

    ``mesh.field_data`` is left alone; the normals function (``normals``, to share one built for these
    faces, else a new one) is kept on the mesh object as ``mesh._display_normals`` so SurfaceArrays can
    refresh them, and the polygons as ``mesh._faces`` (counts, indices) for ``add_surface(cull_hidden=True)``.
    """
    # A copy: SurfaceArrays writes into the mesh's own arrays, never into the caller's.
    mesh = polygon_mesh(points, face_counts, face_indices, layout)
    if normals is None:
        normals = VertexNormals(face_counts, face_indices, mesh.n_points)
    object.__setattr__(mesh, "_display_normals", normals)
    object.__setattr__(mesh, "_faces", (np.asarray(face_counts), np.asarray(face_indices)))
    mesh.point_data["Normals"] = normals(mesh.points)
    mesh.point_data.active_normals_name = "Normals"
    return mesh


class SurfaceArrays:
    """Numpy views of a rig mesh's own VTK arrays -- points, normals and optionally one scalar array -- for
    in-place updates (a drag, playback) without new VTK arrays or pyvista's wrapping on every access."""

    def __init__(self, mesh, scalars: str | None = None) -> None:
        from vtkmodules.util.numpy_support import vtk_to_numpy
        pd = mesh.GetPointData()
        self._vtk = [mesh.GetPoints(), pd.GetNormals()] + ([pd.GetArray(scalars)] if scalars else [])
        self.points = vtk_to_numpy(mesh.GetPoints().GetData())
        self.normals = vtk_to_numpy(pd.GetNormals())
        self.scalars = vtk_to_numpy(pd.GetArray(scalars)) if scalars else None
        self._normals_of = mesh._display_normals
        self.normals_stale = False    # the normals are for earlier points (``update(defer_normals=True)``)

    def update(self, points: np.ndarray, normals: np.ndarray | None = None, scalars: np.ndarray | None = None,
               defer_normals: bool = False) -> None:
        """New points (same count); normals float or int8 (``VertexNormals.quantised``), computed if None, unless
        ``defer_normals``: then left for ``refresh_normals`` (a frame drawn by a proxy with its own normals,
        ``widgets.lod``)."""
        self.points[:] = points
        self.normals_stale = normals is None and defer_normals
        if normals is None:
            if not self.normals_stale:
                self.normals[:] = self._normals_of(self.points)
        elif normals.dtype == np.int8:
            dequantise(normals, out=self.normals)
        else:
            self.normals[:] = normals
        if scalars is not None:
            self.scalars[:] = scalars
        for obj in self._vtk:
            obj.Modified()

    def refresh_normals(self) -> None:
        """The normals for the current points, if an update deferred them."""
        if self.normals_stale:
            self.normals[:] = self._normals_of(self.points)
            self.normals_stale = False
            self._vtk[1].Modified()


@dataclass
class ColorMap:
    """Per-vertex scalars with their colour map and legend text (title includes units)."""
    scalars: np.ndarray          # (V,) values, or (V, 3) uint8 RGB when rgb=True
    title: str = ""
    cmap: str = "inferno"
    clim: tuple[float, float] | None = None
    rgb: bool = False
    categorical: bool = False
    legend: list[tuple[str, tuple[float, float, float]]] | None = None  # swatches for categorical/RGB views
    marked: np.ndarray | None = None   # the vertices it paints (a segmentation's regions): framed with the face


def add_surface(plotter, mesh, colormap: ColorMap | None = None, *, wireframe: bool = False, name="surface",
                specular: float = SURFACE_SPECULAR, cull_hidden: bool = False, base_colors: np.ndarray | None = None):
    """Add the rig surface with smooth shading; colour by ``colormap`` with a legend if given, else by
    ``base_colors`` ((V, 3) uint8: each part in its material's colour, ``model.parts.vertex_colors``) if given,
    else in the one skin colour.

    ``cull_hidden`` (a ``rig_mesh``; the viewport and ``render``): skip the faces turned away from the camera
    where that changes nothing seen (``solvers.mesh.hidden_back_faces``: the closed, outward parts); the other
    parts keep both sides, their backs drawn by a second actor named ``<name>_backs`` (see ``surface_face``)."""
    plotter.remove_actor(f"{name}_backs", render=False)
    # Smooth shading comes from the mesh's own "Normals" (rig_mesh/SurfaceArrays), not VTK's filter.
    kwargs = dict(smooth_shading=False, interpolation="gouraud", name=name, show_edges=wireframe, edge_color=EDGE_COLOR,
                  line_width=EDGE_WIDTH, specular=specular, specular_power=SPECULAR_POWER, diffuse=DIFFUSE,
                  ambient=AMBIENT, reset_camera=False, render=False)   # the caller renders, once
    if colormap is None and base_colors is not None and len(base_colors) == mesh.n_points:
        colormap = ColorMap(base_colors, rgb=True)
    if colormap is None:
        return _shade(plotter, mesh, plotter.add_mesh(mesh, color=SKIN, **kwargs), wireframe, name, cull_hidden)
    if colormap.legend:
        entries = colormap.legend if len(colormap.legend) <= 10 else \
            colormap.legend[:9] + [(f"… {len(colormap.legend) - 9} more", (0.7, 0.7, 0.7))]
        entries = [(f" {text}", color) for text, color in entries]   # a space between the swatch and its text
        suppressed, plotter.suppress_rendering = plotter.suppress_rendering, True
        try:    # pyvista's add_legend renders the whole picture (0.11 s at 422k vertices): the caller renders, once
            legend = plotter.add_legend(entries, bcolor=(0.1, 0.1, 0.12), border=False, face="rectangle",
                                        name="legend", loc="upper left")
        finally:
            plotter.suppress_rendering = suppressed
        _legend_white_text(legend, entries)
        if colormap.title:
            plotter.add_text(colormap.title, position="lower_right", font_size=10, color="white", name="legend_title",
                             render=False)
    if colormap.rgb:
        mesh.point_data["colors"] = np.asarray(colormap.scalars, dtype=np.uint8)
        actor = plotter.add_mesh(mesh, scalars="colors", rgb=True, **kwargs)
        fit_overlays(plotter)
        _map_directly(actor, mesh, "colors")
        return _shade(plotter, mesh, actor, wireframe, name, cull_hidden)
    mesh.point_data["values"] = np.asarray(colormap.scalars, dtype=np.float32)
    bar = dict(title=colormap.title or " ", vertical=True, position_x=0.82, position_y=0.12, height=0.76,
               width=0.06, title_font_size=14, label_font_size=12, n_labels=5, fmt="%.3g",
               color="white", render=False)   # pyvista's default: render as the bar is added, a whole picture
    if colormap.categorical:
        actor = plotter.add_mesh(mesh, scalars="values", cmap=colormap.cmap, clim=colormap.clim,
                                 show_scalar_bar=False, interpolate_before_map=False, **kwargs)
    else:
        actor = plotter.add_mesh(mesh, scalars="values", cmap=colormap.cmap, clim=colormap.clim,
                                 scalar_bar_args=bar, **kwargs)
        if bar["title"] in plotter.scalar_bars:
            plotter.scalar_bars[bar["title"]].SetVerticalTitleSeparation(8)  # pixels between title and top label
    fit_overlays(plotter)
    _map_directly(actor, mesh, "values")
    return _shade(plotter, mesh, actor, wireframe, name, cull_hidden)


def _white_directional_lights(renderer) -> int:
    """The number of lights on in ``renderer`` if VTK's shaders light with one uniform direction and colour
    each ("lightDirectionVC<i>", "lightColor<i>": every light directional, and not one lone headlight of
    intensity 1, which VTK lights without uniforms) and all are white; else 0."""
    lights = [light for light in renderer.GetLights() if light.GetSwitch()]
    if not lights or any(light.GetPositional() for light in lights):
        return 0
    if len(lights) == 1 and lights[0].LightTypeIsHeadlight() and lights[0].GetIntensity() == 1.0:
        return 0
    if any(len(set(light.GetDiffuseColor())) != 1 for light in lights):
        return 0
    return len(lights)


def _shade(plotter, mesh, actor, wireframe: bool, name: str, cull_hidden: bool):
    """Light ``actor``'s surface per vertex (Gouraud shading proper) instead of per pixel, cull the faces whose
    back cannot show (``cull_hidden``), and return it.

    Why: on software OpenGL (llvmpipe under Xvfb) most of a frame of ICT FaceKit (53k small triangles) is spent
    per triangle and per 4x4 pixel block of it: the rasteriser's set-up, the depth test, and the fragment
    shader's inputs. VTK's per-pixel lighting interpolates the view-space position and normal (7 floats) and
    normalises them in every pixel; here the vertex shader computes each light's diffuse and specular terms
    for both sides of the surface (VTK lights a face seen from behind with its normal flipped) into one vec4,
    and the fragment shader only picks a side and applies the material colour (a colour map's included).
    Culling drops the faces turned away (the back of the head, the far halves of the eyes and teeth, 40% of
    ICT's triangles from the front) before they are rasterised; the parts whose backs can show (eyelashes,
    the eyelids' occlusion sheets, the mouth bag, a face mask) get a second actor of their faces reversed,
    lit as their back. Measured under Xvfb on ICT at the default window size: see the README's Benchmarks.
    The picture: the same but for highlights a pixel or two off at a few places (within the screenshot
    tests' tolerance). Only for what the uniforms describe (white directional lights, the ones
    ``style_plotter`` sets) and a mesh with vertex normals, without edges drawn (VTK draws them through a
    geometry shader, which would have to pass the new input on); anything else keeps VTK's per-pixel
    lighting, both sides drawn.
    """
    if wireframe:
        return actor
    back = shade_surface_actor(plotter.renderer, mesh, actor, cull_hidden)
    if back is not None:
        plotter.add_actor(back, name=f"{name}_backs", reset_camera=False, render=False)
    return actor


def shade_surface_actor(renderer, mesh, actor, cull_hidden: bool):
    """``_shade``'s work on ``renderer``: per-vertex lighting for ``actor`` and, with ``cull_hidden``, its hidden
    back sides culled; returns the actor of the reversed faces whose backs can show (for the caller to add after
    ``actor``), or None."""
    n_lights = _white_directional_lights(renderer)
    if not n_lights or mesh.GetPointData().GetNormals() is None:
        return None
    culled = cull_hidden and getattr(mesh, "_faces", None) is not None
    _vertex_lighting(actor, n_lights, "front" if culled else "both")
    if not culled:
        return None
    from vtkmodules.vtkCommonDataModel import vtkPolyData
    from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper
    actor.GetProperty().BackfaceCullingOn()
    cells, _faces = _back_sides(mesh)
    if cells is None:
        return None
    backs = vtkPolyData()   # the mesh's points and point data (shared arrays), the reversed faces
    backs.SetPoints(mesh.GetPoints())
    backs.GetPointData().ShallowCopy(mesh.GetPointData())
    backs.SetPolys(cells)
    mapper = vtkPolyDataMapper()
    mapper.ShallowCopy(actor.GetMapper())   # the same colouring
    mapper.SetInputData(backs)
    back = vtkActor()
    back.SetMapper(mapper)
    back.SetProperty(actor.GetProperty())   # its back faces culled too: it draws the reversed faces seen from the front
    _vertex_lighting(back, n_lights, "back")
    object.__setattr__(mesh, "_backs", backs)
    return back


def _back_sides(mesh):
    """(vtkCellArray of the mesh's faces whose back can show, each reversed (``solvers.mesh.reversed_faces``);
    their face indices), cached on the mesh; (None, None) when every face's back is hidden. Those faces and their
    reversed cells may be found beforehand, off the GUI thread (``model.rig_prep.DefaultView``: the mesh's
    ``_hidden_faces`` and ``_back_layout``)."""
    cached = getattr(mesh, "_back_cells", None)
    if cached is None:
        from vtkmodules.util.numpy_support import vtk_to_numpy

        from solvers.mesh import hidden_back_faces
        counts, indices = mesh._faces
        hidden = getattr(mesh, "_hidden_faces", None)
        layout = getattr(mesh, "_back_layout", None)    # (faces, offsets, ids) of the faces whose back can show
        if hidden is None or len(hidden) != len(counts):
            points = vtk_to_numpy(mesh.GetPoints().GetData())   # a pyvista mesh's ``points``, or a plain vtkPolyData's
            hidden, layout = hidden_back_faces(points, counts, indices), None
        faces = np.flatnonzero(~hidden) if layout is None else layout[0]
        cached = (None, None)
        if faces.size:
            cells = cell_array(*(reversed_faces(counts, indices, faces) if layout is None else layout[1:]))
            cached = (cells, faces)
        object.__setattr__(mesh, "_back_cells", cached)
    return cached


def surface_face(mesh, dataset, cell: int) -> int:
    """The mesh's face index of ``cell`` of a picked ``dataset``: the mesh itself, or its backs' actor."""
    if dataset is not None and dataset is getattr(mesh, "_backs", None):
        return int(_back_sides(mesh)[1][cell])
    return int(cell)


VTK_ALPHA_DISCARD = "if (gl_FragData[0].a <= 0.0)\n    {\n    discard;\n    }"   # in vtkPolyDataFS.glsl


def _vertex_lighting(actor, n_lights: int, side: str = "both") -> None:
    """Per-vertex lighting (see ``_shade``) of the sides of ``actor``'s faces that it draws: ``"both"``, ``"front"``
    (its back faces culled) or ``"back"`` (it draws reversed faces, lit as the back side, the reversed back faces
    culled). One side needs two interpolated values (diffuse, specular), both sides four: llvmpipe sets up and
    interpolates every value in every triangle (~1 ms CPU a frame of ICT less with two, the same picture)."""
    specular = actor.GetProperty().GetSpecular() > 0
    sides = {"both": ((0, ""), (2, "-")), "front": ((0, ""),), "back": ((0, "-"),)}[side]  # (offset, normal's sign)
    width = 2 * len(sides)
    side_terms = []
    for i in range(n_lights):
        for k, sign in sides:       # lit.xy: the first side drawn, lit.zw: the back (normal flipped) when both are
            side_terms.append(f"d = max(0.0, dot({sign}n, -lightDirectionVC{i}));")
            side_terms.append(f"lit[{k}] += d * lightColor{i}.g;")
            if specular:
                side_terms.append(f"lit[{k + 1}] += sign(d) * pow(max(1e-5, dot(reflect(lightDirectionVC{i}, "
                                  f"{sign}n), eye)), specularPowerUniform) * lightColor{i}.g;")
    sp = actor.GetShaderProperty()
    sp.ClearAllShaderReplacements()
    uniforms = "".join(f"uniform vec3 lightColor{i};\nuniform vec3 lightDirectionVC{i};\n" for i in range(n_lights))
    sp.AddVertexShaderReplacement("//VTK::Normal::Dec", True, "//VTK::Normal::Dec\n" + uniforms
                                  + f"uniform float specularPowerUniform;\nout vec{width} vertexLightVSOutput;\n", False)
    sp.AddVertexShaderReplacement("//VTK::Normal::Impl", True, "\n".join(
        ["//VTK::Normal::Impl", "{", "vec3 n = normalize(normalMatrix * normalMC);",
         "vec3 eye = normalize(-(MCVCMatrix * vertexMC).xyz);", f"vec{width} lit = vec{width}(0.0);", "float d;"]
        + side_terms + ["vertexLightVSOutput = lit;", "}"]), False)
    sp.AddFragmentShaderReplacement("//VTK::Normal::Dec", True,
                                    f"//VTK::Normal::Dec\nin vec{width} vertexLightVSOutput;", False)
    sp.AddFragmentShaderReplacement("//VTK::Normal::Impl", True, "", False)
    pick = "vertexLightVSOutput" if side != "both" else \
        "gl_FrontFacing ? vertexLightVSOutput.xy : vertexLightVSOutput.zw"
    spec = " + lit.y * specularColor" if specular else ""
    sp.AddFragmentShaderReplacement(
        "//VTK::Light::Impl", True,
        f"vec2 lit = {pick};\ngl_FragData[0] = vec4(ambientColor + lit.x * diffuseColor{spec}, opacity);", False)
    if actor.GetProperty().GetOpacity() > 0:
        # VTK's shader ends with ``if (gl_FragData[0].a <= 0.0) discard;``, never true for this surface (its alpha
        # is the opacity). A shader that may discard makes llvmpipe write depth late, after shading every 4x4
        # block of a triangle; without it the depth test and write come first (~1 ms CPU a frame of ICT).
        sp.AddFragmentShaderReplacement(VTK_ALPHA_DISCARD, True, "", False)


def _legend_white_text(legend, entries) -> None:
    """White text beside each swatch: a legend's text took its swatch's colour (a dark blue region's name was
    unreadable on the dark box). Each swatch is a square carrying its colour as cell scalars."""
    import pyvista as pv
    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    for i, (_text, color) in enumerate(entries):
        swatch = pv.PolyData(square, faces=[4, 0, 1, 2, 3])
        swatch.cell_data["rgb"] = np.array([[int(round(255 * c)) for c in color]], dtype=np.uint8)
        legend.SetEntrySymbol(i, swatch)
        legend.SetEntryColor(i, 1.0, 1.0, 1.0)
    legend.ScalarVisibilityOn()
    legend.SetPadding(4)


@dataclass(frozen=True)
class OverlayLayout:
    """Where a colour map's legend and colour bar go in a picture of ``size`` (w, h) pixels (``overlay_layout``):
    boxes (x, y, width, height) in pixels from the lower left corner (VTK's display), None when not shown;
    ``font``: the size in pixels of the bar's text and of the titles; ``room`` (left, right): the pixels at each
    side that the camera keeps clear of the model (``camera_placement``)."""
    legend: tuple[float, float, float, float] | None
    bar: tuple[float, float, float, float] | None
    font: int
    room: tuple[float, float]


def overlay_layout(size, legend_labels=None, bar_title: str | None = None, titled: bool = False) -> OverlayLayout:
    """The legend (``legend_labels``: a row each) in the upper left corner (below the picture's title if ``titled``)
    and the colour bar (titled ``bar_title``, None: no bar) at the right edge, its labels right of it and its title
    above, for a picture of ``size``.

    Their text grows with the picture's smaller side: a legend row is min(w, h) / 46 pixels high, kept within 15 and
    24 (readable in a 600x300 picture, not huge at 4K), the bar's text and the titles 0.72 of a row. The legend is
    as wide as its longest label needs (at most 45% of the picture; its text shrinks to fit a narrower box). Was: a
    legend of 220 pixels sized for the viewport and drawn at that fraction of an exported picture (600x300: rows of
    7 pixels), over the character's right eye at the viewport's default size, as the bar was over the head's side."""
    w, h = (max(int(v), 1) for v in size)
    row = float(np.clip(min(w, h) / 46, 15, 24))
    font = int(round(0.72 * row))
    margin = round(0.6 * row)
    legend = bar = None
    left = right = 0.0
    if legend_labels:
        chars = max(len(str(t)) for t in legend_labels)
        width = min(row * (1.6 + 0.5 * chars), 0.45 * w)
        top = margin + (1.6 * font if titled else 0)
        height = min(row * len(legend_labels) + 8, h - top - margin)
        legend = (margin, h - top - height, width, height)
        left = width + 2 * margin
    if bar_title is not None:
        lines = bar_title.splitlines() or [""]
        title_width = 0.62 * font * max(len(t) for t in lines)     # centred over the bar and its labels
        width = 3.6 * row
        bottom = 0.1 * h
        bar = (w - margin - (max(width, title_width) + width) / 2, bottom, width, h - margin - bottom)
        right = max(width, title_width) + 2 * margin
    return OverlayLayout(legend, bar, font, (left, right))


TITLES = ("legend_title", "title")   # the corner texts that ``fit_overlays`` sizes: a colour map's, a picture's


def _overlays(renderer) -> tuple:
    """(legend actor, colour bar actor, titles (``TITLES``)) that ``renderer`` shows (None where it shows none)."""
    legend = bar = None
    named = getattr(renderer, "actors", {})
    texts = [named[n] for n in TITLES if n in named and named[n].GetVisibility()]
    for actor in renderer.GetViewProps():
        if not actor.GetVisibility():
            continue
        if actor.IsA("vtkLegendBoxActor"):
            legend = actor
        elif actor.IsA("vtkScalarBarActor"):
            bar = actor
    return legend, bar, texts


def _layout_of(renderer, size) -> OverlayLayout:
    legend, bar, _texts = _overlays(renderer)
    labels = [legend.GetEntryString(i) or "" for i in range(legend.GetNumberOfEntries())] if legend else None
    titled = "title" in getattr(renderer, "actors", {})
    return overlay_layout(size, labels, (bar.GetTitle() or "") if bar is not None else None, titled)


def renderer_size(plotter, size=None) -> tuple[int, int]:
    """``size`` if given, else the pixels of the plotter's active renderer (its subplot's share of the window)."""
    if size:
        return max(1, int(size[0])), max(1, int(size[1]))
    w, h = plotter.window_size
    x0, y0, x1, y1 = plotter.renderer.GetViewport()
    return max(1, round(w * (x1 - x0))), max(1, round(h * (y1 - y0)))


def overlay_room(plotter, size=None) -> tuple[float, float]:
    """The pixels at the left and right of the plotter's active renderer, ``size`` (w, h) pixels (default: as it is
    now), that its legend and colour bar take (``overlay_layout``): (0, 0) without them (or once it is closed)."""
    if getattr(plotter, "_closed", False):
        return 0.0, 0.0
    return _layout_of(plotter.renderer, renderer_size(plotter, size)).room


def fit_overlays(plotter, size=None) -> None:
    """Place and size the legend, colour bar and titles of the plotter's active renderer, ``size`` (w, h) pixels
    (default: as it is now), as ``overlay_layout`` says: when a colour map is drawn and before a picture is taken at
    another size (``Viewport.picture``). Nothing here runs per frame."""
    if getattr(plotter, "_closed", False):      # its window is gone (a colour map set as the window closes)
        return
    w, h = renderer_size(plotter, size)
    legend, bar, texts = _overlays(plotter.renderer)
    layout = _layout_of(plotter.renderer, (w, h))
    if legend is not None and layout.legend is not None:
        x, y, lw, lh = layout.legend
        legend.SetPosition(x / w, y / h)
        legend.SetPosition2(lw / w, lh / h)
    if bar is not None and layout.bar is not None:
        x, y, bw, bh = layout.bar
        bar.SetPosition(x / w, y / h)
        bar.SetPosition2(bw / w, bh / h)
        bar.UnconstrainedFontSizeOn()
        for prop in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
            prop.SetFontSize(layout.font)
    for text in texts:
        text.SetMinimumFontSize(layout.font)
        text.SetMaximumFontSize(layout.font)


def _map_directly(actor, mesh, name: str) -> None:
    """Feed the mesh to the mapper directly, colouring by point array ``name``.

    pyvista puts a Python ``ActiveScalarsAlgorithm`` between a mesh and its mapper; it runs again (a shallow
    copy through the VTK pipeline from Python) each time the mesh's points move, ~1-2 ms a frame in playback.
    Our meshes are not shared between mappers, so the mapper can read the array by name itself.
    """
    mapper = actor.GetMapper()
    mapper.SetInputData(mesh)
    mapper.SetScalarModeToUsePointFieldData()
    mapper.SelectColorArray(name)
    mapper.ScalarVisibilityOn()


def style_plotter(plotter, playback: bool = False) -> None:
    """Background gradient and two camera-attached lights: a key from above-left and a headlight fill.

    Two lights, not VTK's five-light kit: on software OpenGL every light is paid per pixel, and the
    kit makes a frame of ICT FaceKit ~15 ms slower (measured under Xvfb) for a barely different look.
    ``playback=True`` (views redrawn 30 times a second): a flat background and one key light, ~8 ms less a
    frame for two views in a 1400x340 window (measured under Xvfb); pair it with ``add_surface(specular=0)``.
    """
    import pyvista as pv
    for renderer in plotter.renderers:
        # No frustum culling: it asks every actor for its bounds each render, and for a mesh whose points
        # moved that is a pass over all cells (~25% of a playback frame under Xvfb); a face is always in view.
        renderer.GetCullers().RemoveAllItems()
    for renderer in plotter.ren_win.GetRenderers():   # pyvista's own layer-1 renderer too: each decides its own
        blend_only_when_needed(renderer)
    plotter.remove_all_lights()
    if playback:
        plotter.set_background(BACKGROUND_FLAT)
        plotter.add_light(pv.Light(position=(-0.35, 0.5, 1.0), focal_point=(0, 0, 0), light_type="camera light",
                                   intensity=1.05))
        return
    plotter.set_background(BACKGROUND_BOTTOM, top=BACKGROUND_TOP)
    plotter.add_light(pv.Light(position=KEY_LIGHT_POSITION, focal_point=(0, 0, 0), light_type="camera light",
                               intensity=KEY_LIGHT_INTENSITY))
    plotter.add_light(pv.Light(light_type="headlight", intensity=FILL_LIGHT_INTENSITY))


GL_BLEND = 0x0BE2   # the OpenGL enum (VTK's Python wrapping takes the number)


def needs_blending(renderer) -> bool:
    """Whether anything ``renderer`` draws mixes with what lies behind it: a visible 2D actor (text, legends,
    colour bars, point labels: their glyphs are alpha-textured) or a visible prop with translucent geometry."""
    return any(p.GetVisibility() and (p.IsA("vtkActor2D") or p.HasTranslucentPolygonalGeometry())
               for p in renderer.GetViewProps())


def blend_only_when_needed(renderer) -> None:
    """Turn OpenGL blending off for the renders of ``renderer`` in which nothing needs it (``needs_blending``),
    on again for the others, decided as each render starts (an observer of its StartEvent).

    Why: VTK enables blending for the whole frame. On software OpenGL (llvmpipe under Xvfb) a blended pixel
    is read, mixed and written back, and the gradient background's full-window quad and the opaque surface
    pay for it although every one of their pixels is opaque (alpha 1: the same picture, bit for bit).
    Measured on ICT in the main window: ~3 ms CPU a render less (see the README's Benchmarks)."""
    from vtkmodules.vtkCommonCore import vtkCommand   # not all of VTK (``import vtk``: ~0.4 s in a fresh process)
    if getattr(renderer, "_blend_observer", None) is not None:
        return

    def on_start(ren, _event) -> None:
        state = ren.GetRenderWindow().GetState()
        (state.vtkglEnable if needs_blending(ren) else state.vtkglDisable)(GL_BLEND)

    renderer._blend_observer = renderer.AddObserver(vtkCommand.StartEvent, on_start)


GL_READ_FRAMEBUFFER, GL_COLOR_BUFFER_BIT, GL_NEAREST = 0x8CA8, 0x4000, 0x2600


def copy_cached_background(renderer) -> None:
    """Fill ``renderer``'s frames with its gradient background copied from a cached image, not drawn anew.

    Why: VTK draws a gradient background as a full-window quad through a shader on every render; on software
    OpenGL (llvmpipe under Xvfb) that is ~2 ms CPU a frame (about 1 ms on the two raster threads) for the same
    pixels each time. Here, as each render starts (an observer of its StartEvent), the renderer's own
    background drawing (``vtkOpenGLRenderer.Clear``: the gradient, dithered as VTK dithers it) runs once into
    an off-screen frame buffer of the window's size, and every frame then starts with a copy of it (a plain
    memory copy: the same format) while the renderer clears depth only (``PreserveColorBuffer``). The picture is
    the same, bit for bit. The cache is redrawn when the window's size or the background changes; renders this
    does not fit (a gradient off, a renderer not covering the window, multisampling, hardware selection) draw
    their background as VTK does."""
    from vtkmodules.vtkCommonCore import VTK_UNSIGNED_CHAR, vtkCommand   # not all of VTK (see blend_only_when_needed)
    if getattr(renderer, "_background_observer", None) is not None:
        return
    cache: dict = {"fbo": None, "key": None}

    def on_start(ren, _event) -> None:
        win = ren.GetRenderWindow()
        w, h = win.GetSize()
        usable = (ren.GetGradientBackground() and not ren.GetTexturedBackground() and ren.GetLayer() == 0
                  and tuple(ren.GetViewport()) == (0.0, 0.0, 1.0, 1.0) and win.GetMultiSamples() <= 1
                  and ren.GetSelector() is None and w > 0 and h > 0)
        if not usable:
            ren.SetPreserveColorBuffer(False)
            return
        from vtkmodules.vtkRenderingOpenGL2 import vtkOpenGLFramebufferObject
        state = win.GetState()
        key = (w, h, ren.GetBackground(), ren.GetBackground2(), ren.GetDitherGradient(), ren.GetGradientMode(),
               ren.GetBackgroundAlpha())
        if cache["key"] != key or cache["fbo"] is None:
            fbo = cache["fbo"]
            if fbo is None:
                fbo = cache["fbo"] = vtkOpenGLFramebufferObject()
                fbo.SetContext(win)
            state.PushFramebufferBindings()
            fbo.PopulateFramebuffer(w, h, True, 1, VTK_UNSIGNED_CHAR, False, 0, 0)   # binds it
            fbo.ActivateDrawBuffer(0)
            state.vtkglViewport(0, 0, w, h)
            state.vtkglScissor(0, 0, w, h)
            ren.SetPreserveColorBuffer(False)
            ren.Clear()                     # VTK's own background, into the cache
            state.PopFramebufferBindings()
            cache["key"] = key
        ren.SetPreserveColorBuffer(True)    # this render clears depth only: its colour comes from the cache
        state.PushReadFramebufferBinding()
        cache["fbo"].Bind(GL_READ_FRAMEBUFFER)
        cache["fbo"].ActivateReadBuffer(0)
        state.vtkglScissor(0, 0, w, h)      # the camera sets the render's own viewport and scissor next
        state.vtkglBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL_COLOR_BUFFER_BIT, GL_NEAREST)
        state.PopReadFramebufferBinding()

    renderer._background_observer = renderer.AddObserver(vtkCommand.StartEvent, on_start)
    renderer._background_cache = cache


def drop_cached_background(renderer) -> None:
    """Undo ``copy_cached_background``: VTK draws the background again, and the cache's frame buffer is released
    (call it while the render window is still open)."""
    if getattr(renderer, "_background_observer", None) is None:
        return
    renderer.RemoveObserver(renderer._background_observer)
    renderer._background_observer = None
    renderer.SetPreserveColorBuffer(False)
    fbo = renderer._background_cache["fbo"]
    if fbo is not None and renderer.GetRenderWindow() is not None:
        fbo.ReleaseGraphicsResources(renderer.GetRenderWindow())
    renderer._background_cache = None


def camera_direction(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(direction from focus to eye, view up) for a camera preset. The face looks down +Z, Y up."""
    dirs = {
        "front": (0.0, 0.0, 1.0),
        "left": (1.0, 0.0, 0.0),     # the character's left side (+X)
        "right": (-1.0, 0.0, 0.0),
        "three-quarter": (0.55, 0.12, 0.83),
    }
    if name not in dirs:
        raise ValueError(f"Unknown camera '{name}': use one of {', '.join(CAMERAS)}.")
    d = np.asarray(dirs[name])
    return d / np.linalg.norm(d), np.array([0.0, 1.0, 0.0])


def set_camera(plotter, name: str, focus_points: np.ndarray, view_angle: float = 30.0,
               size: tuple[int, int] | None = None, direction: tuple | None = None) -> None:
    """Frame ``focus_points`` (e.g. the face area) from a preset direction (or ``direction``: (focus-to-eye,
    view up), e.g. where the camera looks now), for the plotter's window size or the given (w, h).

    The camera looks at the centre of the points' box and stands as close as it can with every point inside
    the view (each at its own depth: the nose nearer than the ears), with a margin of 10%: a box's bounding
    sphere wasted a third of the view on a face, which is much deeper and narrower than it is tall. The points
    are framed beside the colour map's legend and bar, not under them (``overlay_room``)."""
    room = overlay_room(plotter, size)
    center, position, up = camera_placement(name, focus_points, renderer_size(plotter, size), view_angle, direction,
                                            room=room)
    # the renderer's camera, not ``plotter.camera``: for a camera never set (a new view's first surface) pyvista's
    # getter first frames the scene's bounds itself and renders it twice, whole pictures for nothing (every value it
    # sets is set here; on a 422k-vertex rig ~0.1 s each); marked set, so that its later reads keep this one
    cam = plotter.renderer.camera
    cam.view_angle = view_angle
    cam.focal_point = center.tolist()
    cam.position = position.tolist()
    cam.up = up.tolist()
    cam.is_set = True
    plotter.reset_camera_clipping_range()


def camera_placement(name: str, focus_points: np.ndarray, size: tuple[int, int], view_angle: float = 30.0,
                     direction: tuple | None = None, room: tuple[float, float] = (0.0, 0.0)
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(focal point, position, view up) of ``set_camera``'s camera for a picture of ``size`` (w, h) pixels, the
    points framed in the part of it between ``room`` (left, right) pixels kept clear at its sides (at least a
    quarter of the picture's width is used): the camera looks beside the points' centre so that they sit in the
    middle of that part."""
    pts = np.asarray(focus_points, dtype=np.float64).reshape(-1, 3)
    lo, hi = bounds(pts)
    center = (lo + hi) / 2
    d, up = camera_direction(name) if direction is None else (np.asarray(direction[0], dtype=np.float64),
                                                              np.asarray(direction[1], dtype=np.float64))
    d = d / np.linalg.norm(d)
    right = np.cross(up, d)
    if np.linalg.norm(right) < 1e-9:   # looking along the up vector: any perpendicular will do
        right = np.cross(np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0]), d)
    right /= np.linalg.norm(right)
    true_up = np.cross(d, right)
    rel = pts - center
    x, y, z = np.abs(rel @ right) * 1.1, np.abs(rel @ true_up) * 1.1, rel @ d   # z: towards the eye
    w, h = size
    left, right_room = (float(v) for v in room)
    free = max(w - left - right_room, 0.25 * w)
    t = np.tan(np.radians(view_angle / 2))
    aspect = free / h if free > 0 and h > 0 else 1.0
    dist = float(np.max(z + np.maximum(y / t, x / (t * aspect)))) if len(pts) else 1.0
    dist = max(dist, 1e-6 + float(z.max(initial=0.0)), 1e-6)
    # the free part's middle lies (left - right) / 2 pixels right of the picture's: the camera looks that far left
    shift = (left - right_room) / 2 if free > 0.25 * w else 0.0
    focal = center - right * (shift / (h / 2) * t * dist if h > 0 else 0.0)
    return focal, focal + d * dist, true_up


def offscreen_plotter(size):
    """A pyvista plotter drawing off screen at ``size`` (w, h) pixels, in the application's look (``style_plotter``):
    what ``render_png`` draws into (a batch's previews draw the same picture on the CPU:
    ``app.cli_batch.preview_image``)."""
    use_offscreen_backend_if_headless()
    import pyvista as pv
    plotter = pv.Plotter(off_screen=True, window_size=list(size))
    try:
        style_plotter(plotter)
    except BaseException:
        plotter.close()
        raise
    return plotter


def render_png(points, face_counts, face_indices, out_path, *, focus=None, colormap: ColorMap | None = None,
               camera: str = "front", size=(1024, 768), wireframe=False, overlays=None, title: str = "",
               texture=None, base_colors: np.ndarray | None = None) -> None:
    """Render the surface off screen to a PNG file, atomically (a temporary beside it, then moved into place:
    a killed render never leaves a truncated PNG under the final name). ``texture(plotter, mesh, wireframe)``
    adds the surface instead, textured (widgets.texture_view.textured_surface). ``base_colors``: the parts'
    colours without a colour map (``add_surface``)."""
    plotter = offscreen_plotter(size)
    try:
        mesh = rig_mesh(points, face_counts, face_indices)
        if texture is not None and colormap is None:
            texture(plotter, mesh, wireframe)
        else:
            add_surface(plotter, mesh, colormap, wireframe=wireframe, cull_hidden=True, base_colors=base_colors)
        for add in overlays or ():
            add(plotter)
        if title:
            plotter.add_text(title, position="upper_left", font_size=11, color="white", name="title", render=False)
            fit_overlays(plotter)
        set_camera(plotter, camera, points if focus is None else focus)
        write_image_atomically(plotter, out_path)
    finally:
        plotter.close()


def write_image_atomically(plotter, out_path) -> None:
    """``plotter.screenshot`` to a temporary of the same extension beside ``out_path``, then ``os.replace``: the
    ``render`` command's picture (the window's File ▸ Export Image takes ``Viewport.picture`` and writes it with
    ``model.atomic.write_png`` off the GUI thread)."""
    import os

    from model.atomic import check_output_file, disk_errors, remove_stale_temporaries, temp_path
    out = check_output_file(out_path)      # a folder or a device: one sentence (an OSError too), nothing written
    tmp = temp_path(out, suffix=out.suffix or ".png")
    try:
        with disk_errors(out):             # a full disk: one sentence naming the picture, no temporary left
            out.parent.mkdir(parents=True, exist_ok=True)
            remove_stale_temporaries(out.parent)
            plotter.screenshot(str(tmp))
            os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
