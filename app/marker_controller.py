"""Drag markers to solve keyframes, coarse to fine, region by region (Joshi et al. 2003, §4; ALGORITHMS.md
§4 and §8).

In marker mode (View ▸ Marker Mode, M) a click on the surface adds a marker (a vertex, or a face point with
barycentric weights), a right-click on a marker removes it, and dragging a marker moves its target in the
plane through the marker facing the camera, damped by the motion-damping gain at that point
(``solvers.damping``); the other markers stay pinned where they are. Each mouse move re-solves the regions of
the hierarchy level chosen in the Markers panel (``solvers.regional_solve.RegionalSolver``, λ_r toward the
pose at the press) and shows the regional pose (``PoseEvaluator.evaluate_regional``). The solver is built
once per press (it depends on the markers and the level); one drag is one undo step.
"""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor, wait as wait_for
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from PySide6 import QtCore, QtWidgets

from app.document import PoseState
from app.marker_commands import SetMarkersCommand, SetPoseCommand
from model.correctives import solver_correctives
from model.errors import RigInputError
from model.antagonists import pair_indices
from model.markers import DRAG_LAM_REG, Marker, MarkerSet, in_view_plane
from model.wording import count
from solvers.correctives import linearised_correctives
from solvers.damping import damping_gains
from solvers.mesh import extent
from solvers.regional_solve import RegionalSolver, shape_region_max
from widgets.marker_overlay import MarkerOverlay
from widgets.markers_panel import MarkersPanel
from widgets.shapes_panel import PoseEdit
from widgets.viewport import Gesture, ViewportTool

SECTION = "markers"
PICK_RADIUS_PX = 12.0       # a press this close (logical pixels) to a marker grabs it
MIN_SPACING = 0.002         # markers closer than this fraction of the face size are refused


@dataclass
class DragState:
    """Everything one drag needs, set up at the press (the solver depends on the markers and the level)."""

    index: int
    old: PoseState
    level: int | None
    blend: sp.csr_matrix | None
    W0: np.ndarray                 # (R+1, K) regional pose at the press (the λ_r reference)
    solver: RegionalSolver
    neutral_at: np.ndarray         # (M, 3) markers on the neutral
    start: np.ndarray              # (M, 3) markers on the surface at the press (the pins)
    targets: np.ndarray            # (M, 3) current targets
    gain: float                    # damping gain of the dragged marker
    moved: bool = False
    W: np.ndarray | None = None    # (R+1, K) pose after the last move
    correctives: tuple | None = None   # the rig's live correctives: (activate, marker displacements (C, 3M), drivers)
    forward: np.ndarray | None = None  # the camera's view direction at the press: the dragged marker's free depth


@dataclass
class HeldPress:
    """A press on a marker that came before what a drag of the level needs was ready (``MarkerController.held``:
    found ahead on the worker thread when Marker Mode or a level was chosen; ~0.7 s on the 106k-vertex, 228-shape
    studio rig). The window keeps running; the mouse's latest ``motion`` and whether the button is already
    ``released`` are played into the drag when the work arrives (``MarkerController._start_held_press``)."""

    index: int
    jobs: list = field(default_factory=list)   # the Futures it waits for (``MarkerController._when_done``)
    motion: np.ndarray | None = None
    released: bool = False


HOLD_AFTER_S = 0.1          # a press waits this long for the level's set-up found ahead, then is held (HeldPress)
DRAG_CORRECTIVE_STEPS = 4   # Gauss–Newton solves a move at most, on a rig with correctives (~2 ms each on ICT)


def same_blend(a: sp.spmatrix | None, b: sp.spmatrix | None) -> bool:
    """Whether two partitions of unity are the same (the same object, or equal shape and entries)."""
    if a is b:
        return True
    if a is None or b is None or a.shape != b.shape or a.nnz != b.nnz:
        return False
    return (sp.csr_matrix(a) != sp.csr_matrix(b)).nnz == 0


