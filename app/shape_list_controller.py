"""The Shapes list's edits (Maya's Shape Editor, Blender's shape keys): reorder, sort, rename, duplicate, delete
with its correctives, mute, solo, slider ranges and in-betweens. Turns the Shapes panel's ``shape_edited``
gestures into undo commands (app.commands) over ``model.shape_edits``; asks for what a gesture leaves open
(a range, an in-between's weight, an OBJ file). Each public method is one undo step, also for tests.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app import settings as app_settings
from app.commands import (DeleteShapesCommand, DuplicateShapeCommand, RenameShapeCommand, ReorderShapesCommand,
                          SetShapeSettingsCommand)
from model import shape_edits as se
from model.errors import RigInputError
from model.wording import count


class ShapeListController(QtCore.QObject):
    def __init__(self, window) -> None:
        super().__init__(window)
        self.window, self.document, self.panel = window, window.document, window.shapes_panel
        self.dialog: QtWidgets.QDialog | None = None   # the question a gesture asked last (range, weight)
        self.panel.shape_edited.connect(self._on_shape_edit)
        self.document.rig_changed.connect(self.refresh)
        self.document.shapes_changed.connect(self.refresh)
        self.document.shape_settings_changed.connect(self.refresh)
        if self.document.project is not None:
            self.refresh()

    def refresh(self) -> None:
        """Show the rig's mute, solo, ranges and in-betweens in the panel."""
        rig = self.document.rig
        if rig is None:
            return
        self.panel.set_shape_info(rig.muted, rig.solo, dict(rig.ranges),
                                  {n: [i.weight for i in v] for n, v in rig.inbetweens.items()})

    # --- the panel's gestures ---------------------------------------------------------------------------
    def _on_shape_edit(self, edit) -> None:
        if self.document.rig is None:
            return
        k = edit.kind
        try:
            if k == "rename":
                self.rename(edit.shape, edit.text)
            elif k == "duplicate":
                self.duplicate(edit.shape)
            elif k == "delete":
                self.delete(list(edit.names or (edit.shape,)))
            elif k in ("move-up", "move-down"):
                self.move(list(edit.names or (edit.shape,)), -1 if k == "move-up" else 1)
            elif k == "move-to":
                self.move_to(list(edit.names or (edit.shape,)), int(edit.text))
            elif k == "sort":
                self.sort(edit.text)
            elif k == "mute":
                self.set_mute(edit.shape, edit.on)
            elif k == "solo":
                self.set_solo(edit.shape, edit.on, exclusive=edit.exclusive)
            elif k == "range":
                self.range_dialog(edit.shape)
            elif k == "inbetween-pose":
                self.inbetween_pose_dialog(edit.shape)
            elif k == "inbetween-obj":
                self.inbetween_obj_dialog(edit.shape)
            elif k == "remove-inbetweens":
                self.remove_inbetweens(edit.shape)
        except RigInputError as exc:
            self.window.show_error("Shapes", str(exc))
            self.refresh()   # a refused toggle shows the state again

    def _push(self, command) -> None:
        self.document.undo_stack.push(command)

    # --- edits (each one undo step) ---------------------------------------------------------------------
    def rename(self, old: str, new: str) -> None:
        new = se.check_new_name(self.document.rig, new, allow=old)
        if new != old:
            self._push(RenameShapeCommand(self.document, old, new))
            self.panel.select(new)
            self.window.show_status(f"Renamed {old} to {new}.")

    def duplicate(self, name: str) -> str:
        new = se.unique_name(self.document.rig, name)
        self._push(DuplicateShapeCommand(self.document, name, new))
        self.panel.select(new)
        self.window.show_status(f"Duplicated {name} as {new}.")
        return new

    def delete(self, names: list[str]) -> None:
        rig = self.document.rig
        fixes = se.correctives_needing(rig, names)
        what = names[0] if len(names) == 1 else count(len(names), "shape")
        text = f"Delete {what}" + (f" and {count(len(fixes), 'corrective')}" if fixes else "")
        self._push(DeleteShapesCommand(self.document, names, text))
        self.panel.select(None)
        self.window.show_status(f"Deleted {what}" + (f" and the corrective{'s' if len(fixes) > 1 else ''} "
                                                     f"{', '.join(fixes)}" if fixes else "") + " (Ctrl+Z brings it back).")

    def move(self, names: list[str], step: int) -> None:
        rig = self.document.rig
        what = names[0] if len(names) == 1 else count(len(names), "shape")
        self._reorder(se.moved_order(rig.n_shapes, [rig.shape_index(n) for n in names], step),
                      f"Move {what} {'up' if step < 0 else 'down'}")

    def move_to(self, names: list[str], place: int) -> None:
        """Move shapes to before list position ``place`` (a drag in the list)."""
        rig = self.document.rig
        self._reorder(se.moved_to_order(rig.n_shapes, [rig.shape_index(n) for n in names], place),
                      f"Move {names[0] if len(names) == 1 else count(len(names), 'shape')}")

    def _reorder(self, order: list[int], text: str) -> None:
        if order != list(range(self.document.rig.n_shapes)):
            se.reorder_check(self.document.rig, order)
            self._push(ReorderShapesCommand(self.document, order, text))

    def sort(self, by: str) -> None:
        rig = self.document.rig
        self._reorder(se.sorted_order(rig.shape_names, by), f"Sort shapes by {by}")

    def _settings(self, new, text: str, takes_offset: bool = False) -> None:
        old = se.ShapeSettings.of(self.document.rig)
        if new != old:
            self._push(SetShapeSettingsCommand(self.document, old, new, text, takes_offset=takes_offset))

    def set_mute(self, name: str, on: bool) -> None:
        self._settings(se.with_mute(self.document.rig, name, on), f"{'Mute' if on else 'Unmute'} {name}")

    def set_solo(self, name: str, on: bool, exclusive: bool = False) -> None:
        self._settings(se.with_solo(self.document.rig, name, on, exclusive=exclusive),
                       f"{'Solo' if on else 'Unsolo'} {name}")

    def set_range(self, name: str, lo: float, hi: float) -> None:
        self._settings(se.with_range(self.document.rig, name, lo, hi), f"Range of {name}: {lo:g} to {hi:g}")

    def add_inbetween_from_pose(self, name: str, weight: float) -> None:
        """The surface shown now (the pose plus any pending sculpt) becomes ``name``'s target at ``weight``."""
        doc = self.document
        surface = doc.evaluate_state(doc.pose_state(), dtype=np.float64)
        if doc.edit_offset is not None:
            surface = surface + doc.edit_offset
        delta = se.inbetween_from_surface(doc.rig, surface)
        self._settings(se.with_inbetween(doc.rig, name, weight, delta), f"In-between of {name} at {weight:g}",
                       takes_offset=True)
        self.window.show_status(f"Added an in-between of {name} at weight {weight:g} from the current pose.")

    def add_inbetween_from_obj(self, name: str, weight: float, path: str | Path) -> None:
        rig = self.document.rig
        delta = se.inbetween_from_obj(rig, path)
        self._settings(se.with_inbetween(rig, name, weight, delta), f"In-between of {name} at {weight:g}")
        self.window.show_status(f"Added an in-between of {name} at weight {weight:g} from {Path(path).name}.")

    def remove_inbetweens(self, name: str) -> None:
        self._settings(se.without_inbetweens(self.document.rig, name), f"Remove in-betweens of {name}")

    # --- what a gesture asks for ------------------------------------------------------------------------
    def range_dialog(self, name: str) -> None:
        lo, hi = se.shape_range(self.document.rig, name)
        dialog = RangeDialog(name, lo, hi, self.window)
        dialog.setAttribute(QtCore.Qt.WA_DeleteOnClose)
        dialog.accepted.connect(lambda: self._guarded(self.set_range, name, *dialog.values()))
        self.dialog = dialog
        dialog.open()

    def _weight_now(self, name: str) -> float:
        w = float(self.document.weights[self.document.rig.shape_index(name)])
        return w if w not in (0.0, 1.0) else 0.5

    def _ask_weight(self, text: str, value: float, then) -> QtWidgets.QInputDialog:
        """A window-modal question for an in-between's weight; ``then(weight)`` on OK (``self.dialog`` meanwhile)."""
        dlg = QtWidgets.QInputDialog(self.window)
        dlg.setWindowTitle("Add In-between")
        dlg.setInputMode(QtWidgets.QInputDialog.DoubleInput)
        dlg.setDoubleRange(-10.0, 10.0)
        dlg.setDoubleDecimals(3)
        dlg.setDoubleValue(value)
        dlg.setLabelText(text)
        dlg.setAttribute(QtCore.Qt.WA_DeleteOnClose)
        dlg.doubleValueSelected.connect(then)
        self.dialog = dlg
        dlg.open()
        return dlg

    def inbetween_pose_dialog(self, name: str) -> None:
        self._ask_weight(f"Weight at which {name} reaches the surface shown now\n(not 0 or 1; e.g. 0.5):",
                         self._weight_now(name), lambda w: self._guarded(self.add_inbetween_from_pose, name, w))

    def inbetween_obj_dialog(self, name: str) -> None:
        path = app_settings.open_file(self.window, "scanFolder", f"In-between of {name}", "OBJ (*.obj)")
        if path:
            self._ask_weight(f"Weight at which {name} reaches {Path(path).name}:", 0.5,
                             lambda w: self._guarded(self.add_inbetween_from_obj, name, w, path))

    def _guarded(self, fn, *args) -> None:
        try:
            fn(*args)
        except RigInputError as exc:
            self.window.show_error("Shapes", str(exc))


class RangeDialog(QtWidgets.QDialog):
    """Min and max of a shape's slider (Maya's slider limits): below 0 for negative weights, above 1 to
    overdrive."""

    def __init__(self, name: str, lo: float, hi: float, parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle(f"Range of {name}")
        form = QtWidgets.QFormLayout(self)
        self.lo, self.hi = QtWidgets.QDoubleSpinBox(), QtWidgets.QDoubleSpinBox()
        for box, v, tip in ((self.lo, lo, "Lowest weight (below 0: the opposite motion)"),
                            (self.hi, hi, "Highest weight (above 1: overdrive)")):
            box.setRange(-100.0, 100.0)
            box.setDecimals(3)
            box.setSingleStep(0.1)
            box.setValue(v)
            box.setToolTip(tip)
        form.addRow("Min", self.lo)
        form.addRow("Max", self.hi)
        buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.Ok | QtWidgets.QDialogButtonBox.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)

    def values(self) -> tuple[float, float]:
        return self.lo.value(), self.hi.value()
