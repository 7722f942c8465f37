"""A small line plot of per-frame curves with a cursor at the current frame (QPainter, no matplotlib).

Used under the mocap views for weight curves and per-frame marker error; clicking or dragging in the plot
asks for that frame (``frame_requested``); given the frames' rate, the time axis is labelled in seconds. The
curves are drawn once into a pixmap (redrawn when they or the size change); moving the cursor during playback
repaints only the two strips it leaves and enters.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

PALETTE = [(230, 120, 60), (90, 170, 230), (120, 200, 110), (220, 90, 160), (230, 200, 80), (160, 130, 230),
           (80, 200, 190), (200, 200, 200)]


TIME_AXIS_PX = 14          # the time axis's labels under the plot
TICK_SPACING_PX = 56       # the least room between two of its labels
TIME_STEPS = (0.05, 0.1, 0.2, 0.25, 0.5, 1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 1800, 3600)


class CurvePlot(QtWidgets.QWidget):
    frame_requested = QtCore.Signal(int)

    def __init__(self, title: str = "", parent=None) -> None:
        super().__init__(parent)
        self._title = title
        self.curves: list[tuple[str, np.ndarray, tuple[int, int, int]]] = []
        self.cursor = 0
        self.n_frames = 0
        self.y_range: tuple[float, float] = (0.0, 1.0)
        self.rate = 0.0        # frames per second: the time axis is labelled in seconds (0: no time axis)
        self._background: QtGui.QPixmap | None = None   # everything but the cursor; redrawn at a new size
        self.setMinimumSize(240, 70)
        self.setSizePolicy(QtWidgets.QSizePolicy.Expanding, QtWidgets.QSizePolicy.Expanding)

    @property
    def title(self) -> str:
        return self._title

    @title.setter
    def title(self, text: str) -> None:
        self._title = text
        self._background = None
        self.update()

    def set_curves(self, curves: list[tuple[str, np.ndarray]], y_range: tuple[float, float] | None = None,
                   rate: float | None = None) -> None:
        """Curves as (name, values (F,)); NaN values leave gaps. The y range defaults to the data's; ``rate`` (frames
        per second) labels the time axis in seconds (None: as before)."""
        if rate is not None:
            self.rate = float(rate)
        self.curves = [(name, np.asarray(v, dtype=np.float64), PALETTE[i % len(PALETTE)])
                       for i, (name, v) in enumerate(curves)]
        self.n_frames = max((c[1].size for c in self.curves), default=0)
        if y_range is None:
            vals = np.concatenate([c[1][np.isfinite(c[1])] for c in self.curves]) if self.curves else np.zeros(0)
            lo, hi = (float(vals.min()), float(vals.max())) if vals.size else (0.0, 1.0)
            lo = min(lo, 0.0)
            y_range = (lo, hi if hi > lo else lo + 1.0)
        self.y_range = y_range
        self._background = None
        self.update()

    def set_cursor(self, frame: int) -> None:
        if frame != self.cursor:
            old = self._cursor_strip()
            self.cursor = int(frame)
            self.update(old)
            self.update(self._cursor_strip())

    def _cursor_strip(self) -> QtCore.QRect:
        r = self._plot_rect()
        x = int(self._x(self.cursor, r))
        return QtCore.QRect(x - 2, int(r.top()) - 1, 5, int(r.height()) + 3)

    # --- geometry ----------------------------------------------------------------------------------
    def _plot_rect(self) -> QtCore.QRectF:
        below = TIME_AXIS_PX if self.rate > 0 else 0   # the seconds under the plot
        return QtCore.QRectF(44, 16, max(10, self.width() - 52), max(10, self.height() - 24 - below))

    def time_ticks(self) -> list[tuple[float, str]]:
        """(x, label) of the time axis: whole steps of seconds at least ``TICK_SPACING_PX`` apart (none without a
        rate). Without them a key or a frame of the curves had no time to read."""
        if self.rate <= 0 or self.n_frames < 2:
            return []
        r = self._plot_rect()
        duration = (self.n_frames - 1) / self.rate
        per_second = r.width() / duration
        step = next((s for s in TIME_STEPS if s * per_second >= TICK_SPACING_PX), TIME_STEPS[-1])
        return [(r.left() + t * per_second, f"{t:g} s") for t in np.arange(0.0, duration + 1e-9, step)]

    def _x(self, frame: float, r: QtCore.QRectF) -> float:
        return r.left() + r.width() * (frame / max(1, self.n_frames - 1))

    def frame_at(self, x: float) -> int:
        r = self._plot_rect()
        f = round((x - r.left()) / r.width() * max(1, self.n_frames - 1))
        return int(np.clip(f, 0, max(0, self.n_frames - 1)))

    # --- painting ----------------------------------------------------------------------------------
    def paintEvent(self, event) -> None:  # Qt override
        if self._background is None or self._background.size() != self.size():
            self._background = QtGui.QPixmap(self.size())
            self._paint_curves(self._background)
        p = QtGui.QPainter(self)
        p.drawPixmap(event.rect(), self._background, event.rect())
        if self.n_frames:
            r = self._plot_rect()
            x = self._x(self.cursor, r)
            p.setPen(QtGui.QPen(QtGui.QColor(255, 255, 255), 1.0))
            p.drawLine(QtCore.QPointF(x, r.top()), QtCore.QPointF(x, r.bottom()))
        p.end()

    def _paint_curves(self, target: QtGui.QPaintDevice) -> None:
        """Frame, axis labels, title, legend and curves: everything but the cursor."""
        p = QtGui.QPainter(target)
        p.setRenderHint(QtGui.QPainter.Antialiasing)
        p.fillRect(self.rect(), QtGui.QColor(32, 33, 38))
        r = self._plot_rect()
        p.setPen(QtGui.QColor(90, 92, 100))
        p.drawRect(r)
        lo, hi = self.y_range
        small = QtGui.QFont(self.font())
        small.setPointSizeF(max(6.0, small.pointSizeF() * 0.8))
        p.setFont(small)
        p.setPen(QtGui.QColor(170, 170, 175))
        p.drawText(QtCore.QPointF(2, r.bottom()), f"{lo:.3g}")
        p.drawText(QtCore.QPointF(2, r.top() + 10), f"{hi:.3g}")
        p.drawText(QtCore.QPointF(r.left(), 12), self.title)
        metrics = p.fontMetrics()
        for x, label in self.time_ticks():
            p.drawLine(QtCore.QPointF(x, r.bottom()), QtCore.QPointF(x, r.bottom() + 3))
            half = metrics.horizontalAdvance(label) / 2
            left = min(max(x - half, 0.0), self.width() - 2 * half - 1)
            p.drawText(QtCore.QPointF(left, r.bottom() + 4 + metrics.ascent()), label)
        x_legend = r.left() + p.fontMetrics().horizontalAdvance(self.title) + 16
        for name, values, color in self.curves:
            pen = QtGui.QPen(QtGui.QColor(*color), 1.4)
            p.setPen(pen)
            if values.size:
                xs = r.left() + r.width() * np.arange(values.size) / max(1, self.n_frames - 1)
                ys = r.bottom() - r.height() * (np.clip(values, lo, hi) - lo) / (hi - lo)
                ok = np.isfinite(ys)
                # one polyline per run of finite samples
                breaks = np.flatnonzero(np.diff(ok.astype(np.int8)) != 0) + 1
                for seg in np.split(np.arange(values.size), breaks):
                    if seg.size > 1 and ok[seg[0]]:
                        p.drawPolyline(QtGui.QPolygonF([QtCore.QPointF(float(xs[i]), float(ys[i])) for i in seg]))
            p.drawText(QtCore.QPointF(x_legend, 12), name)
            x_legend += p.fontMetrics().horizontalAdvance(name) + 12
        p.end()

    # --- scrubbing ---------------------------------------------------------------------------------
    def mousePressEvent(self, event) -> None:  # Qt override
        if self.n_frames:
            self.frame_requested.emit(self.frame_at(event.position().x()))

    def mouseMoveEvent(self, event) -> None:  # Qt override
        if self.n_frames and event.buttons() & QtCore.Qt.LeftButton:
            self.frame_requested.emit(self.frame_at(event.position().x()))