def pose_at_level(state: PoseState, blend: sp.csr_matrix | None) -> np.ndarray:
    """(R+1, K) per-region weights for ``blend`` (V, R+1) that reproduce ``state`` as well as a regional pose
    of that level can: a global pose is the same vector in every region; a regional pose of another level is
    averaged per region with the new level's blend weights, ``W_r = Σ_v φ_r(v) w(v) / Σ_v φ_r(v)``."""
    if blend is None:
        return np.asarray(state.weights, dtype=np.float64)[None].copy()
    R1 = blend.shape[1]
    if state.region_weights is None:
        return np.tile(np.asarray(state.weights, dtype=np.float64), (R1, 1))
    if same_blend(state.blend, blend):
        return np.array(state.region_weights, dtype=np.float64)
    per_vertex = np.asarray(state.blend @ state.region_weights)            # (V, K)
    B = sp.csc_matrix(blend)
    mass = np.asarray(B.sum(axis=0)).reshape(-1)
    W = np.asarray(B.T @ per_vertex) / np.maximum(mass, 1e-12)[:, None]
    return np.clip(W, 0.0, 1.0)


class MarkerTool(ViewportTool):
    """Marker mode on the viewport: a press on a marker drags it (left button; its target moves in the view
    plane through it) or removes it (right button). A click elsewhere adds one (``MarkerController._on_picked``)."""

    def __init__(self, controller: "MarkerController") -> None:
        self.controller = controller

    def press(self, g: Gesture) -> bool:
        c = self.controller
        if c.document.project is None or c.drag is not None or c.held is not None:
            return False
        i = c.marker_at(g.x, g.y)
        if i is None:
            return False
        if g.button == QtCore.Qt.RightButton:
            c.remove_marker(c.markers.names[i])
            return True
        if g.button != QtCore.Qt.LeftButton:
            return False
        if i in [c.markers.index(n) for n in c.markers.background]:
            c.message(f"Marker {c.markers.names[i]} is on the background: no shape can move it.")
        jobs = c.unfinished_jobs()
        if jobs:           # the drag starts when they are done; the window runs meanwhile
            c.hold_press(i, jobs)
            g.anchor = c.marker_positions()[i]
        else:
            g.anchor = c.begin_drag(i).start[i]
        c.panel.select_marker(i)
        return True

    def drag(self, g: Gesture) -> None:
        c = self.controller
        if c.drag is not None:
            c.drag_by(g.motion)   # the window redraws once per event-loop turn (coalesced)
        elif c.held is not None:
            c.held.motion = g.motion

    def release(self, g: Gesture) -> None:
        c = self.controller
        if c.held is not None:
            c.held.released = True
        else:
            c.end_drag()


