"""The Segmentation panel: view and map choice, threshold, clean-up, overlap, hierarchy level, method,
the region list, and the region nudge. It shows state and emits requests; the app does the work."""
from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

from model.wording import count
from widgets.length_box import show_length_in

VIEW_LABELS = [("shaded", "Shaded"), ("deformation", "Deformation map"),
               ("deformation-rgb", "Deformation vector (RGB)"), ("segmentation", "Segmentation")]
# (map kind, per-shape normalisation, label) of the map choice
MAP_CHOICES = [("laplacian+displacement", True, "Bends or moves, each shape"),   # the default
               ("laplacian", True, "Laplacian ‖L d‖, each shape"),
               ("laplacian", False, "Laplacian ‖L d‖, raw maximum (Joshi)"),
               ("displacement", True, "Displacement ‖d‖, each shape"),
               ("displacement", False, "Displacement ‖d‖, raw maximum (Acosta)")]


class SegmentationPanel(QtWidgets.QWidget):
    view_changed = QtCore.Signal(str)
    shape_map_changed = QtCore.Signal(int)          # -1 = combined (max over shapes)
    settings_previewed = QtCore.Signal(dict)        # live while dragging the threshold
    settings_committed = QtCore.Signal(dict)        # one undo step
    level_changed = QtCore.Signal(int)
    region_selected = QtCore.Signal(int)            # -1 = none
    nudge_requested = QtCore.Signal(str, float)     # direction ('out','in','up','down','left','right'), amount
    save_nudge_requested = QtCore.Signal()

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self._settings: dict = {}
        self._updating = False
        self._counts: list[int] = []   # regions per level of the segmentation shown
        form = QtWidgets.QFormLayout()
        self.view = QtWidgets.QComboBox()
        for key, label in VIEW_LABELS:
            self.view.addItem(label, key)
        self.view.setToolTip("What the viewport colours: the plain surface, where the shapes deform "
                             "(Laplacian of the displacement, Joshi §2), or the regions")
        self.view.currentIndexChanged.connect(lambda _: self.view_changed.emit(self.view.currentData()))
        form.addRow("View", self.view)
        self.map_kind = QtWidgets.QComboBox()
        for key, normalise, label in MAP_CHOICES:
            self.map_kind.addItem(label, (key, normalise))
        self.map_kind.setToolTip("The map that is thresholded. 'Each shape' divides every shape's map by its own "
                                 "high quantile before the maximum, so broad smooth shapes (a brow raise) count "
                                 "as much as sharp ones (lips, lids); 'raw maximum' is Joshi's map as published")
        self.map_kind.currentIndexChanged.connect(self._commit)
        form.addRow("Map", self.map_kind)
        self.shape = QtWidgets.QComboBox()
        self.shape.setToolTip("Show the combined map (max over shapes) or one shape's map")
        self.shape.currentIndexChanged.connect(lambda i: self.shape_map_changed.emit(i - 1))
        form.addRow("Shape", self.shape)
        self.method = QtWidgets.QComboBox()
        self.method.addItem("Threshold (Joshi)", "threshold")
        self.method.addItem("Region growing (Acosta)", "region-growing")
        self.method.setToolTip("How regions are found")
        self.method.currentIndexChanged.connect(self._commit)
        form.addRow("Method", self.method)
        self.separate = QtWidgets.QComboBox()
        self.separate.addItem("Follow the region moving them", "follow")
        self.separate.addItem("Stay in the background", "background")
        self.separate.setToolTip("Separate meshes of the rig (eyeballs, teeth, tongue, eyelashes): join the skin "
                                 "region whose shapes move them, or stay out of every region")
        self.separate.currentIndexChanged.connect(self._commit)
        form.addRow("Separate meshes", self.separate)

        t_row = QtWidgets.QHBoxLayout()
        self.t_slider = QtWidgets.QSlider(QtCore.Qt.Horizontal)
        self.t_slider.setRange(0, 1000)
        self.t_slider.setToolTip("Threshold quantile t: vertices whose map value is above the t-quantile deform; "
                                 "higher t gives smaller, more local regions")
        self.t_box = QtWidgets.QDoubleSpinBox()
        self.t_box.setRange(0.0, 1.0)
        self.t_box.setDecimals(3)
        self.t_box.setSingleStep(0.01)
        self.t_box.setKeyboardTracking(False)
        self.t_box.setToolTip(self.t_slider.toolTip())
        t_row.addWidget(self.t_slider, 1)
        t_row.addWidget(self.t_box)
        form.addRow("Threshold t", t_row)
        self.t_slider.sliderMoved.connect(self._t_dragged)
        self.t_slider.sliderReleased.connect(self._commit)
        self.t_slider.valueChanged.connect(self._t_slider_value)
        self.t_box.valueChanged.connect(self._t_box_value)

        self.min_size = QtWidgets.QSpinBox()
        self.min_size.setRange(0, 100000)
        self.min_size.setSuffix(" vertices")
        self.min_size.setToolTip("Regions smaller than this are absorbed by the neighbour they share most boundary with")
        self.min_size.setKeyboardTracking(False)
        self.min_size.valueChanged.connect(self._commit)
        form.addRow("Min region", self.min_size)
        self.overlap = QtWidgets.QSpinBox()
        self.overlap.setRange(0, 10)
        self.overlap.setSuffix(" rings")
        self.overlap.setToolTip("Each region grows this many vertex rings into its neighbours, so solves blend without seams")
        self.overlap.valueChanged.connect(self._commit)
        form.addRow("Overlap", self.overlap)

        lvl_row = QtWidgets.QHBoxLayout()
        self.level = QtWidgets.QSlider(QtCore.Qt.Horizontal)
        self.level.setRange(0, 0)
        self.level.setToolTip("Hierarchy level: 0 is the finest; the top level is one region (the global solve)")
        self.level.setPageStep(1)
        self.level_label = QtWidgets.QLabel("–")
        self.level_label.setMinimumWidth(110)
        lvl_row.addWidget(self.level, 1)
        lvl_row.addWidget(self.level_label)
        self.level.valueChanged.connect(self.level_changed)
        form.addRow("Level", lvl_row)
        self.status = QtWidgets.QLabel("")
        self.status.setStyleSheet("color: gray;")
        # a failure is a sentence: wrapped in the panel's width, it never widens the panel past its dock
        self.status.setWordWrap(True)
        form.addRow(self.status)   # the whole row: its sentence wraps less

        self.regions = QtWidgets.QTreeWidget()
        self.regions.setHeaderLabels(["Region", "Vertices", "Most active shapes"])
        self.regions.setRootIsDecorated(False)
        self.regions.setToolTip("Click a region to highlight it (or click it in the viewport)")
        self.regions.itemSelectionChanged.connect(self._region_clicked)
        self.regions.setMinimumHeight(160)

        nudge = QtWidgets.QGroupBox("Nudge selected region (Acosta)")
        ng = QtWidgets.QGridLayout(nudge)
        self.nudge_amount = QtWidgets.QDoubleSpinBox()
        self.nudge_amount.setRange(0.001, 10.0)
        self.nudge_amount.setDecimals(3)
        self.nudge_amount.setValue(0.1)
        self.nudge_amount.setToolTip("Distance of one nudge, in rig units (1 mm at first, whatever the units)")
        ng.addWidget(QtWidgets.QLabel("Step"), 0, 0)
        ng.addWidget(self.nudge_amount, 0, 1, 1, 2)
        buttons = [("Out", "out", "Ctrl+Shift+="), ("In", "in", "Ctrl+Shift+-"), ("Up", "up", "Ctrl+Shift+Up"),
                   ("Down", "down", "Ctrl+Shift+Down"), ("Left", "left", "Ctrl+Shift+Left"),
                   ("Right", "right", "Ctrl+Shift+Right")]
        self.nudge_buttons = {}
        for i, (label, key, shortcut) in enumerate(buttons):
            b = QtWidgets.QPushButton(label)
            b.setToolTip(f"Nudge the region {key} ({shortcut}); undoable")
            b.clicked.connect(lambda _=False, k=key: self.nudge_requested.emit(k, self.nudge_amount.value()))
            sc = QtGui.QShortcut(QtGui.QKeySequence(shortcut), self)
            sc.setContext(QtCore.Qt.WindowShortcut)
            sc.setWhatsThis(f"Nudge Region {label}")   # its name in Help ▸ Keyboard Shortcuts
            sc.activated.connect(lambda k=key: self.nudge_requested.emit(k, self.nudge_amount.value()))
            ng.addWidget(b, 1 + i // 3, i % 3)
            self.nudge_buttons[key] = b
        self.save_shape = QtWidgets.QPushButton("Save as new shape…")
        self.save_shape.setToolTip("Store the nudged surface as a new shape (undoable)")
        self.save_shape.clicked.connect(self.save_nudge_requested)
        ng.addWidget(self.save_shape, 3, 0, 1, 3)

        lay = QtWidgets.QVBoxLayout(self)
        lay.addLayout(form)
        lay.addWidget(self.regions, 1)
        lay.addWidget(nudge)

    # --- state in ----------------------------------------------------------------------------------
    def set_units(self, units: str) -> None:
        """Lengths (the nudge step) are in the rig's units: show them, the step kept the same physical length."""
        show_length_in(self.nudge_amount, units)

    def set_shapes(self, names: list[str], keep_place: bool = False) -> None:
        """List ``names`` in the Shape choice, the shape chosen kept: at its place when ``keep_place`` (the same
        shapes renamed, or one added at the end), else by its name; the combined map when it is gone."""
        i, name = self.shape.currentIndex(), self.shape.currentText()
        self.shape.blockSignals(True)
        self.shape.clear()
        self.shape.addItem("All shapes (max)")
        self.shape.addItems(names)
        if i > 0 and not (keep_place and i <= len(names)):
            i = names.index(name) + 1 if name in names else 0
        self.shape.setCurrentIndex(max(i, 0))
        self.shape.blockSignals(False)

    def shape_choice(self) -> int:
        """The shape whose map is chosen, -1 for the combined map (max over shapes)."""
        return self.shape.currentIndex() - 1

    def set_settings(self, settings: dict) -> None:
        self._settings = dict(settings)
        self._updating = True
        try:
            choice = (settings["map_kind"], bool(settings.get("normalise", True)))
            self.map_kind.setCurrentIndex(next((i for i, (k, n, _) in enumerate(MAP_CHOICES) if (k, n) == choice), 0))
            self.separate.setCurrentIndex(max(0, self.separate.findData(settings.get("separate_meshes", "follow"))))
            self.method.setCurrentIndex(max(0, self.method.findData(settings["method"])))
            self.t_slider.setValue(int(round(settings["t"] * 1000)))
            self.t_box.setValue(settings["t"])
            self.min_size.setValue(settings["min_region_size"])
            self.overlap.setValue(settings["overlap_rings"])
        finally:
            self._updating = False

    def set_levels(self, region_counts: list[int], level: int) -> None:
        self.level.blockSignals(True)
        self.level.setRange(0, max(0, len(region_counts) - 1))
        self.level.setValue(min(level, len(region_counts) - 1))
        self.level.blockSignals(False)
        self._counts = region_counts
        self._update_level_label()

    def _update_level_label(self) -> None:
        counts = self._counts
        lv = self.level.value()
        self.level_label.setText(f"{lv} of {len(counts) - 1}: {count(counts[lv], 'region')}" if counts else "")

    def set_regions(self, rows: list[dict], colors) -> None:
        """rows: {'region', 'core_vertices', 'vertices', 'shapes': [(name, share), ...]}; colors (R, 3) in [0,1]."""
        self._update_level_label()
        self.regions.blockSignals(True)
        self.regions.clear()
        for row, c in zip(rows, colors):
            shapes = ", ".join(f"{n} {s:.0%}" for n, s in row["shapes"][:3])
            item = QtWidgets.QTreeWidgetItem([f"Region {row['region']}", f"{row['core_vertices']:,}", shapes])
            pix = QtGui.QPixmap(14, 14)
            pix.fill(QtGui.QColor.fromRgbF(*[float(x) for x in c]))
            item.setIcon(0, QtGui.QIcon(pix))
            item.setData(0, QtCore.Qt.UserRole, row["region"])
            item.setToolTip(2, "\n".join(f"{n}: {s:.1%}" for n, s in row["shapes"]))
            self.regions.addTopLevelItem(item)
        self.regions.resizeColumnToContents(0)
        self.regions.blockSignals(False)

    def select_region(self, region: int) -> None:
        self.regions.blockSignals(True)
        self.regions.clearSelection()
        if 0 <= region < self.regions.topLevelItemCount():
            item = self.regions.topLevelItem(region)
            item.setSelected(True)
            self.regions.scrollToItem(item)
        self.regions.blockSignals(False)

    def selected_region(self) -> int:
        items = self.regions.selectedItems()
        return int(items[0].data(0, QtCore.Qt.UserRole)) if items else -1

    def set_status(self, text: str) -> None:
        self.status.setText(text)

    def set_view(self, view: str) -> None:
        self.view.setCurrentIndex(max(0, self.view.findData(view)))

    # --- gestures out ------------------------------------------------------------------------------
    def _current(self) -> dict:
        s = dict(self._settings)
        map_kind, normalise = self.map_kind.currentData()
        s.update(t=round(self.t_slider.value() / 1000, 3), map_kind=map_kind, normalise=normalise,
                 separate_meshes=self.separate.currentData(),
                 method=self.method.currentData(), min_region_size=self.min_size.value(),
                 overlap_rings=self.overlap.value())
        return s

    def _t_dragged(self, v: int) -> None:
        self.t_box.blockSignals(True)
        self.t_box.setValue(v / 1000)
        self.t_box.blockSignals(False)
        if not self._updating:
            self.settings_previewed.emit(self._current())

    def _t_slider_value(self, v: int) -> None:
        if not self.t_slider.isSliderDown():
            self.t_box.blockSignals(True)
            self.t_box.setValue(v / 1000)
            self.t_box.blockSignals(False)
            self._commit()

    def _t_box_value(self, v: float) -> None:
        self.t_slider.blockSignals(True)
        self.t_slider.setValue(int(round(v * 1000)))
        self.t_slider.blockSignals(False)
        self._commit()

    def _commit(self, *_) -> None:
        if self._updating:
            return
        current = self._current()
        if current != self._settings:
            self.settings_committed.emit(current)

    def _region_clicked(self) -> None:
        self.region_selected.emit(self.selected_region())
