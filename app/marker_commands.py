"""Undo commands of marker dragging and keyframing (ALGORITHMS.md §8): each stores old and new exactly.

* ``SetPoseCommand``      a drag (one per mouse press → release), a regional Shapes-panel edit, a key jump.
* ``SetMarkersCommand``   add or remove a marker (the 'markers' project section, old and new).
* ``SetSectionArraysCommand``  a project section plus the arrays it refers to (the keyframes).
"""
from __future__ import annotations

import copy

import numpy as np
from PySide6.QtGui import QUndoCommand

from app.document import PoseState


class SetPoseCommand(QUndoCommand):
    """Replace the whole pose (global or regional) by another; undo restores the old one exactly."""

    def __init__(self, document, old: PoseState, new: PoseState, text: str) -> None:
        super().__init__(text)
        self.document, self.old, self.new = document, _copy_state(old), _copy_state(new)

    def redo(self) -> None:
        self.document.set_pose_state(self.new)

    def undo(self) -> None:
        self.document.set_pose_state(self.old)


class SetMarkersCommand(QUndoCommand):
    """Set the project's markers section (``MarkerSet.to_dict()``), e.g. after adding or removing one."""

    def __init__(self, document, old: dict | None, new: dict | None, text: str) -> None:
        super().__init__(text)
        self.document, self.old, self.new = document, copy.deepcopy(old), copy.deepcopy(new)

    def _set(self, value) -> None:
        if value is None:
            self.document.project.sections.pop("markers", None)
            self.document.section_changed.emit("markers")
        else:
            self.document.set_section("markers", value)

    def redo(self) -> None:
        self._set(self.new)

    def undo(self) -> None:
        self._set(self.old)


class SetSectionArraysCommand(QUndoCommand):
    """Replace a section and its arrays (``project.arrays``), e.g. the keyframes after setting a key."""

    def __init__(self, document, name: str, old: tuple, new: tuple, text: str) -> None:
        """``old``/``new`` are (section value or None, {array key: array or None})."""
        super().__init__(text)
        self.document, self.name = document, name
        self.old = (copy.deepcopy(old[0]), {k: None if a is None else np.array(a) for k, a in old[1].items()})
        self.new = (copy.deepcopy(new[0]), {k: None if a is None else np.array(a) for k, a in new[1].items()})

    def redo(self) -> None:
        self.document.set_section_arrays(self.name, *self.new)

    def undo(self) -> None:
        self.document.set_section_arrays(self.name, *self.old)


def _copy_state(s: PoseState) -> PoseState:
    return PoseState(np.array(s.weights, dtype=np.float64),
                     None if s.region_weights is None else np.array(s.region_weights, dtype=np.float64),
                     s.blend, s.level)
