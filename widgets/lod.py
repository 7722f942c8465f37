"""A level of detail for studio-scale surfaces: fewer faces over the same vertices, drawn while the pose or the
camera keeps changing.

On software OpenGL a render of a 422k-vertex rig (840k triangles) takes 0.1-0.2 s, so a slider drag there ran at
5-9 frames/s. ParaView and VTK's LOD actors draw a decimated copy while the user interacts and the full surface
once still; so does the viewport (``widgets.viewport.Viewport``), for surfaces of more than ``LOD_MIN_TRIANGLES``.

The proxy is a decimation of the surface (``vtkDecimatePro``: it removes vertices and re-triangulates their holes,
keeping the others where they are, with the topology preserved, so lips stay apart and closed parts closed): a
subset of the surface's own vertices, by id. Each frame it draws, its points and point data (normals, colour-map
scalars, part colours) are gathered from the surface's at those ids, so what is drawn at each kept vertex is exactly
the full surface's, shading included; the surface itself, its vertex order and its arrays are never changed.
"""
from __future__ import annotations

import hashlib
import os
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from PySide6 import QtCore

from solvers.mesh import fan_triangulate, hidden_back_faces, reversed_faces
from solvers.normals import VertexNormals, compact_faces

LOD_MIN_TRIANGLES = 150_000     # above this a render on llvmpipe takes >~30 ms (the 106k rig's 210k: 33 ms)
LOD_TARGET_TRIANGLES = 50_000   # about ICT FaceKit's 53k: a production face's density
STILL_AFTER_S = 0.3             # the full surface is drawn once the pose and camera were still this long


def wants_proxy(face_counts: np.ndarray, copies: int = 1) -> bool:
    """Whether a surface of these polygons, drawn ``copies`` times by each render (the Mocap Views draw the same faces
    in two views of one window), is large enough to be drawn by a proxy while it changes: the render's cost is its
    triangles, all copies together."""
    return copies * int(np.maximum(np.asarray(face_counts) - 2, 0).sum()) > LOD_MIN_TRIANGLES


@dataclass(frozen=True)
class ProxyFaces:
    """A proxy: the surface's vertices it keeps, and its triangles over them."""
    vertices: np.ndarray        # (P,) int64 ids of the surface's vertices the proxy keeps, ascending
    triangles: np.ndarray       # (T, 3) int64 indices into ``vertices``
    back_faces: np.ndarray      # indices into ``triangles`` whose back side can be seen (``hidden_back_faces``)
    ring: np.ndarray            # ids of the vertices of the surface's faces that touch a kept vertex, ascending
    ring_normals: VertexNormals  # the normals of those faces, over ``ring``
    kept_in_ring: np.ndarray    # where each kept vertex is in ``ring``

    def normals(self, points: np.ndarray) -> np.ndarray:
        """(P, 3) float32: the full surface's display normals at the kept vertices for the surface's ``points``,
        from only the faces around them (every face at a kept vertex: the same sum as the whole surface's normals
        there), a fraction of the whole surface's work."""
        return self.ring_normals(np.asarray(points)[self.ring])[self.kept_in_ring]

    def meshes(self):
        """(front, backs or None): ``vtkPolyData`` of the proxy's triangles and of its back faces reversed, sharing
        points and point data, made on the GUI thread; ``SurfaceDetail`` fills their points and point data."""
        from vtkmodules.vtkCommonCore import vtkPoints
        from vtkmodules.vtkCommonDataModel import vtkPolyData

        from .scene import cell_array
        n = len(self.triangles)
        front = vtkPolyData()
        points = vtkPoints()
        points.SetDataTypeToFloat()
        points.SetNumberOfPoints(len(self.vertices))
        front.SetPoints(points)
        front.SetPolys(cell_array(np.arange(0, 3 * n + 1, 3, dtype=np.int64), self.triangles.ravel()))
        if not self.back_faces.size:
            return front, None
        backs = vtkPolyData()
        backs.SetPoints(points)
        backs.SetPolys(cell_array(*reversed_faces(np.full(n, 3, dtype=np.int64), self.triangles.ravel(),
                                                  self.back_faces)))
        return front, backs


