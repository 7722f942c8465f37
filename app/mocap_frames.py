"""The per-frame display arrays of a solved take, for playback in the side-by-side views (ALGORITHMS.md §5):
the blendshape projection, the dense result with the RBF residual, the residual magnitude, the markers, and
both surfaces' shading normals at the vertices the views draw, filled on a worker thread that follows the
playhead; the window shows the nearest filled frame meanwhile, never computing one itself. No Qt here.
"""
from __future__ import annotations

import threading
import time
from typing import Callable

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


def frames_to_fill(ready: np.ndarray, playhead: int, block: int) -> list[int]:
    """The frames to compute next, following the playhead: the first frame not ready at or after ``playhead``
    (wrapping round to the start), and the frames not ready right after it, ``block`` at most, not wrapping (one
    matrix product). Empty when every frame is ready. The frame shown comes first: it is the one the user waits
    for, and playback moves forward from it."""
    n = ready.size
    if n == 0:
        return []
    p = min(max(int(playhead), 0), n - 1)
    todo = np.flatnonzero(~ready)
    if todo.size == 0:
        return []
    after = todo[todo >= p]
    first = int(after[0] if after.size else todo[0])
    stop = min(n, first + max(1, int(block)))
    ahead = np.flatnonzero(ready[first:stop])
    return list(range(first, first + int(ahead[0]) if ahead.size else stop))


def nearest_ready(ready: np.ndarray, frame: int) -> int | None:
    """The ready frame nearest ``frame`` (the earlier one of two as near), or None when none is: what the views
    show while ``frame`` is being computed, rather than block the window for it."""
    done = np.flatnonzero(ready)
    if done.size == 0:
        return None
    return int(done[np.argmin(np.abs(done - int(frame)))])


