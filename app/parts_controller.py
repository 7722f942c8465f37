"""View ▸ Parts and View ▸ Material Colours: which parts of the rig the viewport draws, and in which colours.

A part is the rig's faces of one material (``model.parts``: ICT FaceKit has twelve -- face, back of the head,
teeth, gums and tongue, each eye's sclera and iris, lashes and three helper shells). Hiding one is a view setting,
as Maya's Hide or Blender's H: the faces are not drawn or picked, the vertices stay and still move with the pose,
nothing in the document changes (so it is not an undo step). The helper shells start hidden (their renderer draws
them translucent; drawn opaque they cover the eyeballs). Both settings are remembered between sessions: the
parts by name (a part the user hid or showed stays so on every rig with a part of that name), the colours on or
off.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui

from app import settings as app_settings
from model.parts import default_hidden, rig_parts, shown_faces, vertex_colors
from model.wording import count
from widgets.scene import SKIN

HIDDEN_KEY, SHOWN_KEY, COLORS_KEY = "view/hidden_parts", "view/shown_parts", "view/material_colors"


def _names(key: str) -> set[str]:
    value = app_settings.settings().value(key, [])
    return {value} if isinstance(value, str) and value else {v for v in (value or []) if isinstance(v, str) and v}


class PartsController(QtCore.QObject):
    """Owns View ▸ Parts (a check per part, Show All Parts) and View ▸ Material Colours, and tells the viewport
    the faces to draw and the parts' colours (``Viewport.set_parts``); ``changed`` tells the other views (the
    Mocap Views) that the parts shown changed."""

    changed = QtCore.Signal()

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window = window
        self.viewport = window.viewport
        self.rig = None
        self.parts = None
        self.hidden: list[str] = []
        self.menu = window.add_menu("parts", "&Parts", parent="view")
        self.menu.setToolTipsVisible(True)
        self.colors_action = window.add_action(
            "view", "&Material Colours", None, None,
            "Draw each part in its material's colour from the rig's file (MTL Kd, glTF base colour) instead of one "
            "skin colour", checkable=True)
        self.colors_action.setChecked(app_settings.settings().value(COLORS_KEY, False, type=bool))
        self.colors_action.toggled.connect(self._on_colors)
        self._fill_menu()

    # --- what the viewport draws ------------------------------------------------------------------
    def view_for(self, rig):
        """(faces to draw or None, vertex colours or None) for a rig about to be shown; rebuilds the menu."""
        self.rig, self.parts = rig, rig_parts(rig)
        hidden_by_user, shown_by_user = _names(HIDDEN_KEY), _names(SHOWN_KEY)
        names = self.parts.names if self.parts is not None else []
        defaults = set(default_hidden(names))
        self.hidden = [n for n in names if n in hidden_by_user or (n in defaults and n not in shown_by_user)]
        if len(self.hidden) == len(names):
            self.hidden = []      # never an empty view
        self._fill_menu()
        return self._view()

    def shown_faces(self) -> np.ndarray | None:
        """The rig's faces of the parts shown (None: all of them)."""
        return shown_faces(self.parts, self.hidden) if self.rig is not None else None

    def _view(self):
        rig = self.rig
        colors = None
        if self.colors_action.isChecked():
            colors = vertex_colors(self.parts, rig.face_counts, rig.face_indices, rig.n_vertices, SKIN)
        return shown_faces(self.parts, self.hidden), colors

    def _apply(self) -> None:
        if self.rig is not None:
            self.viewport.set_parts(*self._view())
            self.changed.emit()

    # --- the menu ---------------------------------------------------------------------------------------
    def _fill_menu(self) -> None:
        self.menu.clear()
        self.part_actions: dict[str, QtGui.QAction] = {}
        if self.parts is None:
            none = self.menu.addAction("No parts: the rig's faces name no materials")
            none.setEnabled(False)
            self.colors_action.setEnabled(False)
            return
        self.colors_action.setEnabled(not np.isnan(self.parts.colors).all())   # some part has a colour of its own
        for k, name in enumerate(self.parts.names):
            n = int((self.parts.face_part == k).sum())
            a = self.menu.addAction(f"{name}  ({count(n, 'face')})")
            a.setCheckable(True)
            a.setChecked(name not in self.hidden)
            a.setToolTip(f"Show or hide the faces of material {name}; its vertices still move with the pose")
            a.toggled.connect(lambda on, name=name: self.set_shown(name, on))
            self.part_actions[name] = a
        self.menu.addSeparator()
        self.show_all_action = self.menu.addAction("Show &All Parts", self.show_all)

    def set_shown(self, name: str, shown: bool) -> None:
        """Show or hide part ``name`` (remembered by name); the last part shown cannot be hidden."""
        self._set_shown({name: shown})

    def show_all(self) -> None:
        self._set_shown(dict.fromkeys(self.hidden, True))

    def _set_shown(self, wanted: dict[str, bool]) -> None:
        """Show (True) or hide (False) the parts named in ``wanted``, remember it, and redraw once."""
        if self.parts is None:
            return
        wanted = {n: on for n, on in wanted.items() if n in self.parts.names and (n not in self.hidden) != on}
        if not wanted:
            return
        hidden = (set(self.hidden) | {n for n, on in wanted.items() if not on}) - {n for n, on in wanted.items() if on}
        if len(hidden) >= len(self.parts.names):
            self.window.show_status("One part at least stays shown.")
            self._sync_checks()
            return
        self.hidden = [n for n in self.parts.names if n in hidden]
        hidden_by_user, shown_by_user = _names(HIDDEN_KEY), _names(SHOWN_KEY)
        for n, on in wanted.items():
            (hidden_by_user.discard if on else hidden_by_user.add)(n)
            (shown_by_user.add if on else shown_by_user.discard)(n)
        s = app_settings.settings()
        s.setValue(HIDDEN_KEY, sorted(hidden_by_user))
        s.setValue(SHOWN_KEY, sorted(shown_by_user))
        self._sync_checks()
        self._apply()

    def _sync_checks(self) -> None:
        for name, a in self.part_actions.items():
            a.blockSignals(True)
            a.setChecked(name not in self.hidden)
            a.blockSignals(False)

    def _on_colors(self, on: bool) -> None:
        app_settings.settings().setValue(COLORS_KEY, bool(on))
        self._apply()
