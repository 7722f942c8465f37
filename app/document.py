"""The open document: the project being edited, its pose evaluator and its undo stack.

Widgets never change it directly: the main window and controllers push undo commands (app.commands)
whose redo/undo call the setters here, which emit signals the views listen to.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
from PySide6 import QtCore
from PySide6.QtGui import QUndoStack

from model.pose import PoseEvaluator
from model.project import DetachedEdit, Project, save_project
from model.rig import Rig
from model import rig_prep


@dataclass(frozen=True)
class PoseState:
    """Everything that says what pose is shown (DESIGN.md "Pose"), stored exactly by undo commands.

    weights         (K,) the global weight vector.
    region_weights  (R+1, K) per-region weights of segmentation level ``level`` (last row: background),
                    or None for a global pose.
    blend           (V, R+1) partition of unity of that level (shared, never modified), or None.
    """

    weights: np.ndarray
    region_weights: np.ndarray | None = None
    blend: sp.csr_matrix | None = None
    level: int | None = None

    @property
    def is_regional(self) -> bool:
        return self.region_weights is not None

    def equals(self, other: "PoseState") -> bool:
        if not np.array_equal(self.weights, other.weights) or self.is_regional != other.is_regional:
            return False
        if not self.is_regional:
            return True
        return (self.level == other.level and self.blend is other.blend
                and np.array_equal(self.region_weights, other.region_weights))


def _same_deltas(old: PoseEvaluator, new: PoseEvaluator, shape_rows) -> bool:
    """Whether the shapes' deltas after an edit are the same set as before (so is their reach): ``new`` shares
    ``old``'s matrices, or ``shape_rows`` (see ``Document.rig_edited``) takes every old shape's row and no new one."""
    return new.shares_matrices(old) or (shape_rows is not None
                                        and set(np.asarray(shape_rows).tolist()) == set(range(old.K)))


class Document(QtCore.QObject):
    rig_changed = QtCore.Signal()      # a new rig (topology, shapes) — rebuild everything
    shapes_changed = QtCore.Signal()   # shapes or correctives edited on the same topology
    pose_changed = QtCore.Signal()     # weights changed — re-evaluate the surface
    path_changed = QtCore.Signal()
    section_changed = QtCore.Signal(str)   # a project section (e.g. 'segmentation') was edited
    offset_changed = QtCore.Signal()       # the pending sculpt/nudge offset changed
    shape_settings_changed = QtCore.Signal()   # mute, solo, ranges or in-betweens edited: same shapes and deltas

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.undo_stack = QUndoStack(self)
        self.project: Project | None = None
        self.path: Path | None = None
        self.evaluator: PoseEvaluator | None = None   # float32, for display
        self.rig_version = 0   # bumped on every new rig and rig edit: what the float64 evaluator is keyed on
        self._evaluator64: tuple[int, PoseEvaluator] | None = None
        self._shapes_version = 0   # bumped on every new rig and every edit of its shapes' deltas
        self._reach: tuple[int, np.ndarray] | None = None   # (shapes version, the shapes' reach)
        self.default_view: rig_prep.DefaultView | None = None   # prepared with the load (``model.rig_prep``), or None
        self._triangles: np.ndarray | None = None   # the rig's (``triangles``)
        self._surface: np.ndarray | None = None
        self.edit_offset: np.ndarray | None = None  # pending sculpt/nudge (V, 3), shown on top of the pose
        # Regional pose (Joshi §4): per-region weights of one segmentation level, or None for a global pose.
        self.region_weights: np.ndarray | None = None
        self.region_blend: sp.csr_matrix | None = None
        self.region_level: int | None = None
        self.edit_region: int | None = None   # the region the Shapes panel edits (None: all of them)
        self._collapsed: tuple | None = None  # (global weights set, regional state before): exact undo
        self._mirror: np.ndarray | None = None   # the rig's vertex mirror map, computed on first use
        # run_edit(label, fn) runs ``edit_rig``'s copies and returns fn's result: here by default; the window runs
        # them on a worker thread with its input held (``app.background.run_modal``)
        self.run_edit: Callable[[str, Callable[[], Any]], Any] = lambda label, fn: fn()

    # --- whole document ----------------------------------------------------------------------------
    def set_project(self, project: Project, path: str | Path | None, prep: rig_prep.RigPrep | None = None) -> None:
        """Replace the document (after a successful load: nothing is replaced on a failed one). ``prep``: the
        rig's evaluator and reach, made off the GUI thread (``model.rig_prep``); made here when not given."""
        self.project = project
        self.path = Path(path) if path else None
        if prep is not None and not prep.is_for(project.rig):
            prep = None
        self.evaluator = prep.evaluator if prep is not None else PoseEvaluator(project.rig)
        self.rig_version += 1
        self._shapes_version += 1
        self._reach = (self._shapes_version, prep.reach) if prep is not None else None
        # the default view's hidden back faces and normals, prepared with the load (the faces and parts of a rig
        # never change while it is open)
        self.default_view = prep.view if prep is not None else None
        self._triangles = prep.triangles if prep is not None else None
        self._surface = None
        self._mirror = None
        self.edit_offset = None
        # the saved current pose, regional if it was (its blend is kept with it)
        self.region_weights, self.region_blend, self.region_level = \
            project.region_weights, project.region_blend, project.region_level
        self.edit_region = None
        self._collapsed = None
        self.undo_stack.clear()
        self.rig_changed.emit()
        self.path_changed.emit()
        self.pose_changed.emit()

    def save(self, path: str | Path, write=None) -> None:
        """Write the project to ``path``; ``write(callable)`` runs the writing (the window runs it off the GUI thread
        with its input held, ``app.background.run_modal``), else it runs here. The document is then saved there."""
        assert self.project is not None
        p = self.project
        p.region_weights, p.region_blend, p.region_level = self.region_weights, self.region_blend, self.region_level
        if write is None:
            save_project(p, path)
        else:
            write(lambda: save_project(p, path))
        self.path = Path(path)
        self.undo_stack.setClean()
        self.path_changed.emit()

    def mirror_map(self) -> np.ndarray:
        """The rig's vertex mirror map across x = 0 (``solvers.symmetry.mirror_map``), once per rig: mirroring
        poses, shapes and correctives all use it."""
        if self._mirror is None:
            from solvers.symmetry import mirror_map
            self._mirror = mirror_map(self.project.rig.neutral)
        return self._mirror

    @property
    def rig(self):
        return None if self.project is None else self.project.rig

    @property
    def is_modified(self) -> bool:
        return not self.undo_stack.isClean()

    # --- pose --------------------------------------------------------------------------------------
    @property
    def is_regional(self) -> bool:
        return self.region_weights is not None

    @property
    def weights(self) -> np.ndarray:
        """The weight vector the Shapes panel shows: the global pose, or for a regional pose the edited
        region's row (the background row, which is solved globally, when no region is selected)."""
        if self.region_weights is None:
            return self.project.weights.copy()
        r = self.edit_region if self.edit_region is not None else self.region_weights.shape[0] - 1
        return self.region_weights[r].copy()

    def set_weights(self, weights: np.ndarray) -> None:
        """Set a global pose. On a regional pose this replaces it by the global one; setting the previous
        global weights right after (an undo) brings the regional pose back exactly."""
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != self.project.weights.shape:
            raise ValueError(f"expected {self.project.weights.shape[0]} weights, got {w.shape}")
        if self.region_weights is not None:
            self._collapsed = (w.copy(), self.pose_state(), self.weights)
            self.region_weights = self.region_blend = self.region_level = None
            self.project.weights = w.copy()
            self._surface = None
            self.pose_changed.emit()
            return
        c, self._collapsed = self._collapsed, None
        if c is not None and np.array_equal(self.project.weights, c[0]) and np.array_equal(w, c[2]):
            self.set_pose_state(c[1])
            return
        if np.array_equal(w, self.project.weights):
            return
        self.project.weights = w.copy()
        self._surface = None
        self.pose_changed.emit()

    def pose_state(self) -> PoseState:
        """A copy of the whole pose (global or regional) that ``set_pose_state`` restores exactly."""
        rw = None if self.region_weights is None else self.region_weights.copy()
        return PoseState(self.project.weights.copy(), rw, self.region_blend if rw is not None else None,
                         self.region_level if rw is not None else None)

    def set_pose_state(self, state: PoseState, surface: np.ndarray | None = None) -> None:
        """Show ``state`` (global or regional per-region weights with their level's blend). ``surface``: its posed
        surface if already evaluated (``evaluate_state(state)``: keyed playback evaluates the next frame ahead)."""
        w = np.asarray(state.weights, dtype=np.float64)
        if w.shape != self.project.weights.shape:
            raise ValueError(f"expected {self.project.weights.shape[0]} weights, got {w.shape}")
        if state.region_weights is not None:
            W = np.asarray(state.region_weights, dtype=np.float64)
            if state.blend is None or W.shape != (state.blend.shape[1], w.size):
                raise ValueError(f"regional weights {W.shape} do not fit the blend of level {state.level}")
        self._collapsed = None
        self.project.weights = w.copy()
        self.region_weights = None if state.region_weights is None else np.array(state.region_weights, dtype=np.float64)
        self.region_blend = state.blend if state.region_weights is not None else None
        self.region_level = state.level if state.region_weights is not None else None
        if self.edit_region is not None and (self.region_weights is None
                                             or self.edit_region >= self.region_weights.shape[0] - 1):
            self.edit_region = None
        self._surface = surface
        self.pose_changed.emit()

    def set_region_weights_live(self, region_weights: np.ndarray) -> None:
        """Replace the regional weights (same level and blend) during a drag; not an undo step by itself."""
        self.region_weights = np.asarray(region_weights, dtype=np.float64)
        self._collapsed = None
        self._surface = None
        self.pose_changed.emit()

    def set_edit_region(self, region: int | None) -> None:
        """Which region's row the Shapes panel shows and edits (None: the background / all regions)."""
        if region is not None and (self.region_weights is None or not 0 <= region < self.region_weights.shape[0] - 1):
            region = None
        if region != self.edit_region:
            self.edit_region = region
            self.pose_changed.emit()

    def evaluator64(self) -> PoseEvaluator:
        """The float64 evaluator of the current rig (exports, take solves, authoring), built on first use after
        each rig change."""
        if self._evaluator64 is None or self._evaluator64[0] != self.rig_version:
            self._evaluator64 = (self.rig_version, PoseEvaluator(self.project.rig, dtype=np.float64))
        return self._evaluator64[1]

    def triangles(self) -> np.ndarray:
        """(T, 3) the rig's triangles (``Rig.triangles``), prepared with the load or made on first use: a rig's
        faces never change while it is open."""
        if self._triangles is None:
            self._triangles = self.project.rig.triangles()
        return self._triangles

    def shape_reach(self) -> np.ndarray:
        """(V,) each vertex's largest displacement over the rig's shapes (``model.rig_prep.shape_reach``): where the
        camera frames and how much a marker drag is damped; made once per rig and per edit of its shapes."""
        if self._reach is None or self._reach[0] != self._shapes_version:
            self._reach = (self._shapes_version, rig_prep.shape_reach(self.project.rig))
        return self._reach[1]

    def evaluate_state(self, state: PoseState, dtype=np.float32) -> np.ndarray:
        """(V, 3) surface of any pose state (for export and playback), without touching the document."""
        ev = self.evaluator if dtype == np.float32 else self.evaluator64()
        return ev.pose(state.weights if state.region_weights is None else state.region_weights, state.blend)

    def posed_surface(self) -> np.ndarray:
        """(V, 3) float32 surface of the pose alone (no pending sculpt), cached."""
        if self._surface is None:
            self._surface = self.evaluator.pose(
                self.project.weights if self.region_weights is None else self.region_weights, self.region_blend)
        return self._surface

    def surface(self) -> np.ndarray:
        """(V, 3) float32 surface shown: the pose plus any pending sculpt/nudge offset."""
        x = self.posed_surface()
        return x if self.edit_offset is None else x + self.edit_offset.astype(np.float32)

    def set_edit_offset(self, offset: np.ndarray | None) -> None:
        self.edit_offset = None if offset is None else np.array(offset, dtype=np.float64)
        self.offset_changed.emit()
        self.pose_changed.emit()

    # --- sections ----------------------------------------------------------------------------------
    def section(self, name: str, default=None):
        return self.project.sections.get(name, default)

    def set_section(self, name: str, value) -> None:
        import copy
        self.project.sections[name] = copy.deepcopy(value)
        self.section_changed.emit(name)

    def set_section_arrays(self, name: str, value, arrays: dict[str, np.ndarray | None]) -> None:
        """Replace a section and the project arrays it refers to (None removes an array)."""
        import copy
        for key, a in arrays.items():
            if a is None:
                self.project.arrays.pop(key, None)
            else:
                self.project.arrays[key] = np.array(a)
        if value is None:
            self.project.sections.pop(name, None)
        else:
            self.project.sections[name] = copy.deepcopy(value)
        self.section_changed.emit(name)

    def shape_settings_edited(self, evaluator: PoseEvaluator | None = None, shape_rows=None) -> None:
        """The shapes' mute, solo, ranges or in-betweens changed (names and deltas did not): a new evaluator
        (``evaluator``, made off the GUI thread by ``edit_rig``, else here), reusing the old one's matrices when the
        in-betweens are the same, and a new pose."""
        self._edited_evaluators(evaluator, shape_rows)
        self._surface = None
        self.shape_settings_changed.emit()
        self.pose_changed.emit()

    def _edited_evaluators(self, evaluator: PoseEvaluator | None = None, shape_rows=None) -> None:
        """After an edit of the rig: the display evaluator (``evaluator`` if given), made of its predecessor's
        matrices where it can be (``PoseEvaluator.with_settings``: shared when the edit replaced none of the arrays
        they were made of, else copied row by row with ``shape_rows``); the float64 one kept (shared) only when its
        matrices can be shared, else made on its next use, not here; the rig's version bumped, and the shapes'
        version when the set of their deltas may have changed (the reach is made again on its next use: not after
        a rename, a reorder or a duplicate)."""
        rig, old = self.project.rig, self.evaluator
        self.evaluator = evaluator if evaluator is not None else old.with_settings(rig, shape_rows)
        if not _same_deltas(old, self.evaluator, shape_rows):
            self._shapes_version += 1
        kept = self._evaluator64
        self._evaluator64 = None
        if kept is not None and kept[0] == self.rig_version and kept[1].made_of(rig):
            self._evaluator64 = (self.rig_version + 1, kept[1].with_settings(rig))
        self.rig_version += 1

    def edit_rig(self, label: str, edit: Callable[[Project], Any], shape_rows: Callable[[Rig], list[int]], *,
                 settings: bool = False, made: PoseEvaluator | None = None) -> Any:
        """Run ``edit(project)`` -- an edit of the shapes' arrays that replaces what it changes (``model.shape_edits``'
        list edits, a shape's new deltas) -- on a copy of the project (``model.project.DetachedEdit``) with the live
        regional pose in it, and make the display evaluator of the result from this one's rows
        (``PoseEvaluator.with_settings`` with ``shape_rows(edited rig)``: see ``rig_edited``), both through
        ``run_edit``: in the window, on a worker thread while the window stays drawn (on the 106k-vertex,
        228-shape rig a reorder copies 580 MB of deltas and 232 MB of evaluator rows: seconds of new memory).
        Then the edit is taken over and the views told (``rig_edited``; with ``settings``, an edit of the shapes'
        in-betweens only, as ``shape_settings_edited``). ``made``: the edited rig's display evaluator, made
        beforehand with the arrays ``edit`` assigns (Save as new shape's background job): nothing is copied, so the
        edit runs here. Returns what ``edit`` returned; an error (a refused edit) leaves the document as it was."""
        run = self.run_edit if made is None else (lambda _label, fn: fn())
        while True:
            p = self.project
            # the project gets the live regional pose, as save does
            p.region_weights, p.region_blend, p.region_level = \
                self.region_weights, self.region_blend, self.region_level
            job, old = DetachedEdit(p), self.evaluator

            def work():
                result = edit(job.project)
                rows = list(shape_rows(job.project.rig))
                if made is not None:
                    return result, rows, made, None
                evaluator = old.with_settings(job.project.rig, rows)
                # the shapes' reach, where the set of deltas changed (``_edited_evaluators``): made here, not by the
                # views' first ``shape_reach`` after the edit (228 shapes x 106k vertices: 0.2-0.3 s)
                same = _same_deltas(old, evaluator, rows)
                return result, rows, evaluator, None if same else rig_prep.shape_reach(job.project.rig)

            result, rows, evaluator, reach = run(label, work)
            if self.project is p and self.evaluator is old:
                break
            # the rig was edited under the copy by something the window ran meanwhile (background results wait
            # for ``run_edit``, ``app.background.after_modal``, so nothing is expected to): the edit again, here
            run = lambda _label, fn: fn()   # noqa: E731
        job.adopt(p)
        evaluator.rig = p.rig            # made for the copy's Rig object, whose arrays ``p.rig`` now has
        if settings:
            self.shape_settings_edited(evaluator, rows)
        else:
            self.region_weights = p.region_weights
            self.rig_edited(evaluator=evaluator, shape_rows=rows, reach=reach)
        return result

    def rig_edited(self, evaluator: PoseEvaluator | None = None, shape_rows=None,
                   reach: np.ndarray | None = None) -> None:
        """Shapes or correctives changed in place (same topology): a new evaluator (or ``evaluator``, one built off
        the GUI thread for the edited arrays). An edit that replaced none of the arrays the evaluators are made of
        (a rename, other drivers) keeps their matrices and the shapes' reach; one of the shape list says which of
        the shapes before the edit each shape's deltas are (``shape_rows``: an index, or -1 for new deltas), and
        the new evaluator is copied from the old one's rows (``PoseEvaluator.with_settings``). ``reach``: the edited
        rig's ``shape_reach``, made off the GUI thread where the edit changed it."""
        rig = self.project.rig
        if self.region_weights is not None and self.region_weights.shape[1] != rig.n_shapes:
            self.region_weights = self.region_blend = self.region_level = None  # the shape set changed
            self.edit_region = None
        self._collapsed = None
        self._edited_evaluators(evaluator, shape_rows)
        if reach is not None:
            self._reach = (self._shapes_version, reach)
        self._surface = None
        self.shapes_changed.emit()
        self.pose_changed.emit()
