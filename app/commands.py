"""Undo commands: every edit a user makes goes through one of these (Qt's QUndoStack).

Each command stores what it needs to undo exactly (old and new values), never a diff to recompute.
"""
from __future__ import annotations

import numpy as np
from PySide6.QtGui import QUndoCommand


class SetWeightsCommand(QUndoCommand):
    """Set the global pose weights (a slider drag, a typed value, a preset, a reset)."""

    def __init__(self, document, old: np.ndarray, new: np.ndarray, text: str) -> None:
        super().__init__(text)
        self.document = document
        self.old = np.array(old, dtype=np.float64)
        self.new = np.array(new, dtype=np.float64)

    def redo(self) -> None:
        self.document.set_weights(self.new)

    def undo(self) -> None:
        self.document.set_weights(self.old)


class SetSectionCommand(QUndoCommand):
    """Replace a project section (e.g. the segmentation settings) with a new value."""

    def __init__(self, document, name: str, old, new, text: str) -> None:
        super().__init__(text)
        import copy
        self.document, self.name = document, name
        self.old, self.new = copy.deepcopy(old), copy.deepcopy(new)

    def redo(self) -> None:
        self.document.set_section(self.name, self.new)

    def undo(self) -> None:
        self.document.set_section(self.name, self.old)


class SetEditOffsetCommand(QUndoCommand):
    """A sculpt stroke or a region nudge: the pending offset before and after."""

    def __init__(self, document, old, new, text: str) -> None:
        super().__init__(text)
        self.document = document
        self.old = None if old is None else np.array(old)
        self.new = None if new is None else np.array(new)

    def redo(self) -> None:
        self.document.set_edit_offset(self.new)

    def undo(self) -> None:
        self.document.set_edit_offset(self.old)


class AddShapeCommand(QUndoCommand):
    """Add a new shape (e.g. from a nudged region) with weight 0, taking the pending offset with it."""

    def __init__(self, document, name: str, delta: np.ndarray, text: str | None = None,
                 takes_offset: bool = True, weight: float = 0.0, evaluator=None) -> None:
        super().__init__(text or f"Add shape {name}")
        self.document, self.name = document, name
        self.delta = np.array(delta, dtype=np.float64)
        self.takes_offset = takes_offset   # the pending nudge became the shape; a mirrored shape leaves it
        self.weight = float(weight)        # the new shape's weight (in every region of a regional pose)
        self.evaluator = evaluator         # a PoseEvaluator of the rig with the shape, built in the background
        self.offset = None if document.edit_offset is None else document.edit_offset.copy()

    def redo(self) -> None:
        doc = self.document
        rig, project = doc.rig, doc.project
        rig.shape_names = rig.shape_names + [self.name]
        rig.deltas = np.concatenate([rig.deltas, self.delta[None]], axis=0)
        project.weights = np.append(project.weights, self.weight)
        if doc.region_weights is not None:   # a regional pose keeps its regions, the new shape a column
            doc.region_weights = np.column_stack([doc.region_weights, np.full(len(doc.region_weights), self.weight)])
        if self.takes_offset:
            doc.edit_offset = None
        evaluator, self.evaluator = self.evaluator, None   # only for the first redo: later ones rebuild
        doc.rig_edited(evaluator)

    def undo(self) -> None:
        doc = self.document
        rig, project = doc.rig, doc.project
        k = rig.shape_names.index(self.name)
        rig.shape_names = rig.shape_names[:k] + rig.shape_names[k + 1:]
        rig.deltas = np.delete(rig.deltas, k, axis=0)
        project.weights = np.delete(project.weights, k)
        if doc.region_weights is not None and doc.region_weights.shape[1] == rig.n_shapes + 1:
            doc.region_weights = np.delete(doc.region_weights, k, axis=1)
        if self.takes_offset:
            self.document.edit_offset = self.offset
        self.document.rig_edited()


class SetShapeDeltaCommand(QUndoCommand):
    """Replace one shape's displacements (e.g. with the mirror image of its other side)."""

    def __init__(self, document, name: str, delta: np.ndarray, text: str) -> None:
        super().__init__(text)
        self.document, self.name = document, name
        k = document.rig.shape_names.index(name)
        self.old = document.rig.deltas[k].copy()
        self.new = np.array(delta, dtype=document.rig.deltas.dtype)

    def _set(self, delta: np.ndarray) -> None:
        rig = self.document.rig
        deltas = rig.deltas.copy()   # a new array: whatever kept the old one (an evaluator, a cache) keeps it whole
        deltas[rig.shape_names.index(self.name)] = delta
        rig.deltas = deltas
        self.document.rig_edited()

    def redo(self) -> None:
        self._set(self.new)

    def undo(self) -> None:
        self._set(self.old)
