"""The timeline under the viewport: a ruler with key ticks and a playhead (click or drag to scrub), play/pause,
Set key / Remove key, interpolation (linear or smooth), frame rate and length. It shows state and emits
requests; app.keyframe_controller does the work."""
from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets


class TimelineRuler(QtWidgets.QWidget):
    """Time axis [0, duration] with key diamonds and the current time; press/drag scrubs."""

    scrubbed = QtCore.Signal(float)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setMinimumHeight(34)
        self.setSizePolicy(QtWidgets.QSizePolicy.Expanding, QtWidgets.QSizePolicy.Fixed)
        self.setToolTip("Click or drag to scrub; diamonds are keys")
        # paintEvent fills the whole ruler: Qt need not paint the dock and the window beneath the playhead's columns
        # first, on every frame of playback (~0.2 ms a frame under Xvfb)
        self.setAttribute(QtCore.Qt.WA_OpaquePaintEvent)
        self.duration = 2.0
        self.fps = 24.0
        self.time = 0.0
        self.keys: list[float] = []
        self.margin = 10
        self._backdrop: tuple[tuple, QtGui.QPixmap] | None = None   # (what it shows, the ruler without its playhead)

    def set_state(self, time: float, duration: float, fps: float, keys: list[float]) -> None:
        """Show this state; when only the time moved (playback, scrubbing), only the playhead's old and new
        columns are repainted, not the ruler."""
        new = (max(float(duration), 1e-3), float(fps), list(keys))
        moved_only = new == (self.duration, self.fps, self.keys)
        old_x = self.x_of(self.time)
        self.time = float(time)
        if not moved_only:
            self.duration, self.fps, self.keys = new
            self.update()
            return
        for x in (old_x, self.x_of(self.time)):
            self.update(QtCore.QRect(int(x) - 3, 0, 7, self.height()))   # the playhead's 2 px line, antialiased

    def x_of(self, t: float) -> float:
        return self.margin + (self.width() - 2 * self.margin) * (t / self.duration)

    def time_at(self, x: float) -> float:
        t = (x - self.margin) / max(self.width() - 2 * self.margin, 1) * self.duration
        t = min(max(t, 0.0), self.duration)
        return round(t * self.fps) / self.fps  # snap to frames

    def _ruler_without_playhead(self) -> QtGui.QPixmap:
        """The ruler's background, ticks, times and key diamonds, drawn once for its size and state: a playback
        frame repaints only the playhead's columns, and copying them from here is ~10x cheaper than drawing the
        ruler's ~30 shapes again in Python (clipped to those columns) every frame."""
        dpr = self.devicePixelRatioF()
        key = (self.width(), self.height(), dpr, self.duration, self.fps, tuple(self.keys), self.font().key())
        if self._backdrop is None or self._backdrop[0] != key:
            pixmap = QtGui.QPixmap(max(1, round(self.width() * dpr)), max(1, round(self.height() * dpr)))
            pixmap.setDevicePixelRatio(dpr)
            p = QtGui.QPainter(pixmap)
            p.setFont(self.font())
            self._draw_ruler(p)
            p.end()
            self._backdrop = (key, pixmap)
        return self._backdrop[1]

    def _draw_ruler(self, p: QtGui.QPainter) -> None:
        p.setRenderHint(QtGui.QPainter.Antialiasing)
        h = self.height()
        p.fillRect(self.rect(), QtGui.QColor(40, 42, 48))
        p.setPen(QtGui.QColor(120, 120, 130))
        p.drawLine(self.margin, h - 8, self.width() - self.margin, h - 8)
        n_frames = int(round(self.duration * self.fps))
        step = max(1, int(self.fps // 4)) if n_frames < 400 else int(self.fps)
        for f in range(0, n_frames + 1, step):
            x = self.x_of(f / self.fps)
            major = f % int(max(self.fps, 1)) == 0
            p.drawLine(int(x), h - 8, int(x), h - (16 if major else 11))
            if major:   # right of its tick, or left of it where it would run past the end (the last one)
                label = f"{f / self.fps:g}s"
                width = p.fontMetrics().horizontalAdvance(label)
                p.drawText(int(x) + 2 if int(x) + 2 + width <= self.width() else int(x) - 2 - width, 12, label)
        p.setPen(QtCore.Qt.NoPen)
        p.setBrush(QtGui.QColor(250, 200, 60))
        for t in self.keys:
            x = self.x_of(t)
            y = h - 8
            p.drawPolygon(QtGui.QPolygonF([QtCore.QPointF(x, y - 6), QtCore.QPointF(x + 5, y),
                                           QtCore.QPointF(x, y + 6), QtCore.QPointF(x - 5, y)]))

    def paintEvent(self, _event) -> None:
        p = QtGui.QPainter(self)
        p.drawPixmap(0, 0, self._ruler_without_playhead())   # clipped to the repainted columns
        p.setRenderHint(QtGui.QPainter.Antialiasing)
        p.setPen(QtGui.QPen(QtGui.QColor(255, 80, 80), 2))
        x = self.x_of(self.time)
        p.drawLine(int(x), 0, int(x), self.height())
        p.end()

    def mousePressEvent(self, event) -> None:
        self.scrubbed.emit(self.time_at(event.position().x()))

    def mouseMoveEvent(self, event) -> None:
        if event.buttons() & QtCore.Qt.LeftButton:
            self.scrubbed.emit(self.time_at(event.position().x()))


class TimelinePanel(QtWidgets.QWidget):
    time_changed = QtCore.Signal(float)
    play_toggled = QtCore.Signal(bool)
    set_key_requested = QtCore.Signal()
    key_step_requested = QtCore.Signal(int)   # go to the next (1) or previous (-1) key
    remove_key_requested = QtCore.Signal()
    interpolation_changed = QtCore.Signal(str)
    fps_changed = QtCore.Signal(float)
    duration_changed = QtCore.Signal(float)
    export_csv_requested = QtCore.Signal()
    export_pc2_requested = QtCore.Signal()

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 2)
        self.play = QtWidgets.QToolButton()
        self.play.setText("▶")
        self.play.setCheckable(True)
        self.play.setToolTip("Play / pause the keyed animation (Space)")
        self.play.toggled.connect(self._play_toggled)
        self.set_key = QtWidgets.QPushButton("Set key")
        self.set_key.setToolTip("Key the current pose at the current time (S); while the Graph Editor is shown "
                                "with shapes selected, only those shapes")
        self.set_key.clicked.connect(self.set_key_requested)
        self.remove_key = QtWidgets.QPushButton("Remove key")
        self.remove_key.setToolTip("Remove the key at the current time")
        self.remove_key.clicked.connect(self.remove_key_requested)
        self.ruler = TimelineRuler(self)
        self.ruler.scrubbed.connect(self.time_changed)
        self.time_label = QtWidgets.QLabel("0.000 s")
        self.time_label.setMinimumWidth(110)
        self.time_label.setAutoFillBackground(True)   # opaque: a new text each frame repaints it alone, not the window
        self.interp = QtWidgets.QComboBox()
        self.interp.addItem("Smooth", "smooth")
        self.interp.addItem("Linear", "linear")
        self.interp.setToolTip("Interpolation between keys: smooth (Catmull–Rom, C¹) or linear")
        self.interp.currentIndexChanged.connect(lambda _: self.interpolation_changed.emit(self.interp.currentData()))
        self.fps = QtWidgets.QDoubleSpinBox()
        self.fps.setRange(1.0, 240.0)
        self.fps.setDecimals(2)
        self.fps.setValue(24.0)
        self.fps.setSuffix(" fps")
        self.fps.setKeyboardTracking(False)
        self.fps.setToolTip("Frame rate of playback and export")
        self.fps.valueChanged.connect(self.fps_changed)
        self.duration = QtWidgets.QDoubleSpinBox()
        self.duration.setRange(0.1, 3600.0)
        self.duration.setValue(2.0)
        self.duration.setSuffix(" s")
        self.duration.setKeyboardTracking(False)
        self.duration.setToolTip("Length of the timeline")
        self.duration.valueChanged.connect(self.duration_changed)
        self.export_csv = QtWidgets.QPushButton("CSV…")
        self.export_csv.setToolTip("Export the keyed animation's weights per frame as CSV")
        self.export_csv.clicked.connect(self.export_csv_requested)
        self.export_pc2 = QtWidgets.QPushButton("PC2…")
        self.export_pc2.setToolTip("Export the keyed animation as a PC2 point cache")
        self.export_pc2.clicked.connect(self.export_pc2_requested)
        self.previous_key = QtWidgets.QToolButton()
        self.previous_key.setText("◆◀")
        self.previous_key.setToolTip("Go to the previous key (,)")
        self.previous_key.clicked.connect(lambda: self.key_step_requested.emit(-1))
        self.next_key = QtWidgets.QToolButton()
        self.next_key.setText("▶◆")
        self.next_key.setToolTip("Go to the next key (.)")
        self.next_key.clicked.connect(lambda: self.key_step_requested.emit(1))
        for wdg in (self.play, self.previous_key, self.next_key, self.set_key, self.remove_key):
            lay.addWidget(wdg)
        lay.addWidget(self.ruler, 1)
        for wdg in (self.time_label, self.interp, self.fps, self.duration, self.export_csv, self.export_pc2):
            lay.addWidget(wdg)
        # one row of controls, never taller: when the Mocap Views or the Graph Editor above it closes, the height
        # they had goes back to the viewport, not to an empty timeline with its controls floating in the middle
        self.setSizePolicy(QtWidgets.QSizePolicy.Preferred, QtWidgets.QSizePolicy.Fixed)

    def _fit_time_label(self, duration: float, fps: float) -> None:
        """Fix the time readout's size to its longest text for this animation (the last frame, on a key). A
        label whose size may change asks its layout to redo the whole row on every ``setText``: ~1 ms CPU a
        playback frame under Xvfb; one of fixed size repaints only itself."""
        widest = f"{duration:.3f} s · frame {int(round(duration * fps))} ◆"
        if widest != getattr(self, "_widest_time", None):
            self._widest_time = widest
            label = self.time_label
            label.setFixedSize(max(110, label.fontMetrics().horizontalAdvance(widest) + 8), label.sizeHint().height())

    def _play_toggled(self, on: bool) -> None:
        self.play.setText("❚❚" if on else "▶")
        self.play_toggled.emit(on)

    def set_playing(self, on: bool) -> None:
        self.play.blockSignals(True)
        self.play.setChecked(on)
        self.play.setText("❚❚" if on else "▶")
        self.play.blockSignals(False)

    def set_state(self, time: float, duration: float, fps: float, keys: list[float], interpolation: str) -> None:
        for wdg in (self.fps, self.duration, self.interp):
            wdg.blockSignals(True)
        # unchanged values are not set again: a spin box repaints on every setValue (each playback frame)
        if self.fps.value() != round(fps, self.fps.decimals()):
            self.fps.setValue(fps)
        if self.duration.value() != round(duration, self.duration.decimals()):
            self.duration.setValue(duration)
        if self.interp.currentData() != interpolation:
            self.interp.setCurrentIndex(max(0, self.interp.findData(interpolation)))
        for wdg in (self.fps, self.duration, self.interp):
            wdg.blockSignals(False)
        frame = int(round(time * fps))
        on_key = any(abs(k - time) < 1e-6 for k in keys)
        self._fit_time_label(duration, fps)
        self.time_label.setText(f"{time:.3f} s · frame {frame}" + (" ◆" if on_key else ""))
        self.remove_key.setEnabled(on_key)
        self.ruler.set_state(time, duration, fps, keys)
