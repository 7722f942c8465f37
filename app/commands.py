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
