"""The viewport's pick: VTK's cell picker over only the faces the pick's ray passes near.

VTK's ``vtkCellPicker`` without a locator intersects the ray with every face of every pickable actor, ~15 ms on
ICT FaceKit's 26k faces (the brush cursor picks on every mouse move). With a cell locator it is fast, but it then
keeps the nearest face the ray meets within the pick tolerance, where the pass over every face prefers, among the
faces met within the tolerance of the nearest, one the ray meets inside (not beside): near an edge the two pick
neighbouring faces, 14% of the pixels over ICT's face. So the pass is kept and given less to do: each pickable
surface's faces near the ray (``solvers.ray_pick``: their boxes, grown by 20 times the tolerance, met by the ray)
are put in order into a pick-only copy sharing the surface's points, and the picker, given those copies as its
pick list in the renderer's order, runs its pass over them: the faces it skips are faces the ray cannot meet, so
it picks the same face and point as over every face (ICT: ~1 ms, the boxes made again after the points change).
Anything else pickable (not a plain polygon surface, a transform, clipping planes) is picked as before.
"""
from __future__ import annotations

import numpy as np

from solvers.ray_pick import face_boxes, faces_near_ray

from .scene import cell_array

TOLERANCE = 0.0005   # VTK's pick tolerance, a fraction of the window's diagonal (at the focal point's depth)
MARGIN = 20.0        # the faces near the ray: their boxes grown by this many tolerances


def display_to_world(renderer, x: float, y: float, z: float) -> np.ndarray:
    """The world point at display pixel (x, y) and depth ``z`` (0 the near plane, 1 the far) of ``renderer``."""
    renderer.SetDisplayPoint(float(x), float(y), float(z))
    renderer.DisplayToWorld()
    p = np.array(renderer.GetWorldPoint())
    return p[:3] / p[3]


class FacePicker:
    """Picks on a renderer: ``pick(renderer, x, y)`` → (the picked data set, its cell, the world point) or None."""

    def __init__(self) -> None:
        from vtkmodules.vtkRenderingCore import vtkCellPicker
        self.picker = vtkCellPicker()
        self.picker.SetTolerance(TOLERANCE)
        self._boxes: dict[int, tuple] = {}    # id(data set shown) → (it, its MTime, lo, hi, offsets, connectivity)
        self._copies: list = []               # pick-only actors, reused

    def pick(self, renderer, x: int, y: int):
        picker = self.picker
        surfaces = self._surfaces(renderer)
        if surfaces is None:                  # something else pickable: the pass over everything, as VTK does it
            picker.PickFromListOff()
            if not picker.Pick(x, y, 0, renderer) or picker.GetCellId() < 0:
                return None
            return picker.GetDataSet(), int(picker.GetCellId()), np.array(picker.GetPickPosition())
        for key in [k for k, v in self._boxes.items() if all(v[0] is not d for d in surfaces)]:
            del self._boxes[key]              # a surface no longer shown (a new rig, parts hidden): let it go
        origin, direction, margin = self._ray(renderer, x, y)
        picker.InitializePickList()
        picker.PickFromListOn()
        chosen = []
        for k, data in enumerate(surfaces):
            lo, hi, offsets, connectivity = self._faces(data)
            ids = faces_near_ray(lo, hi, origin, direction, margin)
            actor = self._copy(k, data, ids, offsets, connectivity)
            picker.AddPickList(actor)
            chosen.append((actor, data, ids))
        found = picker.Pick(x, y, 0, renderer)
        cell = picker.GetCellId()
        hit = None
        if found and cell >= 0:
            for actor, data, ids in chosen:
                if actor.GetMapper().GetInput() is picker.GetDataSet():
                    hit = (data, int(ids[cell]), np.array(picker.GetPickPosition()))
        picker.InitializePickList()
        picker.PickFromListOff()
        for actor, _data, _ids in chosen:
            actor.GetMapper().SetInputData(None)   # the copies hold no surface's points between picks
        return hit

    def _surfaces(self, renderer) -> list | None:
        """The data sets of the pickable props in the renderer's order, if all are plain polygon surfaces (no
        transform, no clipping planes); None otherwise."""
        from vtkmodules.vtkCommonDataModel import vtkPolyData
        from vtkmodules.vtkRenderingCore import vtkActor, vtkProp3D
        out = []
        for prop in renderer.GetViewProps():
            if not (prop.GetPickable() and prop.GetVisibility() and isinstance(prop, vtkProp3D)):
                continue
            if not isinstance(prop, vtkActor) or prop.GetProperty().GetOpacity() <= 0.0:
                return None
            mapper = prop.GetMapper()
            data = None if mapper is None else mapper.GetInput()
            if not isinstance(data, vtkPolyData) or data.GetNumberOfCells() != data.GetNumberOfPolys() \
                    or not prop.GetMatrix().IsIdentity() or mapper.GetNumberOfClippingPlanes():
                return None
            if data.GetNumberOfCells():
                out.append(data)
        return out

    @staticmethod
    def _ray(renderer, x: int, y: int):
        """The line under display pixel (x, y) (a point on it and its direction) and the margin (world units)."""
        def world(dx, dy, dz):
            return display_to_world(renderer, dx, dy, dz)

        near, far = world(x, y, 0.0), world(x, y, 1.0)
        focal = renderer.GetActiveCamera().GetFocalPoint()
        renderer.SetWorldPoint(*focal, 1.0)
        renderer.WorldToDisplay()
        z = renderer.GetDisplayPoint()[2]
        (x0, y0), (w, h) = renderer.GetOrigin(), renderer.GetSize()
        diagonal = np.linalg.norm(world(x0 + w, y0 + h, z) - world(x0, y0, z))
        return near, far - near, MARGIN * TOLERANCE * diagonal

    def _faces(self, data):
        """(lo, hi, offsets, connectivity) of ``data``'s faces, made again when it has changed."""
        from vtkmodules.util.numpy_support import vtk_to_numpy
        mtime = data.GetMTime()
        cached = self._boxes.get(id(data))
        if cached is None or cached[0] is not data or cached[1] != mtime:
            polys = data.GetPolys()
            offsets = vtk_to_numpy(polys.GetOffsetsArray()).astype(np.int64, copy=False)
            connectivity = vtk_to_numpy(polys.GetConnectivityArray()).astype(np.int64, copy=False)
            points = vtk_to_numpy(data.GetPoints().GetData())
            cached = (data, mtime, *face_boxes(points, offsets, connectivity), offsets, connectivity)
            self._boxes[id(data)] = cached
        return cached[2:]

    def _copy(self, k: int, data, ids: np.ndarray, offsets: np.ndarray, connectivity: np.ndarray):
        """Pick-only actor ``k``: faces ``ids`` of ``data``, in order, over its very points."""
        from vtkmodules.vtkCommonDataModel import vtkPolyData
        from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper
        while len(self._copies) <= k:
            actor, mapper = vtkActor(), vtkPolyDataMapper()
            actor.SetMapper(mapper)
            self._copies.append(actor)
        counts = offsets[ids + 1] - offsets[ids]
        sub = np.zeros(len(ids) + 1, dtype=np.int64)
        np.cumsum(counts, out=sub[1:])
        at = np.repeat(offsets[ids] - sub[:-1], counts) + np.arange(sub[-1], dtype=np.int64)
        faces = vtkPolyData()
        faces.SetPoints(data.GetPoints())
        faces.SetPolys(cell_array(sub, connectivity[at]))
        actor = self._copies[k]
        actor.GetMapper().SetInputData(faces)
        return actor
