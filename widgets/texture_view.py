"""Drawing a blended texture on the rig surface (viewport and ``render``): no algorithm, only VTK plumbing.

The textured surface is a display-only copy of the rig mesh split at UV seams (``model.textures.DisplaySplit``:
display point i is rig vertex ``vertex[i]``); its points and normals are gathered from the rig surface's on
every update, so the rig's own vertices are never reordered. The texture's pixels are rewritten in place
(only the boxes a blend changed) instead of uploading a new image object every frame.
"""
from __future__ import annotations

import numpy as np

from .scene import polygon_mesh


class TexturedSurface:
    """A pyvista mesh with texture coordinates and a texture whose image is updated in place."""

    def __init__(self, points: np.ndarray, normals: np.ndarray, face_counts: np.ndarray, split, image8: np.ndarray):
        import pyvista as pv
        from vtkmodules.util.numpy_support import vtk_to_numpy
        self.vertex = np.asarray(split.vertex, dtype=np.int64)
        self.mesh = polygon_mesh(np.asarray(points, np.float32)[self.vertex], face_counts, split.face_indices)
        self.mesh.point_data["Normals"] = np.asarray(normals, np.float32)[self.vertex]
        self.mesh.point_data.active_normals_name = "Normals"
        self.mesh.active_texture_coordinates = np.asarray(split.uv, np.float32)
        self.texture = pv.Texture(np.ascontiguousarray(image8))
        self.texture.interpolate = True
        image = self.texture.GetInput()
        self._scalars = image.GetPointData().GetScalars()
        h, w = image8.shape[:2]
        self._pixels = vtk_to_numpy(self._scalars).reshape(h, w, -1)   # row 0 is the image's bottom
        pd = self.mesh.GetPointData()
        self._points = vtk_to_numpy(self.mesh.GetPoints().GetData())
        self._normals = vtk_to_numpy(pd.GetNormals())
        self._vtk = (self.mesh.GetPoints(), pd.GetNormals())

    @property
    def size(self) -> tuple[int, int]:
        return self._pixels.shape[1], self._pixels.shape[0]

    def update_points(self, points: np.ndarray, normals: np.ndarray) -> None:
        """The rig surface's points and normals (V, 3), gathered to the display points."""
        self._points[:] = points[self.vertex]
        self._normals[:] = normals[self.vertex]
        for obj in self._vtk:
            obj.Modified()

    def pixels_top_down(self) -> np.ndarray:
        """The texels shown now, (H, W, 3) uint8, row 0 the top (as ``update_image`` takes them)."""
        return self._pixels[::-1, :, :3]

    def update_image(self, image8: np.ndarray, boxes=None) -> None:
        """New texels (H, W, 3) uint8, row 0 the top; ``boxes`` (row slice, column slice) limits the copy."""
        H = self._pixels.shape[0]
        if boxes is None:
            self._pixels[:] = image8[::-1]
        else:
            for rows, cols in boxes:
                self._pixels[H - rows.stop:H - rows.start, cols] = image8[rows, cols][::-1]
        self._scalars.Modified()
        self.texture.GetInput().Modified()
        self.texture.Modified()

    def add_to(self, plotter, *, wireframe: bool = False, name: str = "surface", specular: float = 0.15):
        """Add the textured surface with the skin's lighting (the texture is the colour)."""
        return plotter.add_mesh(self.mesh, texture=self.texture, color="white", smooth_shading=False,
                                interpolation="gouraud", name=name, show_edges=wireframe,
                                edge_color=(0.15, 0.15, 0.18), line_width=0.5, specular=specular,
                                specular_power=20, diffuse=0.85, ambient=0.15, reset_camera=False)


def textured_surface(split, image8: np.ndarray, face_counts: np.ndarray):
    """For ``scene.render_png(texture=...)``: adds the rig mesh's surface textured by ``image8`` through ``split``."""
    def add(plotter, mesh, wireframe: bool) -> None:
        TexturedSurface(mesh.points, mesh.point_data["Normals"], face_counts, split, image8).add_to(
            plotter, wireframe=wireframe)
    return add
