"""The Graph Editor, like Maya's: the keyed animation's weight curves, one per shape, with each shape's keys.

The shape list on the left chooses the curves shown (none selected: the shapes that move, at most eight); the
first selected shape is the active curve, its keys drawn large. In the plot, a press on a key selects it and a
drag moves it in time (snapped to frames) and weight; Delete removes the selected key; a press on a curve makes
it the active one; a press elsewhere scrubs. It shows state and emits requests; app.keyframe_controller turns
them into undo steps. The plot is widgets.curve_plot.CurvePlot (the mocap panel's weight curves) with keys.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from model.keyframes import Timeline, shape_curves, shape_value

from .curve_plot import PALETTE, CurvePlot

MAX_AUTO_CURVES = 8
KEY_PICK_PX = 7


class GraphPlot(CurvePlot):
    """CurvePlot with key handles: ``keys`` per shown curve, the selected key, and a drag that moves it."""

    key_selected = QtCore.Signal(int, float)              # shape, time (-1: none)
    key_moved = QtCore.Signal(int, float, float, float)    # shape, old time, new time, new weight
    key_deleted = QtCore.Signal(int, float)               # shape, time
    curve_clicked = QtCore.Signal(int)                    # shape

    def __init__(self, parent=None) -> None:
        super().__init__("Weight curves", parent)
        self.setFocusPolicy(QtCore.Qt.StrongFocus)
        self.setMinimumSize(320, 140)
        self.fps = 24.0
        self.shapes: list[int] = []                        # the shape of each shown curve
        self.keys: dict[int, list[tuple[float, float]]] = {}   # shape -> [(time, weight)]
        self.active: int | None = None                    # the active curve's shape
        self.selected_key: tuple[int, float] | None = None
        self._drag: tuple[int, float, float, float] | None = None   # shape, old time, new time, new weight
        delete = QtGui.QShortcut(QtGui.QKeySequence(QtGui.QKeySequence.Delete), self)
        delete.setContext(QtCore.Qt.WidgetShortcut)      # while the plot has the focus (a click gives it)
        delete.setWhatsThis("Delete the Selected Key (Graph Editor)")
        delete.activated.connect(self.delete_selected_key)

    def set_graph(self, names: list[str], shapes: list[int], curves: np.ndarray, keys: dict, fps: float,
                  y_range: tuple[float, float], active: int | None) -> None:
        self.fps, self.shapes, self.keys, self.active = float(fps), list(shapes), keys, active
        if self.selected_key is not None and not any(abs(t - self.selected_key[1]) < 1e-6
                                                    for t, _ in keys.get(self.selected_key[0], [])):
            self.selected_key = None
        self.set_curves([(names[k], curves[:, i]) for i, k in enumerate(shapes)], y_range, rate=self.fps)

    # --- geometry ------------------------------------------------------------------------------------
    def key_point(self, time: float, value: float) -> QtCore.QPointF:
        r = self._plot_rect()
        lo, hi = self.y_range
        return QtCore.QPointF(self._x(time * self.fps, r), r.bottom() - r.height() * (value - lo) / (hi - lo))

    def value_at(self, y: float) -> float:
        r = self._plot_rect()
        lo, hi = self.y_range
        return float(np.clip(lo + (r.bottom() - y) / r.height() * (hi - lo), lo, hi))

    def key_at(self, pos: QtCore.QPointF) -> tuple[int, float] | None:
        """The key under ``pos`` (the active curve's first), or None."""
        order = sorted(self.keys, key=lambda k: k != self.active)
        for k in order:
            for t, v in self.keys[k]:
                p = self.key_point(t, v)
                if abs(p.x() - pos.x()) <= KEY_PICK_PX and abs(p.y() - pos.y()) <= KEY_PICK_PX:
                    return k, t
        return None

    def curve_at(self, pos: QtCore.QPointF) -> int | None:
        """The shown curve passing within a few pixels of ``pos``, or None."""
        if not self.n_frames:
            return None
        f = self.frame_at(pos.x())
        r = self._plot_rect()
        lo, hi = self.y_range
        best, best_d = None, KEY_PICK_PX
        for k, (_name, values, _c) in zip(self.shapes, self.curves):
            if f < values.size and np.isfinite(values[f]):
                d = abs(r.bottom() - r.height() * (values[f] - lo) / (hi - lo) - pos.y())
                if d <= best_d:
                    best, best_d = k, d
        return best

    # --- painting ------------------------------------------------------------------------------------
    def _paint_curves(self, target: QtGui.QPaintDevice) -> None:
        super()._paint_curves(target)
        p = QtGui.QPainter(target)
        p.setRenderHint(QtGui.QPainter.Antialiasing)
        for i, k in enumerate(self.shapes):
            color = QtGui.QColor(*PALETTE[i % len(PALETTE)])
            active = k == self.active
            if active and i < len(self.curves):   # the active curve drawn again, thicker
                values = self.curves[i][1]
                pts = [self.key_point(f / self.fps, v) for f, v in enumerate(values) if np.isfinite(v)]
                p.setPen(QtGui.QPen(color, 3.0))
                p.drawPolyline(QtGui.QPolygonF(pts))
            for t, v in self.keys.get(k, []):
                if self._drag is not None and self._drag[0] == k and abs(self._drag[1] - t) < 1e-6:
                    t, v = self._drag[2], self._drag[3]
                selected = self.selected_key is not None and self.selected_key[0] == k \
                    and abs(self.selected_key[1] - t) < 1e-6 or (self._drag is not None and self._drag[0] == k
                                                                 and abs(self._drag[2] - t) < 1e-6)
                size = 6.0 if active else 4.0
                p.setPen(QtGui.QPen(QtGui.QColor(255, 255, 255) if selected else QtGui.QColor(20, 20, 24), 1.5))
                p.setBrush(QtGui.QColor(255, 220, 60) if selected else color)
                c = self.key_point(t, v)
                p.drawPolygon(QtGui.QPolygonF([c + QtCore.QPointF(0, -size), c + QtCore.QPointF(size, 0),
                                               c + QtCore.QPointF(0, size), c + QtCore.QPointF(-size, 0)]))
        p.end()

    def _refresh(self) -> None:
        self._background = None
        self.update()

    # --- mouse and keys ------------------------------------------------------------------------------
    def mousePressEvent(self, event) -> None:  # Qt override
        pos = event.position()
        hit = self.key_at(pos) if event.button() == QtCore.Qt.LeftButton else None
        if hit is not None:
            k, t = hit
            self.selected_key = hit
            v = next(v for tk, v in self.keys[k] if abs(tk - t) < 1e-6)
            self._drag = (k, t, t, v)
            self.key_selected.emit(k, t)
            if k != self.active:
                self.curve_clicked.emit(k)
            self._refresh()
            return
        curve = self.curve_at(pos)
        if curve is not None and curve != self.active:
            self.curve_clicked.emit(curve)
            return
        if self.selected_key is not None:
            self.selected_key = None
            self.key_selected.emit(-1, 0.0)
            self._refresh()
        super().mousePressEvent(event)

    def mouseMoveEvent(self, event) -> None:  # Qt override
        if self._drag is not None and event.buttons() & QtCore.Qt.LeftButton:
            k, t0, _t, _v = self._drag
            pos = event.position()
            t = self.frame_at(pos.x()) / self.fps
            self._drag = (k, t0, t, self.value_at(pos.y()))
            self._refresh()
            return
        super().mouseMoveEvent(event)

    def mouseReleaseEvent(self, event) -> None:  # Qt override
        if self._drag is None:
            return
        k, t0, t, v = self._drag
        self._drag = None
        old_v = next(v0 for tk, v0 in self.keys[k] if abs(tk - t0) < 1e-6)
        if abs(t - t0) > 1e-6 or abs(v - old_v) > 1e-9:
            self.selected_key = (k, t)
            self.key_moved.emit(k, t0, t, v)
        self._refresh()

    def delete_selected_key(self) -> None:
        if self.selected_key is not None:
            k, t = self.selected_key
            self.selected_key = None
            self.key_deleted.emit(k, t)


class GraphEditor(QtWidgets.QWidget):
    time_requested = QtCore.Signal(float)
    key_moved = QtCore.Signal(int, float, float, float)   # shape, old time, new time, new weight
    key_deleted = QtCore.Signal(int, float)              # shape, time
    selection_changed = QtCore.Signal(list)              # the selected shapes

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.shape_names: list[str] = []
        self._timeline: Timeline | None = None
        self._times = np.zeros(0)
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        left = QtWidgets.QVBoxLayout()
        self.filter = QtWidgets.QLineEdit()
        self.filter.setPlaceholderText("Filter shapes…")
        self.filter.setClearButtonEnabled(True)
        self.filter.textChanged.connect(self._apply_filter)
        self.list = QtWidgets.QListWidget()
        self.list.setSelectionMode(QtWidgets.QAbstractItemView.ExtendedSelection)
        self.list.setToolTip("The shapes whose curves are shown (none selected: the shapes that move). With the "
                             "Graph Editor shown, S keys only the selected shapes; , and . go to their keys.")
        self.list.itemSelectionChanged.connect(lambda: self.selection_changed.emit(self.selected_shapes()))
        self.list.setMaximumWidth(220)
        left.addWidget(self.filter)
        left.addWidget(self.list, 1)
        self.plot = GraphPlot(self)
        self.plot.setToolTip("Drag a key to move it in time and weight; Delete removes the selected key; "
                             "click a curve to make it the active one, elsewhere to scrub")
        self.plot.frame_requested.connect(lambda f: self.time_requested.emit(f / self.plot.fps))
        self.plot.key_moved.connect(self.key_moved)
        self.plot.key_deleted.connect(self.key_deleted)
        self.plot.curve_clicked.connect(self._curve_clicked)
        lay.addLayout(left)
        lay.addWidget(self.plot, 1)

    # --- state ---------------------------------------------------------------------------------------
    def set_shapes(self, names: list[str]) -> None:
        self.shape_names = list(names)
        self.list.blockSignals(True)
        self.list.clear()
        self.list.addItems(self.shape_names)
        self.list.blockSignals(False)
        self._apply_filter(self.filter.text())

    def selected_shapes(self) -> list[int]:
        return sorted(self.list.row(item) for item in self.list.selectedItems())

    def select_shapes(self, shapes: list[int]) -> None:
        """Select these shapes' curves (the first one active), as clicks in the list would."""
        self.list.clearSelection()
        for k in shapes:
            self.list.item(k).setSelected(True)
        if shapes:
            self.list.setCurrentRow(shapes[0], QtCore.QItemSelectionModel.NoUpdate)

    def _curve_clicked(self, k: int) -> None:
        shown = self.plot.shapes
        self.select_shapes([k] + [s for s in shown if s != k] if self.selected_shapes() else [k])

    def _apply_filter(self, text: str) -> None:
        text = text.strip().lower()
        for i in range(self.list.count()):
            item = self.list.item(i)
            item.setHidden(bool(text) and text not in item.text().lower())

    def set_animation(self, timeline: Timeline, times: np.ndarray) -> None:
        """Show ``timeline``'s curves sampled at ``times`` (seconds, one per frame) with each shape's keys."""
        self._timeline, self._times = timeline, np.asarray(times, dtype=np.float64)
        fps = 1.0 / (times[1] - times[0]) if len(times) > 1 else 24.0
        selected = self.selected_shapes()
        K = len(self.shape_names)
        if not timeline.keys or not K:
            self.plot.set_graph(self.shape_names, [], np.zeros((len(times), 0)), {}, fps, (0.0, 1.0), None)
            self.plot.title = "Weight curves: no keys yet (S keys the pose)"
            return
        W = shape_curves(timeline, self._times)
        shapes = selected
        if not shapes:   # the shapes that move or have keys of their own, at most a few
            moving = np.ptp(W, axis=0) > 1e-6
            own = np.zeros(K, dtype=bool)
            for key in timeline.keys:
                if key.keyed is not None:
                    own |= key.keyed
            shapes = list(np.flatnonzero(moving | own)[:MAX_AUTO_CURVES])
        keys = {k: [(key.time, shape_value(key.weights, k)) for key in timeline.shape_keys(k)] for k in shapes}
        lo, hi = min(timeline.lower, float(W.min())), max(timeline.upper, float(W.max()))
        active = self.list.currentRow() if self.list.currentRow() in shapes and selected else \
            (shapes[0] if shapes else None)
        self.plot.set_graph(self.shape_names, shapes, W[:, shapes], keys, fps, (lo, hi), active)
        self.plot.title = "Weight curves" if selected else "Weight curves (the shapes that move)"

    def set_time(self, t: float) -> None:
        self.plot.set_cursor(int(round(t * self.plot.fps)))
