"""The Shapes panel, like Maya's Shape Editor: a slider and a number box per shape, a name filter,
reset, and presets. It shows weights and emits the user's gestures; the app turns them into undo steps.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

SLIDER_STEPS = 1000


@dataclass(frozen=True)
class PoseEdit:
    """One gesture of the Shapes panel on the pose. ``kind``: "drag-start", "drag" (live during a slider
    drag, not an undo step by itself), "drag-end", "set" (a complete edit of one weight: one undo step),
    "reset" (every weight to 0) or "preset" (apply ``preset``); ``shape`` is the shape index and ``value``
    its weight, for the kinds that have them."""

    kind: str
    shape: int = -1
    value: float = 0.0
    preset: str = ""


class _WheelOnlyWhenFocused:
    """A slider or number box inside a scrolling list: the mouse wheel scrolls the list unless the user clicked
    the control first (a wheel notch over a row changed its weight, one undo step each)."""

    def wheelEvent(self, event) -> None:
        if self.hasFocus():
            super().wheelEvent(event)
        else:
            event.ignore()          # unaccepted: Qt hands it to the scroll area


class _Slider(_WheelOnlyWhenFocused, QtWidgets.QSlider):
    pass


class _UndoShortcutFilter(QtCore.QObject):
    """Lets Edit ▸ Undo/Redo (Ctrl+Z, Ctrl+Shift+Z) reach the window while a number box has focus: its line
    edit would otherwise claim them for its own text undo."""

    def eventFilter(self, obj, event) -> bool:
        if event.type() == QtCore.QEvent.ShortcutOverride and (
                event.matches(QtGui.QKeySequence.Undo) or event.matches(QtGui.QKeySequence.Redo)):
            return True             # not accepted: the shortcut fires
        return False


class _NumberBox(_WheelOnlyWhenFocused, QtWidgets.QDoubleSpinBox):
    _undo_filter: _UndoShortcutFilter | None = None

    def __init__(self) -> None:
        super().__init__()
        if _NumberBox._undo_filter is None:
            _NumberBox._undo_filter = _UndoShortcutFilter()
        self.installEventFilter(_NumberBox._undo_filter)            # the box has the focus, or
        self.lineEdit().installEventFilter(_NumberBox._undo_filter)  # its line edit does


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
        self.slider = _Slider(QtCore.Qt.Horizontal)
        self.slider.setFocusPolicy(QtCore.Qt.StrongFocus)
        self.slider.setRange(0, SLIDER_STEPS)
        self.slider.setToolTip(f"Weight of {name}: drag to pose (one drag is one undo step)")
        self.slider.setObjectName(f"slider_{name}")
        self.box = _NumberBox()
        self.box.setFocusPolicy(QtCore.Qt.StrongFocus)
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
        self.slider.setContextMenuPolicy(QtCore.Qt.CustomContextMenu)   # the slider's menu too (Key <shape>)
        self.slider.customContextMenuRequested.connect(lambda pos: self._menu(pos, self.slider))
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

    def _menu(self, pos, where=None) -> None:
        menu = QtWidgets.QMenu(self)
        key = menu.addAction(f"Key {self.name}")
        key.setToolTip("Key this shape alone at the current time (its own curve in the Graph Editor)")
        key.triggered.connect(lambda: self.panel.key_shape_requested.emit(self.index))
        act = menu.addAction("Mirror to the Other Side")
        act.setToolTip("Make (or replace) the other side's shape as this one's mirror image across x = 0")
        act.triggered.connect(lambda: self.panel.mirror_shape_requested.emit(self.index))
        self.context_menu = menu   # tests pick its actions
        menu.popup((where or self.label).mapToGlobal(pos))

    def _pressed(self) -> None:
        self._dragging = True
        self.panel.pose_edited.emit(PoseEdit("drag-start", self.index))

    def _released(self) -> None:
        self._dragging = False
        self.panel.pose_edited.emit(PoseEdit("drag-end", self.index))

    def _slider_moved(self, v: int) -> None:
        value = v / SLIDER_STEPS
        self.box.blockSignals(True)
        self.box.setValue(value)
        self.box.blockSignals(False)
        # while dragging: live; keyboard, wheel or a click on the groove: one step each
        self.panel.pose_edited.emit(PoseEdit("drag" if self._dragging else "set", self.index, value))

    def _box_changed(self, value: float) -> None:
        self.panel.pose_edited.emit(PoseEdit("set", self.index, float(value)))


class ShapesPanel(QtWidgets.QWidget):
    """Sliders for every shape. Every gesture on the pose is one ``pose_edited(PoseEdit)``; the window turns it
    into an edit of the global pose or, while the pose is regional, of the selected region's weights."""

    pose_edited = QtCore.Signal(object)           # a PoseEdit
    mirror_shape_requested = QtCore.Signal(int)   # make the other side's shape from this one (right-click)
    key_shape_requested = QtCore.Signal(int)      # key this shape alone at the current time (right-click)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setMinimumWidth(400)
        lay = QtWidgets.QVBoxLayout(self)
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
        self.reset.clicked.connect(lambda: self.pose_edited.emit(PoseEdit("reset")))
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
        keep = 0   # rows of the same names in the same places stay (a shape added at the end adds one row)
        while keep < min(len(self.rows), len(names)) and self.rows[keep].name == names[keep]:
            keep += 1
        for r in self.rows[keep:]:
            r.setParent(None)
            r.deleteLater()
        self.rows = self.rows[:keep]
        for i, name in enumerate(names[keep:], start=keep):
            row = _ShapeRow(i, name, self)
            self._rows_layout.insertWidget(i, row)
            self.rows.append(row)
        self.presets.clear()
        self.presets.addItems(presets or [])
        self.presets.setEnabled(bool(presets))
        self.apply_preset.setEnabled(bool(presets))
        self._weights = np.concatenate([self._weights[:keep], np.zeros(len(names) - keep)])  # what the rows show
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
            visible = bool(text in r.name.lower() and (not only_active or self._weights[r.index] > 0))
            if r.isHidden() == visible:   # only the rows that change (setVisible costs ~3 ms a row)
                r.setVisible(visible)

    def _preset_clicked(self) -> None:
        if self.presets.currentText():
            self.pose_edited.emit(PoseEdit("preset", preset=self.presets.currentText()))

    def set_target(self, text: str) -> None:
        """Say which weights the sliders edit (the global pose, a region's weights)."""
        self.target.setText(text)