def proxy_faces(points: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
                target: int | None = None, on_filter: Callable | None = None,
                cache: Path | None | bool = True) -> ProxyFaces | None:
    """About ``target`` triangles over a subset of the surface's vertices (their ids), shaped like the surface.

    Decimation by vertex removal (Schroeder, Zarge & Lorensen 1992, "Decimation of triangle meshes";
    ``vtkDecimatePro`` with topology preserved, no splitting and boundary vertices kept): a kept vertex is an
    input vertex, unmoved, found by an id array carried through the filter. Thread-safe (no rendering); 1-7 s
    at 106k-422k vertices, run on a worker thread. ``target`` defaults to ``LOD_TARGET_TRIANGLES``. ``on_filter``
    is given the filter before it runs, to stop it from another thread (``SetAbortExecute(1)``): None then.

    The decimation's triangles are kept in a cache folder (``cache``: True for the user's, ``cache_folder()``;
    None or False for none), keyed by the points, faces and target: a studio rig opened again has its proxy at
    once instead of after 7-14 s of full renders."""
    target = LOD_TARGET_TRIANGLES if target is None else target
    folder = cache_folder() if cache is True else (cache or None)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    key = _cache_key(pts, face_counts, face_indices, target) if folder is not None else ""
    triangles = _cached_triangles(folder, key, len(pts)) if folder is not None else None
    if triangles is None:
        triangles = _decimate(pts, face_counts, face_indices, target, on_filter)
        if triangles is None:
            return None
        if folder is not None:
            _store_triangles(folder, key, triangles)
    return _proxy_over(pts, face_counts, face_indices, triangles)


