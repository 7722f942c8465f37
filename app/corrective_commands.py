"""Undo commands for corrective shapes (ALGORITHMS.md §6): every corrective edit is one of these.

Each stores the whole corrective list before and after (deep copies) plus the pending sculpt offset
before and after, so undo restores exactly what was there, bit for bit.
"""
from __future__ import annotations

import numpy as np
from PySide6.QtGui import QUndoCommand

from model.correctives import evaluation_order


def _copies(correctives) -> list:
    return [c.copy() for c in correctives]


class SetCorrectivesCommand(QUndoCommand):
    """Replace the rig's correctives (add, save a sculpt, import a scan, rename, edit drivers or rule, delete).

    ``old_offset``/``new_offset`` are the document's pending sculpt offset before and after (saving a
    sculpt clears it; undoing the save brings it back). The new list must already be validated
    (``model.correctives.validate_correctives``).
    """

    _KEEP = object()

    def __init__(self, document, old, new, text: str, old_offset=_KEEP, new_offset=_KEEP) -> None:
        super().__init__(text)
        self.document = document
        self.old = _copies(old)
        self.new = _copies(evaluation_order(new))
        cur = document.edit_offset
        self.old_offset = (None if cur is None else np.array(cur)) if old_offset is self._KEEP else \
            (None if old_offset is None else np.array(old_offset, dtype=np.float64))
        self.new_offset = self.old_offset if new_offset is self._KEEP else \
            (None if new_offset is None else np.array(new_offset, dtype=np.float64))

    def _apply(self, correctives, offset) -> None:
        doc = self.document
        doc.edit_offset = None if offset is None else offset.copy()
        doc.offset_changed.emit()

        def edit(project) -> None:
            project.rig.correctives = _copies(correctives)

        # the shapes are untouched: their rows are kept (copied, with the correctives' new rows: a studio rig's
        # 232 MB, off the GUI thread in the window; ``Document.edit_rig``)
        doc.edit_rig(self.text(), edit, lambda rig: list(range(rig.n_shapes)))

    def redo(self) -> None:
        self._apply(self.new, self.new_offset)

    def undo(self) -> None:
        self._apply(self.old, self.old_offset)
