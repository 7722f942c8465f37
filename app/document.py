"""The open document: the project being edited, its pose evaluator and its undo stack.

Widgets never change it directly: the main window and controllers push undo commands (app.commands)
whose redo/undo call the setters here, which emit signals the views listen to.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6 import QtCore
from PySide6.QtGui import QUndoStack

from model.pose import PoseEvaluator
from model.project import Project, save_project


class Document(QtCore.QObject):
    rig_changed = QtCore.Signal()      # a new rig (topology, shapes) — rebuild everything
    shapes_changed = QtCore.Signal()   # shapes or correctives edited on the same topology
    pose_changed = QtCore.Signal()     # weights changed — re-evaluate the surface
    path_changed = QtCore.Signal()
    section_changed = QtCore.Signal(str)   # a project section (e.g. 'segmentation') was edited
    offset_changed = QtCore.Signal()       # the pending sculpt/nudge offset changed

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.undo_stack = QUndoStack(self)
        self.project: Project | None = None
        self.path: Path | None = None
        self.evaluator: PoseEvaluator | None = None
        self._surface: np.ndarray | None = None
        self.edit_offset: np.ndarray | None = None  # pending sculpt/nudge (V, 3), shown on top of the pose

    # --- whole document ----------------------------------------------------------------------------
    def set_project(self, project: Project, path: str | Path | None) -> None:
        """Replace the document (after a successful load: nothing is replaced on a failed one)."""
        self.project = project
        self.path = Path(path) if path else None
        self.evaluator = PoseEvaluator(project.rig)
        self._surface = None
        self.edit_offset = None
        self.undo_stack.clear()
        self.rig_changed.emit()
        self.path_changed.emit()
        self.pose_changed.emit()

    def save(self, path: str | Path) -> None:
        assert self.project is not None
        save_project(self.project, path)
        self.path = Path(path)
        self.undo_stack.setClean()
        self.path_changed.emit()

    @property
    def rig(self):
        return None if self.project is None else self.project.rig

    @property
    def is_modified(self) -> bool:
        return not self.undo_stack.isClean()

    # --- pose --------------------------------------------------------------------------------------
    @property
    def weights(self) -> np.ndarray:
        return self.project.weights.copy()

    def set_weights(self, weights: np.ndarray) -> None:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != self.project.weights.shape:
            raise ValueError(f"expected {self.project.weights.shape[0]} weights, got {w.shape}")
        if np.array_equal(w, self.project.weights):
            return
        self.project.weights = w.copy()
        self._surface = None
        self.pose_changed.emit()

    def posed_surface(self) -> np.ndarray:
        """(V, 3) float32 surface of the pose alone (no pending sculpt), cached."""
        if self._surface is None:
            self._surface = self.evaluator.evaluate(self.project.weights)
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

    def rig_edited(self) -> None:
        """Shapes or correctives changed in place (same topology): rebuild the evaluator."""
        self.evaluator = PoseEvaluator(self.project.rig)
        self._surface = None
        self.shapes_changed.emit()
        self.pose_changed.emit()
