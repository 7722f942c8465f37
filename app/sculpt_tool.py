"""Sculpt brushes on the viewport (ALGORITHMS.md §6, authoring a corrective; ``solvers.sculpt``): a viewport tool
(``widgets.viewport.ViewportTool``) that turns a left-button drag on the face into a grab, smooth or
inflate/deflate stroke, and a wireframe sphere overlay that shows the brush. A stroke writes the document's
pending edit offset live; the whole stroke is one ``SetEditOffsetCommand`` on the undo stack. The Correctives
controller turns the tool on in sculpt mode.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore

from app.commands import SetEditOffsetCommand
from solvers import sculpt
from widgets.viewport import Gesture, ViewportTool

_DAB = 0.1                  # inflate/deflate per dab: this fraction of the radius times the strength
_CURSOR = "brush_cursor"


class SculptTool(ViewportTool):
    """Brush strokes on ``viewport`` into ``document``'s edit offset, with the brush settings of ``panel``
    (a CorrectivesPanel); ``active()`` says whether sculpt mode is on (strokes and cursor only then)."""

    def __init__(self, viewport, document, panel, active) -> None:
        self.viewport, self.document, self.panel, self._active = viewport, document, panel, active
        self.mesh: sculpt.SculptMesh | None = None   # the rig's neighbourhoods and mirror map, once per rig
        self.brush_actions: list = []                # the Brush menu's actions: enabled in sculpt mode only
        self._stroke: dict | None = None
        self._cursor = None

    def reset(self) -> None:
        """A new rig: its sculpt mesh is built on the next ``enable``."""
        self.mesh = None

    # --- on the viewport -----------------------------------------------------------------------------
    def enable(self) -> None:
        """Take the viewport's left-button drags that start on the face (elsewhere the camera turns)."""
        rig = self.document.rig
        if self.mesh is None:
            self.mesh = sculpt.SculptMesh.build(rig.neutral, self.document.triangles(), symmetric=True)
        self.viewport.push_tool(self)
        self.set_brush_actions(True)

    def disable(self) -> None:
        """Finish a stroke under way, leave the viewport, hide the cursor."""
        if self._stroke is not None:
            self.end_stroke()
        self.viewport.remove_tool(self)
        self._hide_cursor()
        self.set_brush_actions(False)

    def set_brush_actions(self, on: bool) -> None:
        for act in self.brush_actions:
            act.setEnabled(on)

    def press(self, g: Gesture) -> bool:
        return g.button == QtCore.Qt.LeftButton and self.begin_stroke(g)

    def drag(self, g: Gesture) -> None:
        self.move_stroke(g)

    def release(self, g: Gesture) -> None:
        self.end_stroke()

    def hover(self, g: Gesture) -> None:
        if self._active():
            self._show_cursor(None if g.point is None else g.point.position)

    # --- strokes ---------------------------------------------------------------------------------------
    def begin_stroke(self, g: Gesture) -> bool:
        """Start a stroke where gesture ``g`` presses, if it is on the face; False otherwise (the view turns)."""
        if not self._active() or self.document.project is None or g.point is None:
            return False
        doc = self.document
        s = self.panel.brush_settings()
        base = doc.surface().astype(np.float64)
        old = None if doc.edit_offset is None else doc.edit_offset.copy()
        center = np.asarray(g.point.position, dtype=np.float64)
        self._stroke = {"settings": s, "old": old, "base": base, "center": center, "changed": False}
        if s["brush"] != "grab":
            self._dab(center)
        self._show_cursor(center)
        return True

    def move_stroke(self, g: Gesture) -> None:
        """Grab: pull the surface by the view-plane motion since the press; other brushes: a dab under the cursor."""
        st = self._stroke
        if st is None:
            return
        s = st["settings"]
        if s["brush"] == "grab":
            drag = g.motion
            new = sculpt.grab(st["base"], st["center"], drag, s["radius"], s["falloff"], s["strength"],
                              mesh=self.mesh, symmetric=s["symmetric"], reference=st["base"])
            base_offset = np.zeros_like(st["base"]) if st["old"] is None else st["old"]
            self.document.set_edit_offset(base_offset + (new - st["base"]))
            st["changed"] = True
            self._show_cursor(st["center"] + drag)
        elif g.point is not None:
            self._dab(g.point.position)
            self._show_cursor(g.point.position)

    def _dab(self, center) -> None:
        st, doc = self._stroke, self.document
        s = st["settings"]
        cur = doc.surface().astype(np.float64)
        if s["brush"] == "smooth":
            new = sculpt.smooth(cur, center, s["radius"], self.mesh, s["falloff"], 0.5 * s["strength"],
                                symmetric=s["symmetric"])
        else:
            amount = _DAB * s["radius"] * s["strength"] * (1.0 if s["brush"] == "inflate" else -1.0)
            new = sculpt.inflate(cur, center, s["radius"], self.mesh, amount, s["falloff"], symmetric=s["symmetric"])
        offset = np.zeros_like(cur) if doc.edit_offset is None else doc.edit_offset.copy()
        doc.set_edit_offset(offset + (new - cur))
        st["changed"] = True

    def end_stroke(self) -> None:
        """One stroke is one undo step (SetEditOffsetCommand from the offset before to the one after)."""
        st, self._stroke = self._stroke, None
        if st is None or not st["changed"]:
            return
        doc = self.document
        new = doc.edit_offset
        doc.undo_stack.push(SetEditOffsetCommand(doc, st["old"], new, f"Sculpt ({st['settings']['brush']})"))

    # --- brush cursor ------------------------------------------------------------------------------
    def _show_cursor(self, center) -> None:
        if center is None or not self._active():
            self._hide_cursor()
            return
        import pyvista as pv
        r = self.panel.radius.value()
        if self._cursor is None:
            sphere = pv.Sphere(radius=1.0, theta_resolution=16, phi_resolution=9)
            unit = np.asarray(sphere.points, dtype=np.float64)
            actor = self.viewport.add_overlay(_CURSOR, sphere, style="wireframe", color=(1.0, 0.75, 0.3),
                                              opacity=0.3, line_width=1, lighting=False)
            self._cursor = (sphere, actor, unit)
        sphere, actor, unit = self._cursor
        sphere.points = (unit * r + np.asarray(center, dtype=np.float64)).astype(np.float32)
        actor.visibility = True
        self._render()

    def update_cursor_radius(self) -> None:
        if self._cursor is not None and self._cursor[1].visibility:
            pts = np.asarray(self._cursor[0].points, dtype=np.float64)
            self._show_cursor(pts.mean(axis=0))

    def _hide_cursor(self) -> None:
        if self._cursor is not None and self._cursor[1].visibility:
            self._cursor[1].visibility = False
            self._render()

    def _render(self) -> None:
        """Show the cursor: now (a hover), or by the window's redraw of the stroke's new surface when one is coming
        (``render_pending``). Rendering here too drew each stroke move twice, the old surface and then the new: at
        422k vertices 0.1-0.16 s more a move, and with the level of detail (``widgets.lod``) the second frame, close
        after the first, drew the proxy: the face flickered between it and the full surface at every dab."""
        if not self.viewport.plotter.render_pending():
            self.viewport.render()