class FrameCache:
    """Per-frame display arrays of a solved take at the vertices the views draw (``shown``: the captured area's,
    about half a studio rig's; all without it), computed on a worker thread that follows the playhead (``fill``,
    ``playhead``) and kept: projection and dense surfaces (F, S, 3) float32, residual magnitude (F, S) float32 in
    mm, and the head-stabilised take markers and the rig's fitted markers (F, M, 3) in rig space. Given ``normals``
    (the views' VertexNormals over the ``shown`` vertices, see ``compact_faces``), also both surfaces' shading
    normals there (F, S, 3) int8, so that playback of a filled cache draws without computing any (two normals are
    ~6 ms of a ~35 ms frame on ICT FaceKit). Only the shown vertices: the whole rig's (F, V, 3) twice was ~3.6 GB on
    the 422k-vertex rig, and a frame of it 0.2-1.1 s; exports take the whole surface from the solution itself."""

    BLOCK = 4   # frames a fill step computes as one matrix product (106k vertices: ~8 ms a frame, ~25 ms alone)

    def __init__(self, solution, take: MarkerTake, rig_units: str, normals: VertexNormals | None = None,
                 shown: np.ndarray | None = None) -> None:
        self.solution = solution
        s = solution.solver
        F, V = solution.n_frames, s.V
        self._shown = np.arange(V) if shown is None else np.asarray(shown)
        S = len(self._shown)
        self.projection = np.zeros((F, S, 3), np.float32)
        self.dense = np.zeros((F, S, 3), np.float32)
        self.residual_mm = np.zeros((F, S), np.float32)
        self._normals = normals
        if normals is not None:
            if normals.n_points != S:
                raise ValueError(f"normals for {normals.n_points} points, but {S} shown vertices")
            self.projection_normals = np.zeros((F, S, 3), np.int8)
            self.dense_normals = np.zeros((F, S, 3), np.int8)
        # the residual's vertices that are shown: their rows in the RBF's output and their places among the shown
        at = np.full(V, -1, np.int64)
        at[self._shown] = np.arange(S)
        at = at[s.residual_vertices] if s.residual_vertices is not None else np.zeros(0, np.int64)
        self._residual_rows = np.flatnonzero(at >= 0)
        self._residual_at = at[self._residual_rows]
        self.ready = np.zeros(F, dtype=bool)
        self.playhead = 0   # the frame the views want (set on the GUI thread): the fill works from it on
        self.speed = 0.0    # frames a second the playhead moves (playing; set on the GUI thread), 0 when still
        self._block_seconds = 0.0   # how long the fill's last block took
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
        self._filled = threading.Condition(self._lock)   # notified as frames become ready

    @property
    def n_frames(self) -> int:
        return self.ready.size

    @property
    def shown(self) -> np.ndarray:
        """The rig vertices the arrays hold, in their order."""
        return self._shown

    def is_ready(self, f: int) -> bool:
        return bool(self.ready[f])

    def wait_ready(self, f: int, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for the fill to make frame f ready, computing nothing; whether it is."""
        with self._filled:
            return bool(self._filled.wait_for(lambda: self.ready[f], timeout))

    def nearest_ready(self, f: int) -> int | None:
        """The computed frame nearest ``f`` (``nearest_ready``), or None."""
        return nearest_ready(self.ready, f)

    def frame(self, f: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(projection, dense, residual mm) of frame f at the shown vertices, computed here if not yet (on the
        caller's thread: the window asks only for frames that are ready)."""
        if not self.ready[f]:
            self._compute([f], batched=False)
        return self.projection[f], self.dense[f], self.residual_mm[f]

    def normals(self, f: int) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
        """(projection, dense) int8 shading normals of frame f, or (None, None) without a normals function."""
        if self._normals is None:
            return None, None
        if not self.ready[f]:
            self._compute([f], batched=False)
        return self.projection_normals[f], self.dense_normals[f]

    def residual_lengths(self, f: int) -> np.ndarray:
        """(N,) the residual's length in mm at every vertex it reaches for frame f (shown or not: a colour range
        sampled from them stays the take's whatever View ▸ Parts shows), from the RBF alone, no surface."""
        sol, s = self.solution, self.solution.solver
        if sol.coefficients is None or s.rbf is None:
            return np.zeros(0)
        return np.linalg.norm(s.rbf.evaluate(sol.coefficients[f]), axis=1) * self.mm

    def warm(self) -> None:
        """Make the batch evaluator's copy of the deltas now (~1 s on the 106k rig; on the solve's thread), not in
        the fill's first block while the take plays: the window's longest freeze then was ~0.2 s, ~0.12 s without."""
        sol, s = self.solution, self.solution.solver
        if s.surface_many is not None and sol.region_weights is None and self.n_frames:
            s.surface_many(sol.weights[:1])

    def _surfaces(self, frames: list[int], batched: bool) -> np.ndarray:
        """(n, S, 3) float32 projections of ``frames`` at the shown vertices: one matrix product (``batched``, a global
        solve: the solver's batch evaluator, as the exports use; its copy of the deltas made by ``warm``), else the pose
        frame by frame."""
        sol, s = self.solution, self.solution.solver
        if batched and s.surface_many is not None and sol.region_weights is None:
            return s.surface_many(sol.weights[frames])[:, self._shown]
        return np.stack([sol.projection(f)[self._shown] for f in frames]).astype(np.float32)

    def _compute(self, frames: list[int], batched: bool = True) -> None:
        sol, s = self.solution, self.solution.solver
        proj = self._surfaces(frames, batched)
        dense = proj.copy()
        if sol.coefficients is not None and s.rbf is not None and self._residual_rows.size:
            for i, f in enumerate(frames):
                dense[i, self._residual_at] += s.rbf.evaluate(sol.coefficients[f])[self._residual_rows]
        res = np.linalg.norm(dense - proj, axis=2) * self.mm
        if self._normals is not None:
            proj_n = [self._normals.quantised(p) for p in proj]
            dense_n = [self._normals.quantised(d) for d in dense]
        with self._lock:
            self.projection[frames], self.dense[frames], self.residual_mm[frames] = proj, dense, res
            if self._normals is not None:
                self.projection_normals[frames], self.dense_normals[frames] = proj_n, dense_n
            self.ready[frames] = True
            self._filled.notify_all()

    def fill_start(self) -> int:
        """Where the next block starts: the playhead, or while it moves, where it will be once the block is computed
        (a fill slower than playback would otherwise always compute frames the playhead has just left)."""
        ahead = int(np.ceil(self.speed * self._block_seconds))
        return (self.playhead + ahead) % self.n_frames if ahead else self.playhead

    def fill(self, stop: threading.Event | None = None, filled: Callable[[list[int]], None] | None = None) -> None:
        """Compute every frame not computed yet (on a worker thread after a solve), in blocks that follow the
        playhead (``frames_to_fill``): the frame the views wait for first, then the frames playback reaches next.
        ``filled(frames)`` is called after each block (the window shows a frame it was waiting for)."""
        while stop is None or not stop.is_set():
            frames = frames_to_fill(self.ready, self.fill_start(), self.BLOCK)
            if not frames:
                return
            t0 = time.perf_counter()
            self._compute(frames)
            self._block_seconds = time.perf_counter() - t0
            if filled is not None:
                filled(frames)
