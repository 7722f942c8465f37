"""The take's marker map on the rig (issue 15 item 2): where each marker is bound on the face, the actor's neutral
markers brought onto the rig by a similarity (Umeyama 1991) with a line to their point, and a map point dragged
along the face to correct it -- one undo step per drag (``app.actor_commands.SetMarkerMapCommand``), kept in the
project with the take and written by Save Map….

The Mocap panel's "Show Map on Rig" turns it on; it uses the viewport's gesture API (a ``ViewportTool``) and
overlays, and is exclusive with marker mode (the marker controller's tool).
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore

from model.errors import RigInputError
from model.marker_map import MarkerMap, calibration_cloud, polygon_point_entry
from widgets.viewport import Gesture, ViewportTool

PICK_RADIUS_PX = 12.0          # a press this close (logical pixels) to a map point grabs it
POINT_COLOR = (1.0, 0.55, 0.1)
DRAGGED_COLOR = (1.0, 0.9, 0.2)
ACTOR_COLOR = (0.35, 0.8, 1.0)
OVERLAY = "marker_map_"


class MapTool(ViewportTool):
    """A press on a map point drags it along the surface under the cursor; the release is one undo step."""

    def __init__(self, editor: "MarkerMapEditor") -> None:
        self.editor = editor

    def press(self, g: Gesture) -> bool:
        if g.button != QtCore.Qt.LeftButton:
            return False
        i = self.editor.point_at(g.x, g.y)
        if i is None:
            return False
        self.editor.begin_drag(i)
        return True

    def drag(self, g: Gesture) -> None:
        hit = g.point
        if hit is not None:
            self.editor.drag_to(hit.face, hit.position)

    def release(self, g: Gesture) -> None:
        self.editor.end_drag()


class MarkerMapEditor(QtCore.QObject):
    """Shows the mocap workspace's marker map on the main viewport and lets its points be dragged."""

    point_moved = QtCore.Signal(str)    # a map point was moved (its label), after the undo step was pushed

    def __init__(self, window, mocap) -> None:
        super().__init__(mocap)
        self.window, self.mocap, self.document, self.viewport = window, mocap, window.document, window.viewport
        self.tool = MapTool(self)
        self.shown = False
        self.labels: list[str] = []
        self.drag: dict | None = None   # {index, label, face, position}
        self._meshes: dict = {}
        self.document.pose_changed.connect(lambda: self.refresh() if self.shown else None)
        window.markers.mode_action.toggled.connect(
            lambda on: mocap.panel.show_map_button.setChecked(False) if on and self.shown else None)

    # --- on and off ----------------------------------------------------------------------------------
    def show(self, on: bool) -> bool:
        if on and self.mocap.marker_map is None:
            self.mocap.panel.show_map_button.setChecked(False)
            self.mocap._error("Show Map on Rig", "Load a marker map or Auto Map the take first.")
            return False
        self.shown = bool(on)
        if on:
            self.window.markers.mode_action.setChecked(False)   # one viewport tool at a time
            self.viewport.push_tool(self.tool)
            self.mocap.panel.set_status("The marker map on the rig: orange points are where the markers are bound, "
                                        "blue the actor's neutral markers aligned to them. Drag a point along the "
                                        "face to correct it (undoable).")
        else:
            self.viewport.remove_tool(self.tool)
            self.drag = None
        self.refresh()
        return True

    def refresh(self) -> None:
        """Redraw the map's points on the surface shown (and the actor's aligned markers)."""
        mm = self.mocap.marker_map
        if not self.shown or mm is None or self.document.project is None:
            self._clear()
            self.window.request_render()
            return
        rig = self.document.rig
        try:
            labels = mm.labels
            B = mm.binding(rig, labels)
        except RigInputError:
            self._clear()
            return
        self.labels = labels
        P = np.asarray(B @ self.document.surface().astype(np.float64))
        if self.drag is not None:
            P[self.drag["index"]] = self.drag["position"]
        actor = self._actor_markers(mm, B)
        self._draw(P, actor)
        self.window.request_render()

    def _actor_markers(self, mm: MarkerMap, B) -> np.ndarray | None:
        """(M, 3) the actor's neutral markers (the panel's neutral frames) in the rig's frame by a similarity to
        their map points; NaN for a marker the take does not have or never shows; None without a take."""
        from solvers.rigid import umeyama
        take = self.mocap.workspace.marker_take
        if take is None:
            return None
        rig = self.document.rig
        st = self.mocap.panel.settings()
        frames: int | slice = int(st["calibration_frames"])
        nf = st.get("neutral_frames")
        if isinstance(nf, str) and ":" in nf:
            try:
                a, b = (int(x) for x in nf.split(":"))
                frames = slice(a, b + 1)
            except ValueError:
                pass
        cloud = calibration_cloud(take, frames, rig.units, allow_unseen=True)
        out = np.full((len(self.labels), 3), np.nan)
        rows = [i for i, lab in enumerate(self.labels) if lab in take.labels]
        if len(rows) < 3:
            return out
        src = cloud[[take.labels.index(self.labels[i]) for i in rows]]
        dst = np.asarray(B @ rig.neutral)[rows]
        ok = np.isfinite(src).all(axis=1)
        if ok.sum() < 3:
            return out
        s, R, t = umeyama(src[ok], dst[ok], scale=True)
        out[np.array(rows)[ok]] = s * src[ok] @ R.T + t
        return out

    # --- drawing --------------------------------------------------------------------------------------
    def _clear(self) -> None:
        for name in list(self._meshes):
            self.viewport.remove_overlay(OVERLAY + name)
        self._meshes.clear()

    def _draw(self, P: np.ndarray, actor: np.ndarray | None) -> None:
        import pyvista as pv
        self._clear()
        if not len(P):
            return
        vp = self.viewport
        pts = pv.PolyData(P.astype(np.float32))
        vp.add_overlay(OVERLAY + "points", pts, color=POINT_COLOR, render_points_as_spheres=True, point_size=11)
        self._meshes["points"] = pts
        if self.drag is not None:
            d = pv.PolyData(P[self.drag["index"]:self.drag["index"] + 1].astype(np.float32))
            vp.add_overlay(OVERLAY + "dragged", d, color=DRAGGED_COLOR, render_points_as_spheres=True, point_size=16)
            self._meshes["dragged"] = d
        if actor is not None:
            ok = np.isfinite(actor).all(axis=1)
            if ok.any():
                A = actor[ok].astype(np.float32)
                a = pv.PolyData(A)
                vp.add_overlay(OVERLAY + "actor", a, color=ACTOR_COLOR, render_points_as_spheres=True, point_size=7)
                self._meshes["actor"] = a
                n = int(ok.sum())
                line = pv.PolyData(np.vstack([P[ok], A]).astype(np.float32))
                line.lines = np.column_stack([np.full(n, 2), np.arange(n), np.arange(n) + n]).reshape(-1)
                vp.add_overlay(OVERLAY + "lines", line, color=(1.0, 1.0, 1.0), line_width=1.5, lighting=False)
                self._meshes["lines"] = line

    def point_positions(self) -> np.ndarray:
        """(M, 3) the map points as drawn (on the surface shown; the dragged one where it is dragged)."""
        m = self._meshes.get("points")
        return np.zeros((0, 3)) if m is None else np.array(m.points, dtype=np.float64)

    # --- dragging -------------------------------------------------------------------------------------
    def point_at(self, x: float, y: float) -> int | None:
        """The map point nearest display pixel (x, y) within the grab radius, or None."""
        P = self.point_positions()
        if not len(P):
            return None
        d = self.viewport.world_to_display(P)
        dist = np.hypot(d[:, 0] - x, d[:, 1] - y)
        i = int(np.argmin(dist))
        return i if dist[i] <= PICK_RADIUS_PX * self.viewport.pixel_ratio() else None

    def begin_drag(self, index: int) -> None:
        P = self.point_positions()
        self.drag = {"index": index, "label": self.labels[index], "face": None, "position": P[index]}
        self.window.show_status(f"Moving marker {self.labels[index]}'s point on the rig…", 0)
        self.refresh()

    def drag_to(self, face: int, position) -> None:
        if self.drag is None:
            return
        self.drag.update(face=int(face), position=np.asarray(position, dtype=np.float64))
        self.refresh()

    def end_drag(self) -> bool:
        """One undo step: the dragged marker bound to the place of the face it was dropped on."""
        from app.actor_commands import SetMarkerMapCommand
        dr, self.drag = self.drag, None
        if dr is None or dr["face"] is None:
            self.refresh()
            return False
        old = self.mocap.marker_map
        rig = self.document.rig
        entry = polygon_point_entry(rig, dr["face"], dr["position"], self.document.surface().astype(np.float64))
        if old.markers.get(dr["label"]) == entry:
            self.refresh()
            return False
        new = MarkerMap(markers={**old.markers, dr["label"]: entry}, rig_units=old.rig_units,
                        take_units=old.take_units, source=old.source, extra=dict(old.extra))
        self.document.undo_stack.push(SetMarkerMapCommand(self.mocap, old, new, f"Move marker {dr['label']} on the rig"))
        where = f"vertex {entry}" if isinstance(entry, int) else f"a point of face {entry['face']}"
        self.window.show_status(f"Marker {dr['label']} is now bound to {where}; solve again to use the map.")
        self.point_moved.emit(dr["label"])
        return True
