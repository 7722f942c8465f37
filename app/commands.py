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
    """Add a new shape (e.g. from a nudged region) with weight 0, taking the pending offset with it.

    ``prepared``: (the rig's deltas with the new shape's appended, the display evaluator of that rig), made in the
    background by the caller (``added_shape``) for the first redo; every other redo and undo copies the deltas and
    the evaluator's rows through ``Document.edit_rig`` (in the window: off the GUI thread)."""

    def __init__(self, document, name: str, delta: np.ndarray, text: str | None = None,
                 takes_offset: bool = True, weight: float = 0.0, prepared=None) -> None:
        super().__init__(text or f"Add shape {name}")
        self.document, self.name = document, name
        self.delta = np.array(delta, dtype=np.float64)
        self.takes_offset = takes_offset   # the pending nudge became the shape; a mirrored shape leaves it
        self.weight = float(weight)        # the new shape's weight (in every region of a regional pose)
        self.prepared = prepared
        self.offset = None if document.edit_offset is None else document.edit_offset.copy()

    def _add(self, project, deltas=None) -> None:
        rig = project.rig
        rig.shape_names = rig.shape_names + [self.name]
        rig.deltas = np.concatenate([rig.deltas, self.delta[None]], axis=0) if deltas is None else deltas
        project.weights = np.append(project.weights, self.weight)
        if project.region_weights is not None:   # a regional pose keeps its regions, the new shape a column
            R = project.region_weights
            project.region_weights = np.column_stack([R, np.full(len(R), self.weight)])

    def redo(self) -> None:
        doc = self.document
        if self.takes_offset:
            doc.edit_offset = None
        prepared, self.prepared = self.prepared, None      # only for the first redo
        rows = lambda rig: [*range(rig.n_shapes - 1), -1]   # noqa: E731  (the new shape's row is new)
        if prepared is not None and prepared[1].made_of(_added(doc.rig, self.name, prepared[0])):
            doc.edit_rig(self.text(), lambda project: self._add(project, prepared[0]), rows, made=prepared[1])
        else:
            doc.edit_rig(self.text(), self._add, rows)

    def undo(self) -> None:
        doc = self.document
        k = doc.rig.shape_names.index(self.name)

        def remove(project) -> None:
            rig = project.rig
            rig.shape_names = rig.shape_names[:k] + rig.shape_names[k + 1:]
            rig.deltas = np.delete(rig.deltas, k, axis=0)
            project.weights = np.delete(project.weights, k)
            R = project.region_weights
            if R is not None and R.shape[1] == rig.n_shapes + 1:
                project.region_weights = np.delete(R, k, axis=1)

        if self.takes_offset:
            doc.edit_offset = self.offset
        doc.edit_rig(self.text(), remove, lambda rig: [i for i in range(rig.n_shapes + 1) if i != k])


def _added(rig, name: str, deltas: np.ndarray):
    """A view of ``rig`` with a shape ``name`` of ``deltas``' last row appended (its Rig object not changed)."""
    import copy
    view = copy.copy(rig)
    view.shape_names, view.deltas = rig.shape_names + [name], deltas
    return view


def added_shape(document, name: str, delta: np.ndarray):
    """``AddShapeCommand``'s ``prepared`` for ``document``'s rig with shape ``name`` of ``delta`` appended: its
    deltas and display evaluator (the old one's rows copied). For a background job: reads the document's arrays
    and evaluator, changes nothing."""
    rig = document.rig
    deltas = np.concatenate([rig.deltas, np.asarray(delta, dtype=np.float64)[None]], axis=0)
    return deltas, document.evaluator.with_settings(_added(rig, name, deltas), [*range(rig.n_shapes), -1])


class SetShapeDeltaCommand(QUndoCommand):
    """Replace one shape's displacements (e.g. with the mirror image of its other side)."""

    def __init__(self, document, name: str, delta: np.ndarray, text: str) -> None:
        super().__init__(text)
        self.document, self.name = document, name
        k = document.rig.shape_names.index(name)
        self.old = document.rig.deltas[k].copy()
        self.new = np.array(delta, dtype=document.rig.deltas.dtype)

    def _set(self, delta: np.ndarray) -> None:
        def edit(project) -> None:
            deltas = project.rig.deltas.copy()   # a new array: whatever kept the old one (an evaluator) keeps it
            deltas[project.rig.shape_names.index(self.name)] = delta
            project.rig.deltas = deltas

        def rows(rig) -> list[int]:
            rows = list(range(rig.n_shapes))
            rows[rig.shape_names.index(self.name)] = -1     # the evaluator's other rows are kept
            return rows

        self.document.edit_rig(self.text(), edit, rows)   # off the GUI thread in the window (Document.edit_rig)

    def redo(self) -> None:
        self._set(self.new)

    def undo(self) -> None:
        self._set(self.old)


