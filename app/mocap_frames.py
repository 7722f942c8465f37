"""The per-frame display arrays of a solved take, for playback in the side-by-side views (ALGORITHMS.md §5):
the blendshape projection, the dense result with the RBF residual, the residual magnitude, the markers, and
both surfaces' shading normals, computed lazily or filled on a worker thread. No Qt here.
"""
from __future__ import annotations

import threading

import numpy as np

from model.rig import unit_scale
from model.takes import MarkerTake
from solvers.normals import VertexNormals


def captured_area_faces(rig, area: np.ndarray, shown: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The polygons whose corners all lie in ``area`` (the vertices the markers cover and the residual
    reaches), as counts + indices; all polygons when the area is empty. The side-by-side views draw only
    these: that is where a capture says anything, and half the geometry renders twice as fast. ``shown``: the
    faces View ▸ Parts shows (``model.parts.shown_faces``; None: all), the only ones kept."""
    keep = np.ones(len(rig.face_counts), bool)
    if shown is not None:
        keep[:] = False
        keep[shown] = True
    if area is not None and len(area):
        inside = np.zeros(rig.n_vertices, bool)
        inside[area] = True
        starts = np.concatenate(([0], np.cumsum(rig.face_counts)[:-1]))
        in_area = keep & np.logical_and.reduceat(inside[rig.face_indices], starts)
        if in_area.any():
            keep = in_area
    if keep.all() or not keep.any():
        return rig.face_counts, rig.face_indices
    return rig.face_counts[keep], rig.face_indices[np.repeat(keep, rig.face_counts)]


class FrameCache:
    """Per-frame display arrays of a solved take, computed lazily (or all at once in the background) and kept:
    projection and dense surfaces (F, V, 3) float32, residual magnitude (F, V) float32 in mm, and the
    head-stabilised take markers and the rig's fitted markers (F, M, 3) in rig space. Given ``normals`` (the
    views' VertexNormals over the ``shown`` vertices, see ``compact_faces``), also both surfaces' shading
    normals at those vertices (F, len(shown), 3) int8, so that playback of a filled cache draws without
    computing any (two normals are ~6 ms of a ~35 ms frame on ICT FaceKit)."""

    def __init__(self, solution, take: MarkerTake, rig_units: str, normals: VertexNormals | None = None,
                 shown: np.ndarray | None = None) -> None:
        self.solution = solution
        s = solution.solver
        F, V = solution.n_frames, s.V
        self.projection = np.zeros((F, V, 3), np.float32)
        self.dense = np.zeros((F, V, 3), np.float32)
        self.residual_mm = np.zeros((F, V), np.float32)
        self._normals = normals
        self._shown = np.arange(V) if shown is None else np.asarray(shown)
        if normals is not None:
            if normals.n_points != len(self._shown):
                raise ValueError(f"normals for {normals.n_points} points, but {len(self._shown)} shown vertices")
            self.projection_normals = np.zeros((F, len(self._shown), 3), np.int8)
            self.dense_normals = np.zeros((F, len(self._shown), 3), np.int8)
        self.ready = np.zeros(F, dtype=bool)
        self.mm = unit_scale(rig_units, "mm")
        cols = [take.labels.index(label) for label in solution.labels]
        m = take.positions[:, cols]                                       # take units, NaN where missing
        inv = np.linalg.inv(solution.head)                                # take space -> rig space
        self.markers = np.einsum("fij,fmj->fmi", inv[:, :3, :3], m) + inv[:, None, :3, 3]
        if solution.markers_rig is not None:   # an actor's markers carried onto the rig (ALGORITHMS.md §12)
            self.markers = np.where(np.isfinite(self.markers), solution.markers_rig, np.nan)
        if solution.region_weights is not None:
            self.fitted = np.stack([s.markers_regional(solution.region_weights[f]) for f in range(F)])
        else:
            self.fitted = np.stack([s.markers_at(solution.weights[f]) for f in range(F)])
        self._lock = threading.Lock()

    @property
    def n_frames(self) -> int:
        return self.ready.size

    def frame(self, f: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(projection, dense, residual mm) of frame f, computing it on first use."""
        if not self.ready[f]:
            self._compute(f)
        return self.projection[f], self.dense[f], self.residual_mm[f]

    def normals(self, f: int) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
        """(projection, dense) int8 shading normals of frame f, or (None, None) without a normals function."""
        if self._normals is None:
            return None, None
        if not self.ready[f]:
            self._compute(f)
        return self.projection_normals[f], self.dense_normals[f]

    def _compute(self, f: int) -> None:
        sol = self.solution
        proj = sol.projection(f)
        dense = sol.dense(f, proj)
        res = np.linalg.norm(dense - proj, axis=1) * self.mm
        if self._normals is not None:
            shown = self._shown
            proj_n, dense_n = self._normals.quantised(proj[shown]), self._normals.quantised(dense[shown])
        with self._lock:
            self.projection[f], self.dense[f], self.residual_mm[f] = proj, dense, res
            if self._normals is not None:
                self.projection_normals[f], self.dense_normals[f] = proj_n, dense_n
            self.ready[f] = True

    def fill(self, stop: threading.Event | None = None) -> None:
        """Compute every frame not computed yet (runs on a worker thread after a solve)."""
        for f in range(self.n_frames):
            if stop is not None and stop.is_set():
                return
            if not self.ready[f]:
                self._compute(f)
