"""The Markers panel: marker mode, the hierarchy level drags solve (coarse to fine), λ_r, and the marker
list (background markers flagged). It shows state and emits requests; app.marker_controller does the work."""
from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

from model.markers import DRAG_LAM_REG


class MarkersPanel(QtWidgets.QWidget):
    mode_toggled = QtCore.Signal(bool)
    level_changed = QtCore.Signal(int)
    lam_reg_changed = QtCore.Signal(float)
    remove_requested = QtCore.Signal(str)
    marker_selected = QtCore.Signal(int)   # -1 = none

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        lay = QtWidgets.QVBoxLayout(self)
        self.mode = QtWidgets.QPushButton("Marker mode")
        self.mode.setCheckable(True)
        self.mode.setToolTip("Click the face to add markers, drag them to pose, right-click removes (M)")
        self.mode.toggled.connect(self.mode_toggled)
        lay.addWidget(self.mode)
        form = QtWidgets.QFormLayout()
        self.level = QtWidgets.QComboBox()
        self.level.setToolTip("Which hierarchy level a drag solves: coarse levels (few large regions) first, "
                              "then finer levels refine locally (Joshi §4)")
        self.level.currentIndexChanged.connect(self._level_changed)
        form.addRow("Solve level", self.level)
        self.lam = QtWidgets.QDoubleSpinBox()
        self.lam.setDecimals(4)
        self.lam.setRange(0.0, 10.0)
        self.lam.setSingleStep(0.001)
        self.lam.setValue(DRAG_LAM_REG)
        self.lam.setToolTip("λ_r: how strongly a drag keeps each region near the pose it started from "
                            "(per cm², whatever the rig's units)")
        self.lam.valueChanged.connect(self.lam_reg_changed)
        form.addRow("Stay near pose (λ_r)", self.lam)
        lay.addLayout(form)
        self.hint = QtWidgets.QLabel("No markers yet. Turn on Marker mode (M) and click the face to place "
                                     "markers, then drag one: the weights are solved region by region at the "
                                     "solve level, coarse levels first.")
        self.hint.setWordWrap(True)
        self.hint.setStyleSheet("color: gray;")
        lay.addWidget(self.hint)
        self.list = QtWidgets.QListWidget()
        self.list.setToolTip("Markers on the surface; background markers (no shape moves them) are greyed")
        self.list.currentRowChanged.connect(self.marker_selected)
        lay.addWidget(self.list, 1)
        remove_key = QtGui.QShortcut(QtGui.QKeySequence("Delete"), self.list)   # while the list has the focus
        remove_key.setContext(QtCore.Qt.WidgetShortcut)
        remove_key.setWhatsThis("Remove Marker")
        remove_key.activated.connect(self._remove_clicked)
        row = QtWidgets.QHBoxLayout()
        self.remove = QtWidgets.QPushButton("Remove")
        self.remove.setToolTip("Remove the selected marker (undoable; Delete in the list, or right-click it in "
                               "marker mode)")
        self.remove.clicked.connect(self._remove_clicked)
        row.addWidget(self.remove)
        row.addStretch(1)
        lay.addLayout(row)
        self.status = QtWidgets.QLabel("")
        self.status.setWordWrap(True)
        lay.addWidget(self.status)
        self._updating = False

    def set_mode(self, on: bool) -> None:
        self.mode.blockSignals(True)
        self.mode.setChecked(on)
        self.mode.blockSignals(False)

    def set_levels(self, region_counts: list[int]) -> None:
        """Offer every level; keep the chosen one if it still exists, else default to a middle level."""
        prev = self.current_level()
        self._updating = True
        self.level.clear()
        for i, n in enumerate(region_counts):
            self.level.addItem(f"Level {i}: {n} region{'s' if n != 1 else ''}", i)
        if region_counts:
            pick = prev if prev is not None and prev < len(region_counts) else (len(region_counts) - 1) // 2
            self.level.setCurrentIndex(pick)
        self._updating = False

    def current_level(self) -> int | None:
        data = self.level.currentData()
        return None if data is None else int(data)

    def _level_changed(self, _i: int) -> None:
        if not self._updating and self.current_level() is not None:
            self.level_changed.emit(self.current_level())

    def set_markers(self, names: list[str], background: list[str]) -> None:
        self.list.blockSignals(True)
        cur = self.list.currentRow()
        self.list.clear()
        for n in names:
            item = QtWidgets.QListWidgetItem(n + ("  (background)" if n in background else ""))
            item.setData(QtCore.Qt.UserRole, n)
            if n in background:
                item.setForeground(QtCore.Qt.gray)
                item.setToolTip("No shape moves the surface here: this marker stays pinned")
            self.list.addItem(item)
        if 0 <= cur < len(names):
            self.list.setCurrentRow(cur)
        self.list.blockSignals(False)
        self.remove.setEnabled(bool(names))
        self.hint.setVisible(not names)

    def select_marker(self, index: int) -> None:
        self.list.blockSignals(True)
        self.list.setCurrentRow(index)
        self.list.blockSignals(False)

    def _remove_clicked(self) -> None:
        item = self.list.currentItem()
        if item is not None:
            self.remove_requested.emit(item.data(QtCore.Qt.UserRole))

    def set_status(self, text: str) -> None:
        self.status.setText(text)