class MarkerController(QtCore.QObject):
    """Markers, marker mode and drags; owns the Markers panel (``panel``, in ``dock``), the Marker Mode action
    (``mode_action``, View menu, M), the viewport glyphs and, in marker mode, the viewport tool (``tool``)."""

    markers_changed = QtCore.Signal()
    drag_updated = QtCore.Signal()
    _jobs_done = QtCore.Signal()       # from the worker thread: a job a held press waits for is done

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window = window
        self.document, self.viewport = window.document, window.viewport
        self._antagonist_cache: tuple | None = None   # (rig version, the project's pairs, their shape indices)
        self.panel = panel = MarkersPanel(window)
        self.dock = window.add_dock("Markers", panel, QtCore.Qt.LeftDockWidgetArea, scroll=True)
        self.mode_action = window.add_action(
            "view", "&Marker Mode", self.set_mode, "M",
            "Marker mode: click the face to add a marker, drag a marker to pose the face region by region "
            "(damped where the face barely moves), right-click a marker to remove it", checkable=True)
        panel.mode_toggled.connect(self.mode_action.setChecked)
        self.overlay = MarkerOverlay(self.viewport)
        self.tool = MarkerTool(self)
        self.markers: MarkerSet | None = None
        self.mode = False
        self.lam_reg = DRAG_LAM_REG      # cm², whatever the rig's units (MarkerSet.drag_solver converts it)
        self.drag: DragState | None = None
        self.held: HeldPress | None = None
        self._jobs_done.connect(self._start_held_press, QtCore.Qt.QueuedConnection)
        self.last_message = ""
        self._gains: np.ndarray | None = None
        self._region_max: dict[int, tuple] = {}   # id(blend) -> (blend, (R, K) array or its Future)
        self._warmer: ThreadPoolExecutor | None = None
        self._parts_ahead: tuple | None = None    # (display evaluator, blend, Future of its ``blend_parts``)
        self._tri_of_vertex: sp.csr_matrix | None = None
        self._triangles: np.ndarray | None = None
        self._slider_old: PoseState | None = None
        self._selected: int | None = None
        d = self.document
        d.rig_changed.connect(self._on_rig_change)
        d.shapes_changed.connect(self._on_shapes_change)
        d.section_changed.connect(self._on_section_change)
        d.pose_changed.connect(self._on_pose_change)
        self.viewport.picked.connect(self._on_picked)
        seg = window.segmentation
        seg.segmentation_ready.connect(self._on_segmentation_ready)
        sp_panel = window.segmentation_panel
        sp_panel.region_selected.connect(lambda _r: self.sync_edit_region())
        sp_panel.level_changed.connect(lambda _l: self.sync_edit_region())
        self.viewport.picked.connect(lambda *_: self.sync_edit_region())
        panel.level_changed.connect(self._on_level_change)
        panel.remove_requested.connect(self.remove_marker)
        panel.marker_selected.connect(self._on_marker_selected)
        panel.lam_reg_changed.connect(self._on_lam_reg_change)
        if d.project is not None:
            self._on_rig_change()
            if seg.segmentation is not None:
                self._on_segmentation_ready()

    # --- state --------------------------------------------------------------------------------------
    @property
    def level(self) -> int | None:
        """The hierarchy level drags solve (None: no segmentation yet, a global solve)."""
        return self.panel.current_level()

    def _level_obj(self, level: int | None):
        seg = self.window.segmentation.segmentation
        if seg is None or level is None or not 0 <= level < len(seg.levels):
            return None
        return seg.levels[level]

    def set_mode(self, on: bool) -> None:
        self.mode = bool(on)
        self.panel.set_mode(self.mode)
        if self.mode:
            self.viewport.push_tool(self.tool)
        else:
            self.viewport.remove_tool(self.tool)
            if self.drag is not None:   # leaving marker mode mid-drag (M with the button held) ends the drag
                self.end_drag()
            self._drop_held_press()
        if self.mode:
            self.message("Marker mode: click the face to add a marker, drag a marker to pose, right-click removes.")
            self._warm_region_max()
        self.refresh_overlay(render=True)

    def message(self, text: str, timeout: int = 8000) -> None:
        self.last_message = text
        self.window.show_status(text, timeout)
        self.panel.set_status(text)

    def _on_rig_change(self) -> None:
        rig = self.document.rig
        self._gains = None            # made on a drag's first use (``gains``): on a studio rig they cost a pass over
        self._tri_of_vertex = None    # the shapes, and the triangles around each vertex only a click needs
        self._region_max.clear()
        self._triangles = self.document.triangles()
        self._face_size = extent(rig.neutral)
        self.drag = None
        self._drop_held_press()
        self._load_markers()

    def _on_shapes_change(self) -> None:
        """Shapes edited, same topology: the damping gains and the markers' shape rows change, the triangles stay."""
        self._gains = None
        self._region_max.clear()
        self.drag = None
        self._drop_held_press()
        self._load_markers()

    @property
    def gains(self) -> np.ndarray:
        """(V,) the drag's damping gain at each vertex (Joshi et al. 2003, §4: ``solvers.damping``), from the
        shapes' reach; made on first use after each rig or shape change."""
        if self._gains is None:
            rig = self.document.rig
            self._gains = damping_gains(self.document.shape_reach()) if rig.n_shapes else np.zeros(rig.n_vertices)
        return self._gains

    def _triangles_of(self, vertex: int) -> np.ndarray:
        """The triangles (indices into ``rig.triangles()``) around ``vertex``; their incidence made on first use."""
        if self._tri_of_vertex is None:
            T = self._triangles
            self._tri_of_vertex = sp.csr_matrix((np.ones(T.size), (T.reshape(-1), np.repeat(np.arange(len(T)), 3))),
                                                shape=(self.document.rig.n_vertices, len(T)))
        return self._tri_of_vertex[vertex].indices

    def _load_markers(self) -> None:
        data = self.document.section(SECTION)
        self.markers = None
        # the rig's triangles and moving vertices, known here already (on a studio rig each is a pass over it)
        known = dict(triangles=self._triangles, moving=np.flatnonzero(self.document.shape_reach() > 0))
        if data:
            try:
                self.markers = MarkerSet.from_dict(data, self.document.rig, source="project", **known)
            except RigInputError as exc:
                self.message(f"The project's markers were not loaded: {exc}")
        if self.markers is None:
            self.markers = MarkerSet.for_rig(self.document.rig, [], **known)
        if self._selected is not None and self._selected >= len(self.markers):
            self._selected = None
        self.panel.set_markers(self.markers.names, self.markers.background)
        self.markers_changed.emit()
        self.refresh_overlay(render=True)

    def _on_section_change(self, name: str) -> None:
        if name == SECTION:
            self._load_markers()

    def _on_segmentation_ready(self) -> None:
        seg = self.window.segmentation.segmentation
        counts = [] if seg is None else [lvl.n_regions for lvl in seg.levels]
        self.panel.set_levels(counts)
        self._region_max.clear()
        self.sync_edit_region()
        self._warm_region_max()

    def _on_level_change(self, level: int) -> None:
        self.message(f"Drags solve the {count(self._level_obj(level).n_regions, 'region')} of level {level}."
                     if self._level_obj(level) is not None else "Drags solve one global pose.", 4000)
        self._warm_region_max()

    def _on_lam_reg_change(self, value: float) -> None:
        self.lam_reg = float(value)

    @property
    def selected_marker(self) -> int | None:
        """The index of the marker selected in the Markers panel or by a drag, or None."""
        return self._selected

    def _on_marker_selected(self, index: int) -> None:
        self._selected = index if index >= 0 else None
        self.refresh_overlay(render=True)

    # --- glyphs ---------------------------------------------------------------------------------------
    def marker_positions(self) -> np.ndarray:
        """(M, 3) markers on the surface shown."""
        if self.markers is None or not len(self.markers):
            return np.zeros((0, 3))
        return self.markers.positions(self.document.surface().astype(np.float64))

    def refresh_overlay(self, render: bool = False) -> None:
        if self.document.project is None or self.markers is None:
            return
        visible = self.mode or self.drag is not None
        if not visible or not len(self.markers):
            self.overlay.show(np.zeros((0, 3)))
        else:
            targets = self.drag.targets if self.drag is not None else None
            self.overlay.show(self.marker_positions(), targets, self._selected)
        if render:  # coalesced with the window's pose redraws: one render per event-loop turn
            self.window.request_render()

    def _on_pose_change(self) -> None:
        self.refresh_overlay()  # the window's scheduled redraw renders
        self.sync_edit_region()

    # --- markers --------------------------------------------------------------------------------------
    def _next_name(self) -> str:
        used = set(self.markers.names)
        i = len(used)
        while f"M{i:02d}" in used:
            i += 1
        return f"M{i:02d}"

    def marker_for_point(self, vertex: int, point, name: str) -> Marker:
        """A marker at a picked surface point: the face point of a triangle around ``vertex`` holding it
        (barycentric), or the vertex itself when the point is on it."""
        X = self.document.surface().astype(np.float64)
        p = np.asarray(point, dtype=np.float64)
        tris = self._triangles_of(vertex)
        best, best_bary, best_score = None, None, -np.inf
        for t in tris:
            a, b, c = X[self._triangles[t]]
            v0, v1, v2 = b - a, c - a, p - a
            d00, d01, d11, d20, d21 = v0 @ v0, v0 @ v1, v1 @ v1, v2 @ v0, v2 @ v1
            den = d00 * d11 - d01 * d01
            if den <= 1e-18:
                continue
            l1 = (d11 * d20 - d01 * d21) / den
            l2 = (d00 * d21 - d01 * d20) / den
            bary = np.array([1.0 - l1 - l2, l1, l2])
            score = bary.min()
            if score > best_score:
                best, best_bary, best_score = int(t), bary, score
        if best is None or best_score < -0.05:
            return Marker(name, vertex=int(vertex))
        bary = np.clip(best_bary, 0.0, None)
        bary /= bary.sum()
        if bary.max() > 0.995:
            return Marker(name, vertex=int(self._triangles[best][int(np.argmax(bary))]))
        return Marker(name, face=best, bary=tuple(bary))

    def add_marker_at(self, vertex: int, point=None, name: str | None = None) -> bool:
        """Add a marker at a picked point (one undo step). Duplicates are refused with a message; a marker
        on the background (no shape moves it) is allowed with a warning."""
        if self.document.project is None:
            return False
        name = name or self._next_name()
        try:
            marker = Marker(name, vertex=int(vertex)) if point is None else self.marker_for_point(vertex, point, name)
            new = self.markers.with_marker(marker)
        except RigInputError as exc:
            self.message(f"Marker not added: {exc}")
            return False
        X = self.document.surface().astype(np.float64)
        if len(self.markers):
            P = new.positions(X)
            dist = np.linalg.norm(P[:-1] - P[-1], axis=1)
            j = int(np.argmin(dist))
            if dist[j] < MIN_SPACING * self._face_size:
                self.message(f"Marker not added: it would sit on marker {self.markers.names[j]} "
                             f"({dist[j]:.3g} {self.document.rig.units} away); drag that one instead.")
                return False
        old = self.document.section(SECTION)
        self.document.undo_stack.push(SetMarkersCommand(self.document, old, new.to_dict(), f"Add marker {name}"))
        if name in new.background:
            self.message(f"Marker {name} is on the background: no shape moves the surface there, so it stays "
                         f"pinned and cannot be dragged.")
        else:
            rig = self.document.rig   # in the user's words: where on the face, not a triangle's index
            moves = np.linalg.norm(rig.deltas[:, int(vertex)], axis=1) if rig.n_shapes else np.zeros(0)
            most = f", moved most by {rig.shape_names[int(np.argmax(moves))]}" if moves.size and moves.max() > 0 else ""
            self.message(f"Added marker {name} on the face{most}.", 4000)
        return True

    def remove_marker(self, name: str) -> bool:
        if self.markers is None or name not in self.markers.names:
            return False
        old = self.document.section(SECTION)
        new = self.markers.without(name)
        self.document.undo_stack.push(SetMarkersCommand(self.document, old, new.to_dict(), f"Remove marker {name}"))
        self.message(f"Removed marker {name}.", 4000)
        return True

    def _on_picked(self, vertex: int, point) -> None:
        if self.mode and self.drag is None and self.held is None:
            self.add_marker_at(vertex, point)

    def marker_at(self, x: float, y: float) -> int | None:
        """The marker nearest display pixel (x, y) within the grab radius, or None."""
        if self.markers is None or not len(self.markers):
            return None
        d = self.viewport.world_to_display(self.marker_positions())
        dist = np.hypot(d[:, 0] - x, d[:, 1] - y)
        i = int(np.argmin(dist))
        return i if dist[i] <= PICK_RADIUS_PX * self.viewport.pixel_ratio() else None

    # --- dragging -------------------------------------------------------------------------------------
    def _region_max_for(self, lvl) -> np.ndarray:
        key = id(lvl.blend)
        hit = self._region_max.get(key)
        if hit is None or hit[0] is not lvl.blend:
            hit = (lvl.blend, shape_region_max(self.document.rig.deltas, [r.vertices for r in lvl.regions]))
            self._region_max[key] = hit
        if isinstance(hit[1], Future):      # found ahead by ``_warm_region_max``: done, or soon
            hit = self._region_max[key] = (hit[0], hit[1].result())
        return hit[1]

    def _warm_region_max(self) -> None:
        """While marker mode is on, find the chosen level's shapes per region (``shape_region_max``: 15 ms on ICT,
        0.2 s on the 106k-vertex, 228-shape studio rig, a pass over every shape's deltas), the project's antagonist
        pairs (0.3 s on that rig) and the display evaluator's set-up of the level's regional poses (0.1-0.4 s there)
        on a worker thread, so that the first press on a marker does not: it froze the window 0.23 s on ICT and
        2-5 s on that rig. A shape edit or a new rig drops them with the caches (a new evaluator: not adopted)."""
        lvl = self._level_obj(self.level)
        if not self.mode or lvl is None:
            return
        if self._warmer is None:
            self._warmer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="marker-regions")
        if id(lvl.blend) not in self._region_max:
            job = self._warmer.submit(shape_region_max, self.document.rig.deltas, [r.vertices for r in lvl.regions])
            self._region_max[id(lvl.blend)] = (lvl.blend, job)
        if self._antagonist_key() != (self._antagonist_cache or ())[:2]:
            rig, pairs = self.document.rig, self.document.project.antagonist_pairs
            self._antagonist_cache = (*self._antagonist_key(), self._warmer.submit(lambda: pair_indices(rig, pairs())))
        ev, ahead = self.document.evaluator, self._parts_ahead
        fresh = ahead is None or ahead[0] is not ev or ahead[1] is not lvl.blend
        if ev is not None and fresh and not ev.live().any():   # live correctives: a level is posed per vertex
            self._parts_ahead = (ev, lvl.blend, self._warmer.submit(ev.blend_parts, lvl.blend))

    def _adopt_parts_ahead(self, blend) -> None:
        """Give the display evaluator the regional set-up of ``blend`` made ahead (``_warm_region_max``), waiting
        for it if it is not done yet, before the press's first regional pose would make it on this thread."""
        ahead, self._parts_ahead = self._parts_ahead, None
        if ahead is not None and ahead[0] is self.document.evaluator and ahead[1] is blend:
            ahead[0].adopt_blend_parts(blend, ahead[2].result())

    def unfinished_jobs(self, patience: float = HOLD_AFTER_S) -> list[Future]:
        """What a press at the chosen level would wait for from ``_warm_region_max``: its Futures not done after
        ``patience`` seconds (on ICT they are done within it, and the drag starts at the press)."""
        lvl = self._level_obj(self.level)
        if lvl is None:
            return []
        region_max, pairs, ahead = self._region_max.get(id(lvl.blend)), self._antagonist_cache, self._parts_ahead
        jobs = []
        if region_max is not None and region_max[0] is lvl.blend:
            jobs.append(region_max[1])
        if pairs is not None and pairs[:2] == self._antagonist_key():
            jobs.append(pairs[2])
        if ahead is not None and ahead[0] is self.document.evaluator and ahead[1] is lvl.blend:
            jobs.append(ahead[2])
        jobs = [job for job in jobs if isinstance(job, Future)]
        return list(wait_for(jobs, timeout=patience).not_done) if jobs else []

    def hold_press(self, index: int, jobs: list[Future]) -> None:
        """A press on marker ``index`` before ``jobs`` are done: the drag begins when they are, with where the mouse
        has gone by then (``HeldPress``), so that the window never waits for them."""
        self.held = HeldPress(index)
        QtWidgets.QApplication.setOverrideCursor(QtCore.Qt.BusyCursor)
        self.message(f"Getting level {self.level}'s regions ready for the drag…", 4000)
        self._when_done(jobs)

    def _when_done(self, jobs: list[Future]) -> None:
        self.held.jobs = jobs
        for job in jobs:
            job.add_done_callback(self._emit_jobs_done)

    def _emit_jobs_done(self, _job: Future) -> None:
        try:
            self._jobs_done.emit()      # queued: ``_start_held_press`` runs on the GUI thread
        except RuntimeError:            # the window has gone meanwhile
            pass

    def _start_held_press(self) -> None:
        held = self.held
        if held is None or not all(job.done() for job in held.jobs):
            return
        more = self.unfinished_jobs(patience=0.0)     # another level chosen meanwhile: its set-up too
        if more:
            self._when_done(more)
            return
        self._drop_held_press()
        if not self.mode or self.markers is None or held.index >= len(self.markers):
            return
        self.begin_drag(held.index)
        if held.motion is not None:
            self.drag_by(held.motion)
        if held.released:
            self.end_drag()

    def _drop_held_press(self) -> None:
        if self.held is not None:
            self.held = None
            QtWidgets.QApplication.restoreOverrideCursor()

    def _antagonist_key(self) -> tuple:
        project = self.document.project
        return self.document.rig_version, None if project.antagonists is None else list(project.antagonists)

    def _antagonists(self, rig) -> list[tuple[int, int]]:
        """The project's antagonist pairs (``Project.antagonist_pairs``: the user's, else those found from the rig,
        found once per rig, ahead by ``_warm_region_max`` in marker mode): a drag never leaves both on."""
        hit = self._antagonist_cache
        if hit is None or hit[:2] != self._antagonist_key():
            hit = self._antagonist_cache = (*self._antagonist_key(),
                                            pair_indices(rig, self.document.project.antagonist_pairs()))
        if isinstance(hit[2], Future):
            hit = self._antagonist_cache = (*hit[:2], hit[2].result())
        return hit[2]

    def begin_drag(self, index: int) -> DragState:
        """Set up a drag of marker ``index``: the regional solver of the chosen level for the current markers,
        the pins (every marker where it is now) and the damping gain of the dragged marker."""
        rig, doc = self.document.rig, self.document
        old = doc.pose_state()
        level = self.level
        lvl = self._level_obj(level)
        background = None
        if lvl is not None:
            blend, regions = lvl.blend, [r.vertices for r in lvl.regions]
            region_max = self._region_max_for(lvl)
            column = sp.csc_matrix(blend)[:, -1]
            background = column.indices[column.data > 0]          # the vertices the background blends into
        else:
            level, blend, regions, region_max = None, None, [], np.zeros((0, rig.n_shapes))
        W0 = pose_at_level(old, blend)
        ms = self.markers
        forward = self.viewport.camera_frame().forward
        solver = ms.drag_solver(rig, regions, region_max, lam_reg=self.lam_reg, antagonists=self._antagonists(rig),
                                background=background, dragged=(index, forward))
        if blend is not None:
            self._adopt_parts_ahead(blend)
        if blend is not None and not (old.is_regional and same_blend(old.blend, blend)):
            doc.set_pose_state(PoseState(old.weights, W0, blend, level))  # same pose, now per region
        start = self.marker_positions()
        gain = float(np.asarray(ms.S[index] @ self.gains).reshape(-1)[0])
        live = solver_correctives(rig)
        correctives = None if live is None else \
            (live[0], np.ascontiguousarray(in_view_plane(ms.delta_rows(live[1]).T, index, forward, axis=1)),
             np.asarray(live[2], np.intp))
        self.drag = DragState(index=index, old=old, level=level, blend=blend, W0=W0, solver=solver,
                              neutral_at=ms.positions(rig.neutral), start=start, targets=start.copy(), gain=gain,
                              W=W0.copy(), correctives=correctives, forward=forward)
        self._selected = index
        self.refresh_overlay(render=True)
        return self.drag

    def drag_by(self, mouse_delta: np.ndarray) -> np.ndarray:
        """Target = press position + damped ``mouse_delta`` (world units); re-solve and show. Returns W."""
        dr = self.drag
        dr.targets = dr.start.copy()
        dr.targets[dr.index] = dr.start[dr.index] + dr.gain * np.asarray(mouse_delta, dtype=np.float64)
        b = in_view_plane((dr.targets - dr.neutral_at).reshape(-1), dr.index, dr.forward)   # as the solver's rows
        # From the current pose, λ_r toward it (Joshi §4): warm-started, so a move costs a few solver steps.
        W = dr.solver.solve(b, dr.W) if dr.correctives is None else self._solve_with_correctives(dr, b)
        dr.W = W
        dr.moved = True
        if dr.blend is None:
            self.document.set_pose_state(PoseState(W[0], None, None, None))
        else:
            self.document.set_region_weights_live(W)
        self.drag_updated.emit()
        return W

    @staticmethod
    def _solve_with_correctives(dr: DragState, b: np.ndarray) -> np.ndarray:
        """The drag's weights when the surface also carries the correctives they fire (Smith §4.5): Gauss–Newton
        on each region's model A w + C(w) ≈ b, C the correctives' displacement of the markers with the
        region's weights, linearised at the latest weights (``RegionalSolver.solve(linearised=...)``)."""
        activate, Em, drivers = dr.correctives            # Em (C, 3M): each corrective's marker displacement
        W = dr.W
        for _ in range(DRAG_CORRECTIVE_STEPS):
            C, Jd = linearised_correctives(activate, Em, drivers, W)             # (R+1, 3M), (R+1, 3M, n)
            J = np.zeros((W.shape[0], Em.shape[1], W.shape[1]))
            J[:, :, drivers] = Jd
            offset = C - np.einsum("rmk,rk->rm", J, W)
            new = dr.solver.solve(b, dr.W, linearised=(offset, J))
            done = np.abs(new - W).max() < 1e-6
            W = new
            if done:
                break
        return W

    def end_drag(self) -> bool:
        """Finish the drag: one undo step from the pose at the press to the pose now (if it changed)."""
        dr, self.drag = self.drag, None
        if dr is None:
            return False
        new = self.document.pose_state()
        changed = dr.moved and not new.equals(dr.old)
        if changed:
            name = self.markers.names[dr.index]
            where = f"level {dr.level}" if dr.level is not None else "global"
            self.document.undo_stack.push(SetPoseCommand(self.document, dr.old, new, f"Drag marker {name} ({where})"))
        elif not new.equals(dr.old):
            self.document.set_pose_state(dr.old)
        self.refresh_overlay(render=True)
        return changed

    # --- the Shapes panel on a regional pose ------------------------------------------------------------
    def sync_edit_region(self) -> None:
        """The Shapes panel edits the region selected in the Segmentation panel when the pose is regional
        at that level; otherwise all regions (or the global pose)."""
        doc, seg = self.document, self.window.segmentation
        if doc.project is None:
            return
        region = None
        lvl = self._level_obj(seg.level)
        if (doc.is_regional and lvl is not None and seg.highlight is not None
                and same_blend(lvl.blend, doc.region_blend)):
            region = seg.highlight
        doc.set_edit_region(region)
        sh = self.window.shapes_panel
        if not doc.is_regional:
            sh.set_target("Editing the global pose")
        elif doc.edit_region is not None:
            sh.set_target(f"Editing region {doc.edit_region} of level {doc.region_level} "
                          f"(selected in the Segmentation panel)")
        else:
            sh.set_target(f"Regional pose (level {doc.region_level}): sliders show the background row and set "
                          f"every region; select a region to edit it alone")

    def edit_regional_pose(self, edit: PoseEdit) -> None:
        """A Shapes panel gesture on a regional pose: it edits the selected region's weights, or every region's
        (a reset or a preset on every region makes the pose global again). The window routes pose edits here
        while the pose is regional; each complete edit is one undo step."""
        doc = self.document
        if edit.kind == "drag-start":
            self._slider_old = doc.pose_state()
            return
        if edit.kind == "drag-end":
            old, self._slider_old = self._slider_old, None
            new = doc.pose_state()
            if old is not None and not new.equals(old):
                doc.undo_stack.push(SetPoseCommand(doc, old, new, f"Drag {doc.rig.shape_names[edit.shape]} (regional)"))
            return
        if not doc.is_regional:
            return
        if edit.kind == "drag":
            doc.set_region_weights_live(self._regional_with(edit.shape, edit.value))
        elif edit.kind == "set":
            old = doc.pose_state()
            new = PoseState(old.weights, self._regional_with(edit.shape, edit.value), old.blend, old.level)
            if not new.equals(old):
                doc.undo_stack.push(SetPoseCommand(
                    doc, old, new, f"Set {doc.rig.shape_names[edit.shape]} to {edit.value:.3g} (regional)"))
        elif edit.kind == "reset":
            self._set_rows(np.zeros(doc.rig.n_shapes),
                           "Reset pose" if doc.edit_region is None else f"Reset region {doc.edit_region}")
        elif edit.kind == "preset":
            self._set_rows(doc.rig.weights_from_dict(doc.rig.presets[edit.preset]), f"Preset {edit.preset}")

    def _regional_with(self, k: int, value: float) -> np.ndarray:
        doc = self.document
        W = doc.region_weights.copy()
        rows = np.array([doc.edit_region]) if doc.edit_region is not None else np.arange(W.shape[0])
        W[rows, k] = value
        return W

    def _set_rows(self, w: np.ndarray, text: str) -> None:
        doc = self.document
        old = doc.pose_state()
        if doc.edit_region is None:
            new = PoseState(np.asarray(w, dtype=np.float64), None, None, None)  # every region: a global pose
        else:
            W = old.region_weights.copy()
            W[doc.edit_region] = w
            new = PoseState(old.weights, W, old.blend, old.level)
        if not new.equals(old):
            doc.undo_stack.push(SetPoseCommand(doc, old, new, text))
