"""Sculpt brushes on the viewport (ALGORITHMS.md §6, authoring a corrective; ``solvers.sculpt``): VTK observers
that turn a left-button drag on the face into a grab, smooth or inflate/deflate stroke, and a wireframe sphere
that shows the brush. A stroke writes the document's pending edit offset live; the whole stroke is one
``SetEditOffsetCommand`` on the undo stack. The Correctives controller turns the tool on in sculpt mode.
"""
from __future__ import annotations

import numpy as np

from app.commands import SetEditOffsetCommand
from solvers import sculpt

_OBSERVER_PRIORITY = 10.0   # above the interactor style (0): a stroke on the face does not turn the camera
_DAB = 0.1                  # inflate/deflate per dab: this fraction of the radius times the strength


class SculptTool:
    """Brush strokes on ``viewport`` into ``document``'s edit offset, with the brush settings of ``panel``
    (a CorrectivesPanel); ``active()`` says whether sculpt mode is on (strokes and cursor only then)."""

    def __init__(self, viewport, document, panel, active) -> None:
        self.viewport, self.document, self.panel, self._active = viewport, document, panel, active
        self.mesh: sculpt.SculptMesh | None = None   # the rig's neighbourhoods and mirror map, once per rig
        self.brush_actions: list = []                # the Brush menu's actions: enabled in sculpt mode only
        self._tags: dict[str, int] = {}
        self._stroke: dict | None = None
        self._cursor = None
        self._cursor_unit = None

    def reset(self) -> None:
        """A new rig: its sculpt mesh is built on the next ``enable``."""
        self.mesh = None

    # --- VTK observers on the viewport ---------------------------------------------------------------
    def _vtk_interactor(self):
        return self.viewport.plotter.iren.interactor

    def enable(self) -> None:
        """Listen to the viewport's mouse (strokes start on the face; elsewhere the camera turns)."""
        rig = self.document.rig
        if self.mesh is None:
            self.mesh = sculpt.SculptMesh.build(rig.neutral, rig.triangles(), symmetric=True)
        if self._tags:
            return
        iren = self._vtk_interactor()
        for event, fn in (("LeftButtonPressEvent", self._on_press), ("MouseMoveEvent", self._on_move),
                          ("LeftButtonReleaseEvent", self._on_release)):
            self._tags[event] = iren.AddObserver(event, fn, _OBSERVER_PRIORITY)
        self.set_brush_actions(True)

    def disable(self) -> None:
        """Finish a stroke under way, stop listening, hide the cursor."""
        if self._stroke is not None:
            self.end_stroke()
        iren = self._vtk_interactor() if hasattr(self.viewport, "plotter") else None
        for tag in self._tags.values():
            if iren is not None:
                iren.RemoveObserver(tag)
        self._tags.clear()
        self._hide_cursor()
        self.set_brush_actions(False)

    def set_brush_actions(self, on: bool) -> None:
        for act in self.brush_actions:
            act.setEnabled(on)

    def _abort(self, obj, event: str) -> None:
        cmd = obj.GetCommand(self._tags[event]) if event in self._tags else None
        if cmd is not None:
            cmd.SetAbortFlag(1)

    def _on_press(self, obj, event) -> None:
        x, y = obj.GetEventPosition()
        if self.begin_stroke(x, y):
            self._abort(obj, event)

    def _on_move(self, obj, event) -> None:
        x, y = obj.GetEventPosition()
        if self._stroke is not None:
            self.move_stroke(x, y)
            self._abort(obj, event)
        else:
            hit = self.viewport.pick(x, y)
            self._show_cursor(None if hit is None else hit[1])

    def _on_release(self, obj, event) -> None:
        if self._stroke is not None:
            self.end_stroke()
            self._abort(obj, event)

    # --- strokes (display pixels from the bottom-left, like VTK) -----------------------------------
    def _to_display(self, p) -> np.ndarray:
        r = self.viewport.plotter.renderer
        r.SetWorldPoint(float(p[0]), float(p[1]), float(p[2]), 1.0)
        r.WorldToDisplay()
        return np.array(r.GetDisplayPoint())

    def _to_world(self, x: float, y: float, z: float) -> np.ndarray:
        r = self.viewport.plotter.renderer
        r.SetDisplayPoint(float(x), float(y), float(z))
        r.DisplayToWorld()
        wp = np.array(r.GetWorldPoint())
        return wp[:3] / wp[3]

    def begin_stroke(self, x: float, y: float) -> bool:
        """Start a stroke at display pixel (x, y) if it is on the face; False otherwise (the view turns)."""
        if not self._active() or self.document.project is None:
            return False
        hit = self.viewport.pick(int(x), int(y))
        if hit is None:
            return False
        doc = self.document
        s = self.panel.brush_settings()
        base = doc.surface().astype(np.float64)
        old = None if doc.edit_offset is None else doc.edit_offset.copy()
        self._stroke = {"settings": s, "old": old, "base": base, "center": np.asarray(hit[1], dtype=np.float64),
                        "depth": self._to_display(hit[1])[2], "changed": False}
        if s["brush"] != "grab":
            self._dab(hit[1])
        self._show_cursor(hit[1])
        return True

    def move_stroke(self, x: float, y: float) -> None:
        st = self._stroke
        if st is None:
            return
        s = st["settings"]
        if s["brush"] == "grab":
            drag = self._to_world(x, y, st["depth"]) - self._to_world(*self._to_display(st["center"])[:2], st["depth"])
            new = sculpt.grab(st["base"], st["center"], drag, s["radius"], s["falloff"], s["strength"],
                              mesh=self.mesh, symmetric=s["symmetric"], reference=st["base"])
            base_offset = np.zeros_like(st["base"]) if st["old"] is None else st["old"]
            self.document.set_edit_offset(base_offset + (new - st["base"]))
            st["changed"] = True
            self._show_cursor(st["center"] + drag)
        else:
            hit = self.viewport.pick(int(x), int(y))
            if hit is not None:
                self._dab(hit[1])
                self._show_cursor(hit[1])

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
        plotter = self.viewport.plotter
        if center is None or not self._active():
            self._hide_cursor()
            return
        import pyvista as pv
        r = self.panel.radius.value()
        if self._cursor is None:
            sphere = pv.Sphere(radius=1.0, theta_resolution=16, phi_resolution=9)
            self._cursor_unit = np.asarray(sphere.points, dtype=np.float64)
            self._cursor = (sphere, plotter.add_mesh(sphere, name="brush_cursor", style="wireframe",
                                                     color=(1.0, 0.75, 0.3), opacity=0.3, line_width=1,
                                                     pickable=False, reset_camera=False, lighting=False))
        sphere, actor = self._cursor
        sphere.points = (self._cursor_unit * r + np.asarray(center, dtype=np.float64)).astype(np.float32)
        actor.SetVisibility(True)
        self.viewport.render()

    def update_cursor_radius(self) -> None:
        if self._cursor is not None and self._cursor[1].GetVisibility():
            pts = np.asarray(self._cursor[0].points, dtype=np.float64)
            self._show_cursor(pts.mean(axis=0))

    def _hide_cursor(self) -> None:
        if self._cursor is not None and self._cursor[1].GetVisibility():
            self._cursor[1].SetVisibility(False)
            self.viewport.render()
