"""Undo commands of the actor workflows (issue 15): each stores the old and the new value exactly.

* ``SetAntagonistsCommand``   the project's antagonist pairs (``Project.antagonists``; None: the rig's own).
* ``SetNeutralFramesCommand`` the take solve's neutral frames (the Mocap panel's "Neutral frames").
* ``SetMarkerMapCommand``     the take's marker map (a map point dragged onto another place of the rig).
"""
from __future__ import annotations

from PySide6.QtGui import QUndoCommand

ANTAGONISTS = "antagonists"   # the name ``Document.section_changed`` carries when the pairs change


class SetAntagonistsCommand(QUndoCommand):
    """Replace the project's antagonist pairs ((name, name) list, or None for the pairs found from the rig)."""

    def __init__(self, document, old, new, text: str) -> None:
        super().__init__(text)
        self.document = document
        self.old = None if old is None else [tuple(p) for p in old]
        self.new = None if new is None else [tuple(p) for p in new]

    def _set(self, value) -> None:
        self.document.project.antagonists = None if value is None else list(value)
        self.document.section_changed.emit(ANTAGONISTS)

    def redo(self) -> None:
        self._set(self.new)

    def undo(self) -> None:
        self._set(self.old)


class SetNeutralFramesCommand(QUndoCommand):
    """Set the neutral frames of the take solve ('A:B', 'auto' or None for the first calibration frames)."""

    def __init__(self, mocap, old: str | None, new: str | None, text: str) -> None:
        super().__init__(text)
        self.mocap, self.old, self.new = mocap, old, new

    def redo(self) -> None:
        self.mocap.show_neutral_frames(self.new)

    def undo(self) -> None:
        self.mocap.show_neutral_frames(self.old)


class SetMarkerMapCommand(QUndoCommand):
    """Replace the take's marker map (``model.marker_map.MarkerMap``) by another."""

    def __init__(self, mocap, old, new, text: str) -> None:
        super().__init__(text)
        self.mocap, self.old, self.new = mocap, old, new

    def redo(self) -> None:
        self.mocap.use_map(self.new)

    def undo(self) -> None:
        self.mocap.use_map(self.old)