def _decimate(pts: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray, target: int,
              on_filter: Callable | None) -> np.ndarray | None:
    """(T, 3) int64 triangles over the surface's vertex ids (``proxy_faces``), None when stopped."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkFiltersCore import vtkDecimatePro
    tris = fan_triangulate(face_counts, face_indices).astype(np.int64)
    poly = vtkPolyData()
    vpts = vtkPoints()
    vpts.SetData(numpy_to_vtk(pts, deep=True))
    poly.SetPoints(vpts)
    cells = vtkCellArray()
    cells.SetData(numpy_to_vtkIdTypeArray(np.arange(0, 3 * len(tris) + 1, 3, dtype=np.int64), deep=True),
                  numpy_to_vtkIdTypeArray(tris.ravel(), deep=True))
    poly.SetPolys(cells)
    ids = numpy_to_vtk(np.arange(len(pts), dtype=np.float64), deep=True)   # float: exact below 2**53
    ids.SetName("ids")
    poly.GetPointData().AddArray(ids)
    decimate = vtkDecimatePro()
    decimate.SetInputData(poly)
    decimate.SetTargetReduction(max(0.0, 1.0 - target / max(len(tris), 1)))
    decimate.PreserveTopologyOn()
    decimate.SplittingOff()
    decimate.BoundaryVertexDeletionOff()
    if on_filter is not None:
        on_filter(decimate)
    _run_at_low_priority(decimate.Update)
    if decimate.GetAbortExecute():
        return None
    out = decimate.GetOutput()
    kept = vtk_to_numpy(out.GetPointData().GetArray("ids")).astype(np.int64)
    conn = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).astype(np.int64)
    offsets = vtk_to_numpy(out.GetPolys().GetOffsetsArray())
    if not np.all(np.diff(offsets) == 3):
        raise ValueError("the decimation made polygons other than triangles")
    return kept[conn].reshape(-1, 3)


def _proxy_over(pts: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray,
                triangles: np.ndarray) -> ProxyFaces:
    """The ``ProxyFaces`` of ``triangles`` (over the surface's vertex ids): the vertices they keep, their faces
    whose backs show, the ring of the surface's faces around the kept vertices for their normals."""
    vertices, local = np.unique(triangles, return_inverse=True)
    local = local.reshape(-1, 3).astype(np.int64)
    backs = np.flatnonzero(~hidden_back_faces(pts[vertices], np.full(len(local), 3), local.ravel()))
    counts = np.asarray(face_counts, dtype=np.int64)
    indices = np.asarray(face_indices, dtype=np.int64)
    is_kept = np.zeros(len(pts), dtype=bool)
    is_kept[vertices] = True
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    touching = np.add.reduceat(is_kept[indices].astype(np.int64), starts) > 0 if counts.size else np.zeros(0, bool)
    ring, ring_local = compact_faces(indices[np.repeat(touching, counts)])
    return ProxyFaces(vertices.astype(np.int64), local, backs, ring,
                      VertexNormals(counts[touching], ring_local, len(ring)), np.searchsorted(ring, vertices))


# --- the proxies' cache ----------------------------------------------------------------------------------
CACHE_VERSION = b"lod-1"    # bump when the decimation's settings change: older entries are then never read
CACHE_ENTRIES = 24          # the newest this many proxies are kept (~0.6 MB each at the default target)


def cache_folder() -> Path:
    """Where proxies are kept between sessions: ``$XDG_CACHE_HOME/blendshape-studio/lod`` (``~/.cache`` by
    default), beside the compiled kernels (``solvers.take_kernel``)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "blendshape-studio" / "lod"


def _cache_key(pts: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray, target: int) -> str:
    """A digest of what the decimation depends on (~25 ms at 422k vertices, on the worker thread)."""
    h = hashlib.blake2b(CACHE_VERSION, digest_size=16)
    for part in (pts, np.asarray(face_counts, dtype=np.int64), np.asarray(face_indices, dtype=np.int64),
                 np.array([target, len(pts)], dtype=np.int64)):
        h.update(np.ascontiguousarray(part).view(np.uint8).ravel())
    return h.hexdigest()


def _cached_triangles(folder: Path, key: str, n_points: int) -> np.ndarray | None:
    """The cached triangles of ``key``, or None when there are none or the entry is not a valid one (any (T, 3)
    integer array over ids below ``n_points``; a damaged entry is made again)."""
    path = folder / f"{key}.npy"
    try:
        triangles = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None
    if (triangles.ndim != 2 or triangles.shape[1] != 3 or not len(triangles)
            or triangles.dtype.kind not in "iu" or triangles.min() < 0 or triangles.max() >= n_points):
        return None
    try:
        os.utime(path)      # the newest used: the last one pruned
    except OSError:
        pass
    return triangles.astype(np.int64)


def _store_triangles(folder: Path, key: str, triangles: np.ndarray) -> None:
    """Keep ``triangles`` under ``key`` (written whole or not at all) and prune the oldest entries beyond
    ``CACHE_ENTRIES``; a cache that cannot be written is no cache, never an error."""
    from model.atomic import atomic_write_with
    try:
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_with(folder / f"{key}.npy", lambda f: np.save(f, triangles.astype(np.int32)))
        entries = sorted(folder.glob("*.npy"), key=lambda p: p.stat().st_mtime, reverse=True)
        for old in entries[CACHE_ENTRIES:]:
            old.unlink(missing_ok=True)
    except OSError:
        pass


class SurfaceDetail(QtCore.QObject):
    """Draws a surface mesh by its proxy's faces while renders come less than ``STILL_AFTER_S`` apart (a slider
    dragged, playback, the camera turned: every render that follows another closely), and by its own faces in the
    first render after a still moment and once the view is still again (one more render then, by this object).
    A lone change (a preset chosen, a key set) is drawn in full at once. Several meshes of the same faces drawn in
    one window (the Mocap Views' projection and dense result, ``set_meshes``) share one proxy, each drawing it with
    its own points and point data.

    The swap happens as each render starts (the render window's StartEvent), so it covers every render: the
    window's, the camera's, playback's. ``full_only`` (a picture for export) and ``allowed()`` False (a texture or
    the wireframe shown: they need the real faces) draw in full. ``show_full()`` puts the real faces back at once,
    before a pick or a new colour map. The proxy is made on a worker thread (``proxy_faces``) for each new mesh
    that ``wants_proxy``; until it arrives, everything is drawn in full."""

    _made = QtCore.Signal(object, object)    # (generation, ProxyFaces or None), from the worker thread

    def __init__(self, render_window, render: Callable[[], None], allowed: Callable[[], bool] = lambda: True) -> None:
        super().__init__()
        self._render, self._allowed = render, allowed
        self.full_only = False
        self._surfaces: list = []   # the (mesh, its SurfaceArrays or None) drawn
        self._generation = 0
        # once made: (ProxyFaces, for each surface the (front vtkPolyData, backs or None) drawing it)
        self._proxy: tuple | None = None
        self._full = None           # while the proxy is shown: the (mapper, the dataset it drew) pairs swapped
        self._drawn_proxy = False   # whether the last render drew the proxy (a pick may have swapped back since)
        self._last: float | None = None   # when the last render started
        self._still_render = False
        self._running: list = [None, None, None]   # the proxy being made: its thread, decimation filter, stop event
        self._timer = QtCore.QTimer(self, singleShot=True, interval=int(STILL_AFTER_S * 1000))
        self._timer.timeout.connect(self._when_still)
        self._made.connect(self._adopt)
        from vtkmodules.vtkCommonCore import vtkCommand
        render_window.AddObserver(vtkCommand.StartEvent, self._on_start)
        # VTK's camera styles render once more as the button that turned, panned or zoomed is released: the end of
        # the interaction, drawn in full at once (it drew the proxy, the full surface 0.3 s later)
        self._releasing = False
        interactor = render_window.GetInteractor()
        style = interactor.GetInteractorStyle() if interactor is not None else None
        if style is not None:
            # a style with observers of a button's event hands it to them instead of its own handler: pyvista's
            # observe the left button (and call the handler); for the others the handler is called here
            for event, handler in ((vtkCommand.LeftButtonReleaseEvent, None),
                                   (vtkCommand.MiddleButtonReleaseEvent, "OnMiddleButtonUp"),
                                   (vtkCommand.RightButtonReleaseEvent, "OnRightButtonUp")):
                style.AddObserver(event, lambda *_: setattr(self, "_releasing", True), 1.0)    # before the handler
                if handler is not None:     # the style as the caller: no reference from its observer back to it
                    style.AddObserver(event, lambda caller, _event, h=handler: getattr(caller, h)(), 0.0)
                style.AddObserver(event, lambda *_: setattr(self, "_releasing", False), -1.0)  # after it

    @property
    def proxy_ready(self) -> bool:
        return self._proxy is not None

    @property
    def proxy_vertices(self) -> np.ndarray | None:
        """The ids of the surfaces' vertices the proxy keeps (``ProxyFaces.vertices``), None until it is made."""
        return None if self._proxy is None else self._proxy[0].vertices

    @property
    def proxy_shown(self) -> bool:
        """Whether the last render drew the proxy's faces (the picture shown; until the still render)."""
        return self._drawn_proxy

    def set_mesh(self, mesh, face_counts=None, face_indices=None, points=None, arrays=None) -> None:
        """Draw ``mesh`` (a ``scene.rig_mesh`` of these polygons at ``points``, updated through ``arrays``, its
        ``scene.SurfaceArrays``) from now on; None: no surface (``set_meshes`` of one mesh)."""
        self.set_meshes([] if mesh is None else [(mesh, arrays)], face_counts, face_indices, points)

    def set_meshes(self, surfaces: list, face_counts=None, face_indices=None, points=None) -> None:
        """Draw ``surfaces``, (mesh, its ``scene.SurfaceArrays``) pairs of ``scene.rig_mesh`` of the same polygons
        over the same vertices (the Mocap Views' two), from now on; []: no surface. One proxy of those polygons
        (shaped as at ``points``) is made for them all on a worker thread when a render of them all is large
        enough (``wants_proxy``), of ``LOD_TARGET_TRIANGLES`` in all (the last meshes', if still being made, stops)."""
        self.show_full()
        self._timer.stop()
        _stop(self._running)
        self._generation += 1
        self._surfaces, self._proxy = list(surfaces), None
        if not surfaces or not wants_proxy(face_counts, copies=len(surfaces)):
            return
        generation = self._generation
        target = max(1, LOD_TARGET_TRIANGLES // len(surfaces))
        args = (np.array(points, dtype=np.float64), np.array(face_counts), np.array(face_indices))
        running: list = [None, None, threading.Event()]

        def on_filter(decimate) -> None:
            running[1] = decimate
            if running[2].is_set():     # stopped before the filter existed (``_stop``): it returns at once
                decimate.SetAbortExecute(1)

        def make() -> None:
            try:
                proxy = None if running[2].is_set() else proxy_faces(*args, target=target, on_filter=on_filter)
            except Exception:   # no proxy: everything is drawn in full, as before
                traceback.print_exc()
                proxy = None
            if not running[2].is_set():
                self._made.emit(generation, proxy)

        running[0] = threading.Thread(target=make, name="surface-proxy", daemon=True)
        self._running = running
        running[0].start()

    def _adopt(self, generation: int, proxy: ProxyFaces | None) -> None:
        if generation == self._generation and proxy is not None and self._surfaces:
            self._proxy = (proxy, [proxy.meshes() for _ in self._surfaces])

    def expects_proxy(self) -> bool:
        """Whether a render now would draw the proxy: the surface's own normals may then wait
        (``SurfaceArrays.update(defer_normals=True)``); the proxy computes its own."""
        return (self._proxy is not None and self._last is not None and not self.full_only and self._allowed()
                and time.monotonic() - self._last < STILL_AFTER_S)

    def show_full(self, normals: bool = True) -> None:
        """The surfaces drawn by their own meshes again from now on (no render), their normals brought up to date
        (``normals`` False: left for the next render that draws them in full, ``_on_start``; a pick needs only the
        faces, and a sculpt brush's dab picks at every mouse move: 47 ms of normals a move at 422k vertices)."""
        for _mesh, arrays in self._surfaces if normals else ():
            if arrays is not None:
                arrays.refresh_normals()
        if self._full is None:
            return
        swapped, self._full = self._full, None
        for mapper, dataset in swapped:
            mapper.SetInputData(dataset)

    def _show_proxy(self, window) -> None:
        """Each surface's proxy given its points and point data now; the actors drawing the surfaces (each one's
        front, and the backs of its two-sided parts: ``scene.add_surface``) made to draw their proxies."""
        proxy, meshes = self._proxy
        mine = {}
        for (mesh, arrays), (front, backs) in zip(self._surfaces, meshes):
            _gather(proxy, mesh, arrays, front, backs)
            mine[id(mesh)] = front
            if backs is not None and getattr(mesh, "_backs", None) is not None:
                mine[id(mesh._backs)] = backs
        if self._full is not None:
            return
        swapped = []
        renderers = window.GetRenderers()
        renderers.InitTraversal()
        for _ in range(renderers.GetNumberOfItems()):
            actors = renderers.GetNextItem().GetActors()
            actors.InitTraversal()
            for _ in range(actors.GetNumberOfItems()):
                mapper = actors.GetNextActor().GetMapper()
                drawn = mapper.GetInput() if mapper is not None else None
                if drawn is not None and id(drawn) in mine:
                    swapped.append((mapper, drawn))
                    mapper.SetInputData(mine[id(drawn)])
        self._full = swapped

    def _on_start(self, window, _event) -> None:
        now = time.monotonic()
        busy = self._last is not None and now - self._last < STILL_AFTER_S
        self._last = now
        self._drawn_proxy = busy and self._proxy is not None and not self._still_render and not self.full_only \
            and not self._releasing and self._allowed()
        if self._drawn_proxy:
            self._show_proxy(window)
            self._timer.start()
        else:
            self.show_full()

    def _when_still(self) -> None:
        # by what the last render drew, not by the actors' inputs: a pick since (a sculpt brush's hover off the face,
        # no render after it) puts the surface's own faces back without a render, and the proxy's picture stayed
        if not self._drawn_proxy:
            return
        self.show_full()            # a change VTK sees (now, or at the pick): the window renders
        #                             (``NativePlotter.render``)
        self._still_render = True
        try:
            self._render()
        finally:
            self._still_render = False

    def stop(self) -> None:
        """No surface any more (the view closes): a proxy being made is stopped and waited for (a thread left inside
        VTK as the process exits could crash it)."""
        self._timer.stop()
        self.show_full()
        self._generation += 1
        self._surfaces, self._proxy = [], None
        _stop(self._running)
        if self._running[0] is not None:
            self._running[0].join(timeout=5)


def _gather(proxy: ProxyFaces, mesh, arrays, front, backs) -> None:
    """The proxy's ``front`` (and ``backs``, sharing them) given ``mesh``'s points and point data (normals, colour-map
    scalars, part colours) at the proxy's vertices: each kept vertex drawn exactly as the mesh draws it. Normals that
    ``arrays`` (the mesh's ``scene.SurfaceArrays``) left for later are the proxy's own, from the faces around it."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
    kept = proxy.vertices
    points = vtk_to_numpy(mesh.GetPoints().GetData())
    front.GetPoints().SetData(numpy_to_vtk(points[kept], deep=True))
    source, target = mesh.GetPointData(), front.GetPointData()
    target.Initialize()
    stale = arrays is not None and arrays.normals_stale
    for i in range(source.GetNumberOfArrays()):
        array = source.GetAbstractArray(i)
        if array is None or array.GetNumberOfTuples() != mesh.GetNumberOfPoints():
            continue
        if stale and array is source.GetNormals():
            values = proxy.normals(points)      # the surface's own, not computed for this frame
        else:
            values = vtk_to_numpy(array)[kept]
        copy = numpy_to_vtk(values, deep=True, array_type=array.GetDataType())
        copy.SetName(array.GetName())
        target.AddArray(copy)
    if source.GetNormals() is not None:
        target.SetActiveNormals(source.GetNormals().GetName())
    if source.GetScalars() is not None:
        target.SetActiveScalars(source.GetScalars().GetName())
    if backs is not None:
        backs.GetPointData().ShallowCopy(target)


def _stop(running: list) -> None:
    """Stop the proxy being made by ``running`` ([thread, its decimation filter once made, its stop event]): the
    filter aborted if it runs, else it aborts as it is made, and the thread emits nothing. Before the filter exists
    (the surface's arrays still being copied: 0.4 s at 422k vertices) the flag alone stops it; aborting the filter
    alone missed that, and the stopped decimation then ran to its end (6 s at 422k: a window closed meanwhile waited
    5 s for it, a rig opened meanwhile had it beside its own)."""
    if running[2] is not None:
        running[2].set()
    if running[1] is not None:
        running[1].SetAbortExecute(1)


def _run_at_low_priority(fn: Callable[[], None]) -> None:
    """Run ``fn`` (a VTK filter's ``Update``, which releases the GIL) on a thread of the lowest scheduling priority
    (Linux: a thread's own nice value) and wait for it, so that making a proxy (6 s of a core at 422k vertices) slows
    neither the window nor the new rig's segmentation running beside it. Only the filter runs so: a thread that
    holds the GIL (the numpy around it) at that priority could keep the window waiting for the GIL while the
    scheduler runs the others, and a thread's priority cannot be raised back without privileges."""
    def low() -> None:
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
        except (AttributeError, OSError):   # not Linux: the process's priority
            pass
        fn()
    thread = threading.Thread(target=low, name="surface-proxy-decimation", daemon=True)
    thread.start()
    thread.join()
