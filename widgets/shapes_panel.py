"""The Shapes panel, like Maya's Shape Editor: a slider and a number box per shape, a name filter,
reset, and presets. It shows weights and emits the user's gestures; the app turns them into undo steps.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

SLIDER_STEPS = 1000


class _ShapeRow(QtWidgets.QWidget):
    def __init__(self, index: int, name: str, panel: "ShapesPanel") -> None:
        super().__init__(panel)
        self.index, self.name, self.panel = index, name, panel
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(2, 0, 2, 0)
        self.label = QtWidgets.QLabel(name)
        self.label.setMinimumWidth(120)
        self.label.setMaximumWidth(170)
        self.label.setToolTip(f"{name} (right-click: mirror it to the other side)")
        self.slider = QtWidgets.QSlider(QtCore.Qt.Horizontal)
        self.slider.setRange(0, SLIDER_STEPS)
        self.slider.setToolTip(f"Weight of {name}: drag to pose (one drag is one undo step)")
        self.slider.setObjectName(f"slider_{name}")
        self.box = QtWidgets.QDoubleSpinBox()
        self.box.setRange(0.0, 1.0)
        self.box.setDecimals(3)
        self.box.setSingleStep(0.05)
        self.box.setKeyboardTracking(False)
        self.box.setFixedWidth(72)
        self.box.setToolTip(f"Weight of {name} (0 to 1)")
        lay.addWidget(self.label)
        lay.addWidget(self.slider, 1)
        lay.addWidget(self.box)
        self._dragging = False
        self._bold = False
        self.label.setContextMenuPolicy(QtCore.Qt.CustomContextMenu)
        self.label.customContextMenuRequested.connect(self._menu)
        self.slider.sliderPressed.connect(self._pressed)
        self.slider.sliderReleased.connect(self._released)
        self.slider.valueChanged.connect(self._slider_moved)
        self.box.valueChanged.connect(self._box_changed)

    def set_value(self, value: float) -> None:
        for w in (self.slider, self.box):
            w.blockSignals(True)
        self.slider.setValue(int(round(value * SLIDER_STEPS)))
        self.box.setValue(value)
        for w in (self.slider, self.box):
            w.blockSignals(False)
        active = value > 0
        if active != self._bold:  # style sheets are slow: only touch the label when it changes
            self._bold = active
            self.label.setStyleSheet("font-weight: bold;" if active else "")

    def _menu(self, pos) -> None:
        menu = QtWidgets.QMenu(self)
        act = menu.addAction("Mirror to the Other Side")
        act.setToolTip("Make (or replace) the other side's shape as this one's mirror image across x = 0")
        act.triggered.connect(lambda: self.panel.mirror_shape_requested.emit(self.index))
        menu.popup(self.label.mapToGlobal(pos))

    def _pressed(self) -> None:
        self._dragging = True
        (self.panel.routed_drag_started if self.panel.routed else self.panel.drag_started).emit(self.index)

    def _released(self) -> None:
        self._dragging = False
        (self.panel.routed_drag_finished if self.panel.routed else self.panel.drag_finished).emit(self.index)

    def _slider_moved(self, v: int) -> None:
        value = v / SLIDER_STEPS
        self.box.blockSignals(True)
        self.box.setValue(value)
        self.box.blockSignals(False)
        if self._dragging:
            self.panel._emit_dragged(self.index, value)
        else:  # keyboard, wheel or a click on the groove: one step each
            self.panel._emit_committed(self.index, value)

    def _box_changed(self, value: float) -> None:
        self.panel._emit_committed(self.index, float(value))


class ShapesPanel(QtWidgets.QWidget):
    """Sliders for every shape. Signals carry (shape index, weight)."""

    drag_started = QtCore.Signal(int)
    weight_dragged = QtCore.Signal(int, float)    # live during a drag: not an undo step by itself
    drag_finished = QtCore.Signal(int)
    weight_committed = QtCore.Signal(int, float)  # a complete edit: one undo step
    reset_requested = QtCore.Signal()
    preset_requested = QtCore.Signal(str)
    mirror_shape_requested = QtCore.Signal(int)   # make the other side's shape from this one (right-click)
    # The same gestures while the pose is regional (set_target(..., routed=True)): the marker controller
    # turns them into edits of the selected region's weights (or of every region).
    routed_drag_started = QtCore.Signal(int)
    routed_weight_dragged = QtCore.Signal(int, float)
    routed_drag_finished = QtCore.Signal(int)
    routed_weight_committed = QtCore.Signal(int, float)
    routed_reset_requested = QtCore.Signal()
    routed_preset_requested = QtCore.Signal(str)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setMinimumWidth(400)
        lay = QtWidgets.QVBoxLayout(self)
        self.routed = False
        self.target = QtWidgets.QLabel("Editing the global pose")
        self.target.setWordWrap(True)
        self.target.setToolTip("Which weights the sliders edit: the global pose, or one region's weights of a "
                               "regional pose (select the region in the Segmentation panel)")
        lay.addWidget(self.target)
        top = QtWidgets.QHBoxLayout()
        self.filter = QtWidgets.QLineEdit()
        self.filter.setPlaceholderText("Filter shapes (e.g. brow, _L)")
        self.filter.setClearButtonEnabled(True)
        self.filter.setToolTip("Show only shapes whose name contains this text (case-insensitive)")
        self.filter.textChanged.connect(self._apply_filter)
        self.active_only = QtWidgets.QCheckBox("Active")
        self.active_only.setToolTip("Show only shapes with a non-zero weight")
        self.active_only.toggled.connect(lambda _: self._apply_filter(self.filter.text()))
        top.addWidget(self.filter, 1)
        top.addWidget(self.active_only)
        lay.addLayout(top)
        row = QtWidgets.QHBoxLayout()
        self.presets = QtWidgets.QComboBox()
        self.presets.setToolTip("Emotion presets: apply a weight set (undoable)")
        self.apply_preset = QtWidgets.QPushButton("Apply")
        self.apply_preset.setToolTip("Set the weights of the selected preset")
        self.apply_preset.clicked.connect(self._preset_clicked)
        self.reset = QtWidgets.QPushButton("Reset all")
        self.reset.setToolTip("Set every weight to 0 (undoable)")
        self.reset.clicked.connect(lambda: (self.routed_reset_requested if self.routed
                                            else self.reset_requested).emit())
        row.addWidget(QtWidgets.QLabel("Preset"))
        row.addWidget(self.presets, 1)
        row.addWidget(self.apply_preset)
        row.addWidget(self.reset)
        lay.addLayout(row)
        self.scroll = QtWidgets.QScrollArea()
        self.scroll.setWidgetResizable(True)
        self._rows_host = QtWidgets.QWidget()
        self._rows_layout = QtWidgets.QVBoxLayout(self._rows_host)
        self._rows_layout.setSpacing(1)
        self._rows_layout.addStretch(1)
        self.scroll.setWidget(self._rows_host)
        lay.addWidget(self.scroll, 1)
        self.rows: list[_ShapeRow] = []
        self._weights = np.zeros(0)

    def set_shapes(self, names: list[str], presets: list[str] | None = None) -> None:
        """One row per shape. The same names and presets keep the rows (a corrective edit also says the
        shapes changed: rebuilding 57 rows then was wasted work and made the panel flicker)."""
        current = [self.presets.itemText(i) for i in range(self.presets.count())]
        if [r.name for r in self.rows] == list(names) and current == list(presets or []):
            return
        for r in self.rows:
            r.setParent(None)
            r.deleteLater()
        self.rows = []
        for i, name in enumerate(names):
            row = _ShapeRow(i, name, self)
            self._rows_layout.insertWidget(i, row)
            self.rows.append(row)
        self.presets.clear()
        self.presets.addItems(presets or [])
        self.presets.setEnabled(bool(presets))
        self.apply_preset.setEnabled(bool(presets))
        self._weights = np.zeros(len(names))
        self._apply_filter(self.filter.text())

    def set_weights(self, weights: np.ndarray) -> None:
        weights = np.asarray(weights, dtype=np.float64)
        changed = np.flatnonzero(weights != self._weights) if weights.shape == self._weights.shape \
            else range(len(self.rows))
        for i in changed:
            self.rows[i].set_value(float(weights[i]))
        self._weights = weights.copy()
        if self.active_only.isChecked():
            self._apply_filter(self.filter.text())

    def row(self, name: str) -> _ShapeRow:
        return next(r for r in self.rows if r.name == name)

    def _apply_filter(self, text: str) -> None:
        text = text.strip().lower()
        only_active = self.active_only.isChecked()
        for r in self.rows:
            visible = text in r.name.lower() and (not only_active or self._weights[r.index] > 0)
            r.setVisible(visible)

    def _preset_clicked(self) -> None:
        if self.presets.currentText():
            (self.routed_preset_requested if self.routed else self.preset_requested).emit(self.presets.currentText())

    def set_target(self, text: str, routed: bool) -> None:
        """Say which weights the sliders edit; ``routed`` sends the gestures to the routed_* signals."""
        self.target.setText(text)
        self.routed = bool(routed)

    def _emit_dragged(self, k: int, value: float) -> None:
        (self.routed_weight_dragged if self.routed else self.weight_dragged).emit(k, value)

    def _emit_committed(self, k: int, value: float) -> None:
        (self.routed_weight_committed if self.routed else self.weight_committed).emit(k, value)
