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

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.undo_stack = QUndoStack(self)
        self.project: Project | None = None
        self.path: Path | None = None
        self.evaluator: PoseEvaluator | None = None
        self._surface: np.ndarray | None = None

    # --- whole document ----------------------------------------------------------------------------
    def set_project(self, project: Project, path: str | Path | None) -> None:
        """Replace the document (after a successful load: nothing is replaced on a failed one)."""
        self.project = project
        self.path = Path(path) if path else None
        self.evaluator = PoseEvaluator(project.rig)
        self._surface = None
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

    def surface(self) -> np.ndarray:
        """(V, 3) float32 posed surface, cached until the pose or shapes change."""
        if self._surface is None:
            self._surface = self.evaluator.evaluate(self.project.weights)
        return self._surface

    def rig_edited(self) -> None:
        """Shapes or correctives changed in place (same topology): rebuild the evaluator."""
        self.evaluator = PoseEvaluator(self.project.rig)
        self._surface = None
        self.shapes_changed.emit()
        self.pose_changed.emit()