# --- the Shapes list (model.shape_edits) ------------------------------------------------------------------
class _ShapeListCommand(QUndoCommand):
    """Runs a ``model.shape_edits`` edit on the document's project with the live regional pose in it, then
    tells every view: the evaluator is rebuilt and the keyed animation reloaded (its columns follow the shapes).
    The edits that copy the shapes' deltas (reorder, delete and its undo, duplicate) run through
    ``Document.edit_rig``: in the window, on a worker thread while the window stays drawn."""

    def __init__(self, document, text: str) -> None:
        super().__init__(text)
        self.document = document

    def _edit(self, fn, *args):
        doc = self.document
        # each shape's deltas after the edit are those of the shape of its name before (-1: a new one)
        before = {n: i for i, n in enumerate(doc.project.rig.shape_names)}
        result = doc.edit_rig(self.text(), lambda project: fn(project, *args),
                              lambda rig: [before.get(n, -1) for n in rig.shape_names])
        doc.section_changed.emit("keyframes")
        return result

    def _edit_here(self, fn, *args):
        """``_edit`` on the document's own project, on this thread: for a rename, which copies no array but
        renames the correctives' drivers in their (shared) objects."""
        doc = self.document
        p = doc.project
        before = {n: i for i, n in enumerate(p.rig.shape_names)}
        # the document holds the live regional pose; the project gets all of it, as Document.save does
        p.region_weights, p.region_blend, p.region_level = doc.region_weights, doc.region_blend, doc.region_level
        try:
            result = fn(p, *args)
        finally:
            doc.region_weights = p.region_weights
        # these edits move, remove or add whole shapes and never change a kept shape's deltas: each shape's are those
        # of the shape of its name before (-1: a new one; a rename keeps the very arrays, which the evaluator sees)
        doc.rig_edited(shape_rows=[before.get(n, -1) for n in p.rig.shape_names])
        doc.section_changed.emit("keyframes")
        return result


class ReorderShapesCommand(_ShapeListCommand):
    """Move or sort shapes: ``order`` lists the old indices in their new places."""

    def __init__(self, document, order, text: str) -> None:
        super().__init__(document, text)
        self.order = list(order)
        self.inverse: list[int] | None = None

    def redo(self) -> None:
        from model.shape_edits import reorder_shapes
        self.inverse = self._edit(reorder_shapes, self.order)

    def undo(self) -> None:
        from model.shape_edits import reorder_shapes
        self._edit(reorder_shapes, self.inverse)


class RenameShapeCommand(_ShapeListCommand):
    def __init__(self, document, old: str, new: str) -> None:
        super().__init__(document, f"Rename {old} to {new}")
        self.old, self.new = old, new
        self.record = None

    def redo(self) -> None:
        from model.shape_edits import rename_shape
        self.record = self._edit_here(rename_shape, self.old, self.new)

    def undo(self) -> None:
        from model.shape_edits import undo_rename
        self._edit_here(undo_rename, self.record)


class DeleteShapesCommand(_ShapeListCommand):
    """Delete shapes with the correctives that need them; undo puts all of it back bit for bit."""

    def __init__(self, document, names: list[str], text: str) -> None:
        super().__init__(document, text)
        self.names = list(names)
        self.record = None

    def redo(self) -> None:
        from model.shape_edits import delete_shapes
        self.record = self._edit(delete_shapes, self.names)

    def undo(self) -> None:
        from model.shape_edits import restore_shapes
        self._edit(restore_shapes, self.record)


class DuplicateShapeCommand(_ShapeListCommand):
    def __init__(self, document, name: str, new_name: str) -> None:
        super().__init__(document, f"Duplicate {name} as {new_name}")
        self.name, self.new_name = name, new_name

    def redo(self) -> None:
        from model.shape_edits import duplicate_shape
        self._edit(duplicate_shape, self.name, self.new_name)

    def undo(self) -> None:
        from model.shape_edits import delete_shapes
        self._edit(delete_shapes, [self.new_name])


class SetShapeSettingsCommand(_ShapeListCommand):
    """Mute, solo, a slider range or an in-between (``model.shape_edits.ShapeSettings`` before and after);
    ``takes_offset``: an in-between made from the shown surface takes the pending sculpt with it."""

    def __init__(self, document, old, new, text: str, takes_offset: bool = False) -> None:
        super().__init__(document, text)
        self.old, self.new = old, new
        self.takes_offset = takes_offset
        self.offset = None if document.edit_offset is None else document.edit_offset.copy()

    def _apply(self, settings, offset_after) -> None:
        doc = self.document
        if self.takes_offset:
            doc.edit_offset = offset_after
            doc.offset_changed.emit()
        arrays = lambda inbetweens: {n: [id(i.delta) for i in v] for n, v in inbetweens.items()}   # noqa: E731
        if arrays(settings.inbetweens) != arrays(doc.rig.inbetweens):
            # new evaluator rows (a studio rig's 232 MB copied): off the GUI thread, as the shape list's edits
            doc.edit_rig(self.text(), lambda project: settings.apply(project.rig),
                         lambda rig: list(range(rig.n_shapes)), settings=True)
        else:                  # mute, solo, a range: the evaluator's matrices are shared
            settings.apply(doc.rig)
            doc.shape_settings_edited()

    def redo(self) -> None:
        self._apply(self.new, None)

    def undo(self) -> None:
        self._apply(self.old, self.offset)
