"""The Correctives panel (ALGORITHMS.md §6; Smith 2006 §4.5, §5.6–5.8): the corrective list with live
activations, the driver picker, the sculpt brush settings and the interference finder.

It shows state and emits requests; the corrective controller does the work.
"""
from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

RULE_LABELS = [("product", "Product (Maya multiplication)"), ("hierarchical", "Hierarchical (Smith)"),
               ("min", "Lowest weight"), ("smooth-min", "Lowest weight, smooth")]
RULE_SHORT = {"product": "Product", "hierarchical": "Hierarchical", "min": "Lowest", "smooth-min": "Smooth lowest"}
BRUSHES = [("grab", "Grab"), ("smooth", "Smooth"), ("inflate", "Inflate"), ("deflate", "Deflate")]
FALLOFF_LABELS = [("smooth", "Smooth"), ("linear", "Linear"), ("constant", "Constant")]


_ACTIVATION, _RULE = 1, 2   # columns of the corrective table
CORRECTIVES_TAB, INTERFERENCE_TAB = 0, 1
PAIR_HINT = "Find pairs, then select one to see where it interferes on the face."


def _combo(items, tip: str) -> QtWidgets.QComboBox:
    box = QtWidgets.QComboBox()
    for key, label in items:
        box.addItem(label, key)
    box.setToolTip(tip)
    return box


def _button(text: str, tip: str, signal=None) -> QtWidgets.QPushButton:
    b = QtWidgets.QPushButton(text)
    b.setToolTip(tip)
    if signal is not None:
        b.clicked.connect(lambda _=False: signal.emit())
    return b


MIRROR_TIP = ("Add the other side's version of the selected corrective: drivers _L↔_R, shape reflected across x = 0 "
              "(undoable)")


class CorrectivesPanel(QtWidgets.QWidget):
    new_requested = QtCore.Signal()            # new corrective from the ticked drivers
    use_pose_requested = QtCore.Signal()       # tick the shapes whose weight is > 0
    save_requested = QtCore.Signal()
    discard_requested = QtCore.Signal()
    cancel_requested = QtCore.Signal()
    scan_requested = QtCore.Signal()
    edit_shape_requested = QtCore.Signal()     # sculpt the selected corrective again
    rename_requested = QtCore.Signal()
    drivers_requested = QtCore.Signal()
    delete_requested = QtCore.Signal()
    mirror_requested = QtCore.Signal()         # add the other side's version of the selected corrective
    mute_requested = QtCore.Signal(str, bool)  # (corrective, muted): its tick box was toggled
    rule_requested = QtCore.Signal(str)        # the selected corrective's new rule
    brush_changed = QtCore.Signal()
    find_requested = QtCore.Signal()
    pair_selected = QtCore.Signal(int)         # row in the interference list, -1 = none
    create_pair_requested = QtCore.Signal()
    tab_changed = QtCore.Signal(int)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self._updating = False
        self.setMinimumWidth(360)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.insertTab(CORRECTIVES_TAB, self._build_correctives_tab(), "Correctives")
        self.tabs.insertTab(INTERFERENCE_TAB, self._build_interference_tab(), "Interference")
        self.tabs.currentChanged.connect(self.tab_changed)
        lay.addWidget(self.tabs)

    # --- construction ------------------------------------------------------------------------------
    def _build_correctives_tab(self) -> QtWidgets.QWidget:
        page = QtWidgets.QWidget()
        lay = QtWidgets.QVBoxLayout(page)
        self.table = QtWidgets.QTreeWidget()
        # three columns that fit the dock (the drivers, usually the name itself, are in each row's tooltip): the
        # name takes the width left, the live activation and the rule (short) their contents'
        self.table.setHeaderLabels(["Corrective", "Activation", "Rule"])
        header = self.table.header()
        header.setStretchLastSection(False)
        header.setSectionResizeMode(0, QtWidgets.QHeaderView.Stretch)
        for c in (_ACTIVATION, _RULE):
            header.setSectionResizeMode(c, QtWidgets.QHeaderView.ResizeToContents)
        self.table.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarAlwaysOff)
        self.table.setTextElideMode(QtCore.Qt.ElideMiddle)
        self.table.setRootIsDecorated(False)
        self.table.setAlternatingRowColors(True)
        self.table.setToolTip("Correctives of the rig, in evaluation order (lower orders first), with their "
                              "activation a_c(w) at the current pose; untick one to mute it (compare the face "
                              "without it); double-click to sculpt one again")
        self.table.setMinimumHeight(110)
        self.table.itemSelectionChanged.connect(self._on_selection)
        self.table.itemDoubleClicked.connect(lambda *_: self.edit_shape_requested.emit())
        self.table.itemChanged.connect(self._on_item_changed)
        lay.addWidget(self.table, 2)
        row = QtWidgets.QGridLayout()
        self.rename_button = _button("Rename…", "Rename the selected corrective (undoable; F2 in the list)",
                                     self.rename_requested)
        self.drivers_button = _button("Drivers…", "Edit the selected corrective's driver shapes (undoable)",
                                      self.drivers_requested)
        self.edit_button = _button("Sculpt", "Set the selected corrective's drivers to 1 and sculpt it again",
                                   self.edit_shape_requested)
        self.mirror_button = _button("Mirror", MIRROR_TIP, self.mirror_requested)
        self.delete_button = _button("Delete", "Delete the selected corrective (undoable; Delete key in the list)",
                                     self.delete_requested)
        # two rows of buttons: five in one made the panel wider than its dock at the default window size
        for i, b in enumerate((self.rename_button, self.drivers_button, self.edit_button, self.mirror_button,
                               self.delete_button)):
            row.addWidget(b, i // 3, i % 3)
        for key, signal, what in (("Delete", self.delete_requested, "Delete Corrective"),
                                  ("F2", self.rename_requested, "Rename Corrective")):
            sc = QtGui.QShortcut(QtGui.QKeySequence(key), self.table)   # while the list has the focus
            sc.setContext(QtCore.Qt.WidgetShortcut)
            sc.setWhatsThis(what)
            sc.activated.connect(lambda s=signal: s.emit() if self.selected_name() is not None else None)
        lay.addLayout(row)
        rule_row = QtWidgets.QHBoxLayout()
        rule_row.addWidget(QtWidgets.QLabel("Rule"))
        self.rule = _combo(RULE_LABELS, "How the corrective's activation follows its drivers' weights "
                                        "(for the selected corrective, or the next new one)")
        self.rule.currentIndexChanged.connect(self._on_rule)
        rule_row.addWidget(self.rule, 1)
        lay.addLayout(rule_row)

        drv = QtWidgets.QGroupBox("Drivers of a new corrective")
        dl = QtWidgets.QVBoxLayout(drv)
        self.driver_filter = QtWidgets.QLineEdit()
        self.driver_filter.setPlaceholderText("Filter shapes")
        self.driver_filter.setClearButtonEnabled(True)
        self.driver_filter.setToolTip("Show only shapes whose name contains this text")
        self.driver_filter.textChanged.connect(self._filter_drivers)
        dl.addWidget(self.driver_filter)
        self.drivers = QtWidgets.QListWidget()
        self.drivers.setToolTip("Tick two or more shapes that need a corrective where they combine")
        self.drivers.setMinimumHeight(90)
        dl.addWidget(self.drivers, 1)
        brow = QtWidgets.QHBoxLayout()
        self.use_pose_button = _button("Use posed shapes", "Tick the shapes whose weight is above 0 now",
                                       self.use_pose_requested)
        self.new_button = _button("New corrective",
                                  "Set the ticked drivers (or, if none are ticked, the posed shapes) to 1 "
                                  "and start sculpting the corrective (Ctrl+Shift+N)", self.new_requested)
        brow.addWidget(self.use_pose_button)
        brow.addWidget(self.new_button, 1)
        dl.addLayout(brow)
        self.scan_button = _button("From scan…", "Import an OBJ of the desired combination (same vertices "
                                                 "as the rig, in order) and make the corrective from it",
                                   self.scan_requested)
        self.scan_mode = _combo([("drivers", "Scan is the drivers at 1"), ("fit", "Fit the scan's weights")],
                                "How the scan's pose is found: the ticked drivers at 1 (the scan becomes the "
                                "surface there), or a bounded least-squares fit of all weights with the "
                                "residual over the drivers' region kept (Smith, future work 1)")
        srow = QtWidgets.QHBoxLayout()
        srow.addWidget(self.scan_button)
        srow.addWidget(self.scan_mode, 1)
        dl.addLayout(srow)
        lay.addWidget(drv, 3)

        sculpt = QtWidgets.QGroupBox("Sculpt")
        self.sculpt_box = sculpt
        # the status above the form, in a box layout: a form row gave the wrapped sentence too little height
        sculpt_lay = QtWidgets.QVBoxLayout(sculpt)
        self.sculpt_status = QtWidgets.QLabel("Not sculpting.")
        self.sculpt_status.setWordWrap(True)
        sculpt_lay.addWidget(self.sculpt_status)
        form = QtWidgets.QFormLayout()
        sculpt_lay.addLayout(form)
        self.brush = _combo(BRUSHES, "Grab drags the surface with the mouse; Smooth relaxes it; Inflate and "
                                     "Deflate push it along its normals (G, Shift+S, I, D)")
        self.radius = QtWidgets.QDoubleSpinBox()
        self.radius.setDecimals(3)
        self.radius.setRange(0.001, 1e4)
        self.radius.setToolTip("Brush radius in rig units ([ and ] change it)")
        self.falloff = _combo(FALLOFF_LABELS, "Brush profile from the centre to the rim")
        self.strength = QtWidgets.QDoubleSpinBox()
        self.strength.setRange(0.01, 1.0)
        self.strength.setSingleStep(0.05)
        self.strength.setValue(1.0)
        self.strength.setToolTip("Brush strength: the fraction of the drag (grab) or of the effect per dab")
        self.symmetric = QtWidgets.QCheckBox("Symmetric across x = 0")
        self.symmetric.setToolTip("Mirror every stroke to the other side of the face (X)")
        for w in (self.brush, self.falloff):
            w.currentIndexChanged.connect(lambda _: self.brush_changed.emit())
        for w in (self.radius, self.strength):
            w.valueChanged.connect(lambda _: self.brush_changed.emit())
        self.symmetric.toggled.connect(lambda _: self.brush_changed.emit())
        form.addRow("Brush", self.brush)
        form.addRow("Radius", self.radius)
        form.addRow("Falloff", self.falloff)
        form.addRow("Strength", self.strength)
        form.addRow(self.symmetric)
        srow = QtWidgets.QHBoxLayout()
        self.save_button = _button("Save corrective", "Store the sculpted difference as the corrective: "
                                   "e = (x_des − x_cur) / a (Ctrl+Return)", self.save_requested)
        self.discard_button = _button("Discard sculpt", "Drop the pending sculpt (undoable)", self.discard_requested)
        self.cancel_button = _button("Stop", "Leave sculpt mode (the pending sculpt stays until discarded)",
                                     self.cancel_requested)
        srow.addWidget(self.save_button, 1)
        srow.addWidget(self.discard_button)
        srow.addWidget(self.cancel_button)
        form.addRow(srow)
        lay.addWidget(sculpt)
        self.set_sculpting(None)
        self._on_selection()
        return page

    def _build_interference_tab(self) -> QtWidgets.QWidget:
        page = QtWidgets.QWidget()
        lay = QtWidgets.QVBoxLayout(page)
        row = QtWidgets.QHBoxLayout()
        self.measure = _combo([("overshoot", "Overshoot where both act"), ("overlap", "Overlap"),
                               ("directional", "Overlap, same direction")],
                              "Overshoot: how much the pair's sum exceeds the larger displacement where both "
                              "shapes act (1 = the motion doubles, below 0 = they cancel), shrunk for small "
                              "shared areas.\nOverlap: Σ min(‖d_i‖, ‖d_j‖) / min(Σ‖d_i‖, Σ‖d_j‖). Same "
                              "direction also weights each vertex by max(0, cos θ), so opposing shapes drop out."
                              "\nEvery sum is over the surface (each vertex weighted by its area), so densely "
                              "modelled parts do not count for more")
        self.top = QtWidgets.QSpinBox()
        self.top.setRange(1, 500)
        self.top.setValue(20)
        self.top.setToolTip("How many pairs to list")
        self.find_button = _button("Find pairs", "Rank shape pairs by how much their displacements overlap",
                                   self.find_requested)
        self.partner_of = QtWidgets.QComboBox()
        self.partner_of.addItem("any shape", None)
        self.partner_of.setToolTip("List every pair, or only the partners of one shape (the shape you are "
                                   "correcting), best first")
        self.partner_of.activated.connect(lambda _=0: self.find_requested.emit())
        # the measure on a row of its own, the dock's width: beside Top and Find pairs its name was cut to
        # "Overshoot where both a" in the dock at the window's default size
        form = QtWidgets.QFormLayout()
        form.setFieldGrowthPolicy(QtWidgets.QFormLayout.AllNonFixedFieldsGrow)
        form.addRow("Measure", self.measure)
        form.addRow("Pairs with", self.partner_of)
        row.addWidget(self.top)
        row.addStretch(1)
        row.addWidget(self.find_button)
        form.addRow("Top", row)
        lay.addLayout(form)
        self.merge_mirrored = QtWidgets.QCheckBox("One row for a pair and its mirror")
        self.merge_mirrored.setChecked(True)
        self.merge_mirrored.setToolTip("List eyeWide_L × eyeLookUp_L and eyeWide_R × eyeLookUp_R as one problem "
                                       "(the heat map shows both sides; author one and Mirror it)")
        self.merge_mirrored.toggled.connect(   # re-rank a list already shown
            lambda _=False: self.find_requested.emit() if self.pairs.topLevelItemCount() else None)
        lay.addWidget(self.merge_mirrored)
        self.pairs = QtWidgets.QTreeWidget()
        self.pairs.setHeaderLabels(["#", "Score", "Shape", "Shape", "Sides", "Fixed"])
        self.pairs.headerItem().setToolTip(4, "both: the row stands for the pair and its mirror image on the other "
                                              "side (One row for a pair and its mirror)")
        self.pairs.headerItem().setToolTip(5, "Whether the pair already has a corrective (✓), or one side of two")
        # every column within the dock at the window's default size (1400x900): sized to their contents, the Sides and
        # Fixed columns sat past the list's right edge, behind a horizontal scroll bar. The numbers, Sides and Fixed
        # keep their contents' width; the two shape names share the rest, elided in the middle (the row's tooltip
        # names them whole)
        header = self.pairs.header()
        header.setStretchLastSection(False)
        header.setMinimumSectionSize(20)
        for c, mode in enumerate((QtWidgets.QHeaderView.ResizeToContents, QtWidgets.QHeaderView.ResizeToContents,
                                  QtWidgets.QHeaderView.Stretch, QtWidgets.QHeaderView.Stretch,
                                  QtWidgets.QHeaderView.ResizeToContents, QtWidgets.QHeaderView.ResizeToContents)):
            header.setSectionResizeMode(c, mode)
        self.pairs.setTextElideMode(QtCore.Qt.ElideMiddle)
        self.pairs.setRootIsDecorated(False)
        self.pairs.setAlternatingRowColors(True)
        self.pairs.setToolTip("Shape pairs that interfere most, best first; select one to see where (the "
                              "overshoot of their sum, or min(‖d_i‖, ‖d_j‖) for the overlap measures)")
        self.pairs.itemSelectionChanged.connect(self._on_pair)
        # the selected pair's summary and action above the list, which takes the rest of the (tall) page:
        # below it they ended up under the fold of the dock's scroll area
        self.create_pair_button = _button("Create corrective for this pair",
                                          "Set the pair to 1 and start sculpting its corrective",
                                          self.create_pair_requested)
        self.create_pair_button.setEnabled(False)
        lay.addWidget(self.create_pair_button)
        self.pair_info = QtWidgets.QLabel(PAIR_HINT)
        self.pair_info.setWordWrap(True)
        lay.addWidget(self.pair_info)
        lay.addWidget(self.pairs, 1)
        return page

    # --- state shown -------------------------------------------------------------------------------
    def set_units(self, units: str) -> None:
        """Lengths (the brush radius) are in the rig's units: show them."""
        self.radius.setSuffix(f" {units}")

    def set_shapes(self, names: list[str]) -> None:
        chosen = self.partner_of.currentData()
        self.partner_of.clear()
        self.partner_of.addItem("any shape", None)
        for n in names:
            self.partner_of.addItem(n, n)
        self.partner_of.setCurrentIndex(max(0, self.partner_of.findData(chosen)) if chosen in names else 0)
        self.drivers.clear()
        for n in names:
            item = QtWidgets.QListWidgetItem(n)
            item.setFlags(item.flags() | QtCore.Qt.ItemIsUserCheckable)
            item.setCheckState(QtCore.Qt.Unchecked)
            self.drivers.addItem(item)
        self._filter_drivers(self.driver_filter.text())

    def ticked_drivers(self) -> list[str]:
        return [self.drivers.item(i).text() for i in range(self.drivers.count())
                if self.drivers.item(i).checkState() == QtCore.Qt.Checked]

    def set_ticked(self, names) -> None:
        """Tick ``names`` (and only them) among the drivers; the first is scrolled into view (Use posed shapes
        ticked shapes far down the list and showed none of them)."""
        names = set(names)
        first = None
        for i in range(self.drivers.count()):
            it = self.drivers.item(i)
            it.setCheckState(QtCore.Qt.Checked if it.text() in names else QtCore.Qt.Unchecked)
            if first is None and it.text() in names and not it.isHidden():
                first = it
        if first is not None:
            self.drivers.scrollToItem(first, QtWidgets.QAbstractItemView.PositionAtTop)

    def _filter_drivers(self, text: str) -> None:
        t = text.strip().lower()
        for i in range(self.drivers.count()):
            it = self.drivers.item(i)
            it.setHidden(bool(t) and t not in it.text().lower())

    def set_correctives(self, rows, activations) -> None:
        """rows: (name, drivers, rule) or (name, drivers, rule, muted) in evaluation order; activations: (C,)
        at the current pose."""
        selected = self.selected_name()
        before = {self.table.topLevelItem(i).data(0, QtCore.Qt.UserRole) for i in range(self.table.topLevelItemCount())}
        self._updating = True
        self.table.clear()
        labels = dict(RULE_LABELS)
        added = None
        for (name, drivers, rule, *muted), a in zip(rows, activations):
            muted = bool(muted and muted[0])
            item = QtWidgets.QTreeWidgetItem([name, f"{a:.3f}", RULE_SHORT.get(rule, rule)])
            item.setData(0, QtCore.Qt.UserRole, name)
            item.setData(_RULE, QtCore.Qt.UserRole, rule)
            item.setFlags(item.flags() | QtCore.Qt.ItemIsUserCheckable)
            item.setCheckState(0, QtCore.Qt.Unchecked if muted else QtCore.Qt.Checked)
            tip = (f"{name}: driven by {', '.join(drivers)}; {labels.get(rule, rule)}"
                   + ("; muted: it adds nothing to the face until ticked again" if muted else ""))
            for c in range(3):
                item.setToolTip(c, tip)
            if muted:
                for c in range(3):
                    item.setForeground(c, QtCore.Qt.gray)
            item.setTextAlignment(_ACTIVATION, QtCore.Qt.AlignRight | QtCore.Qt.AlignVCenter)
            self.table.addTopLevelItem(item)
            if name == selected:
                item.setSelected(True)
            if before and name not in before:
                added = item
        self._updating = False
        self._on_selection()
        if added is not None and len(rows) == len(before) + 1:   # a corrective just made: show its row
            self.table.scrollToItem(added)
            self._reveal(self.table)

    def muted_names(self) -> list[str]:
        return [self.table.topLevelItem(i).text(0) for i in range(self.table.topLevelItemCount())
                if self.table.topLevelItem(i).checkState(0) == QtCore.Qt.Unchecked]

    def _on_item_changed(self, item: QtWidgets.QTreeWidgetItem, column: int) -> None:
        if column == 0 and not self._updating:
            name, muted = item.data(0, QtCore.Qt.UserRole), item.checkState(0) == QtCore.Qt.Unchecked
            # after this signal returns: the edit rebuilds the table, which must not delete the item mid-signal
            QtCore.QTimer.singleShot(0, self, lambda: self.mute_requested.emit(name, muted))

    def set_activations(self, activations) -> None:
        for i, a in enumerate(activations):
            item = self.table.topLevelItem(i)
            if item is not None:
                item.setText(_ACTIVATION, f"{a:.3f}")

    def activation_texts(self) -> list[str]:
        return [self.table.topLevelItem(i).text(_ACTIVATION) for i in range(self.table.topLevelItemCount())]

    def names(self) -> list[str]:
        return [self.table.topLevelItem(i).text(0) for i in range(self.table.topLevelItemCount())]

    def selected_name(self) -> str | None:
        items = self.table.selectedItems()
        return items[0].data(0, QtCore.Qt.UserRole) if items else None

    def select(self, name: str | None) -> None:
        for i in range(self.table.topLevelItemCount()):
            it = self.table.topLevelItem(i)
            it.setSelected(it.data(0, QtCore.Qt.UserRole) == name)

    def _on_selection(self) -> None:
        has = self.selected_name() is not None
        for b in (self.rename_button, self.drivers_button, self.edit_button, self.mirror_button,
                  self.delete_button):
            b.setEnabled(has)
        if has and not self._updating:
            key = self.table.selectedItems()[0].data(_RULE, QtCore.Qt.UserRole)
            self._updating = True
            self.rule.setCurrentIndex(max(0, self.rule.findData(key)))
            self._updating = False

    def set_mirror_allowed(self, allowed: bool, why: str | None = None) -> None:
        """Enable Mirror for a selected corrective it can act on; disabled, its tooltip says ``why``."""
        self.mirror_button.setEnabled(allowed)
        self.mirror_button.setToolTip(MIRROR_TIP if allowed or not why else why)

    def _on_rule(self, _index: int) -> None:
        if not self._updating and self.selected_name() is not None:
            self.rule_requested.emit(self.rule.currentData())

    def current_rule(self) -> str:
        return self.rule.currentData()

    def set_sculpting(self, drivers: list[str] | None, has_offset: bool = False) -> None:
        on = drivers is not None
        if on:
            self.sculpt_status.setText(f"Sculpting {' + '.join(drivers)}: drag on the face "
                                       "(drag off the face to turn the view).")
        else:
            self.sculpt_status.setText("Not sculpting: start a new corrective, or select one and press Sculpt.")
        self.save_button.setEnabled(on)
        self.cancel_button.setEnabled(on)
        self.discard_button.setEnabled(has_offset)
        self.sculpt_box.setProperty("active", on)
        sheet = "QGroupBox { border: 1px solid #d08a3a; margin-top: 6px; }QGroupBox::title { color: #e0a050; }" \
            if on else ""
        if self.sculpt_box.styleSheet() != sheet:   # restyling the group and its children: ~3 ms a sculpt move
            self.sculpt_box.setStyleSheet(sheet)

    def reveal_sculpt(self) -> None:
        """Scroll the dock so the Sculpt group (brush settings, Save corrective) is in view."""
        self._reveal(self.sculpt_box)

    def _reveal(self, widget: QtWidgets.QWidget) -> None:
        """Scroll the dock (if the panel is taller than it) so ``widget`` is in view."""
        w = self.parentWidget()
        while w is not None and not isinstance(w, QtWidgets.QScrollArea):
            w = w.parentWidget()
        if w is not None:
            QtCore.QTimer.singleShot(0, w, lambda: w.ensureWidgetVisible(widget, 0, 0))

    def heightForWidth(self, width: int) -> int:  # Qt override
        """No preferred height for a width: with it, the word-wrapped labels made the dock's scroll area size the
        panel to its preferred height (taller than the dock of a 1400x900 window, Save corrective under the fold)
        instead of fitting it to the dock (never below its minimum) with the lists taking what is left."""
        return -1

    def brush_settings(self) -> dict:
        return {"brush": self.brush.currentData(), "radius": float(self.radius.value()),
                "falloff": self.falloff.currentData(), "strength": float(self.strength.value()),
                "symmetric": self.symmetric.isChecked()}

    # --- interference ------------------------------------------------------------------------------
    def set_pairs(self, rows) -> None:
        """Rows (shape, shape, score[, the mirror pair as text or "", the corrective status as text or ""])."""
        self.pairs.clear()
        names = []
        for i, (a, b, s, *rest) in enumerate(rows):
            twin = rest[0] if rest else ""
            item = QtWidgets.QTreeWidgetItem([str(i + 1), f"{s:.3f}", a, b, "both" if twin else ""])
            item.setTextAlignment(1, QtCore.Qt.AlignRight | QtCore.Qt.AlignVCenter)   # the score before the names
            self.pairs.addTopLevelItem(item)
            names.append((a, b, twin))
        self.set_pair_names(names)
        self.set_pair_correctives([r[4] if len(r) > 4 else "" for r in rows])
        self.set_pair_action(False)
        self.create_pair_button.setEnabled(False)

    def set_pair_names(self, rows) -> None:
        """The listed rows' shape names, (shape, shape, the mirror pair as text or ""), and their tooltips (as listed,
        and after a rename)."""
        for i, (a, b, twin) in enumerate(rows):
            item = self.pairs.topLevelItem(i)
            if item is not None:
                item.setText(2, a)
                item.setText(3, b)
                for c in range(6):   # the names whole (the list may elide them)
                    item.setToolTip(c, f"{a} × {b}, and its mirror image {twin}" if twin else f"{a} × {b}")

    def set_pair_action(self, has_corrective: bool) -> None:
        """The pair button creates the selected pair's corrective, or edits the one it has."""
        self.create_pair_button.setText("Edit the corrective of this pair" if has_corrective
                                        else "Create corrective for this pair")

    def set_pair_correctives(self, status: list[str]) -> None:
        """The Fixed column: "✓" when the row's pair (and its mirror) has a corrective, "1/2" for one side."""
        for i, text in enumerate(status):
            item = self.pairs.topLevelItem(i)
            if item is not None:
                item.setText(5, text)
                item.setToolTip(5, "" if not text else "This pair has a corrective" if text == "✓" else
                                f"{text.replace('/', ' of ')} sides of this row have a corrective: Mirror makes "
                                "the other")

    def selected_pair_row(self) -> int:
        items = self.pairs.selectedItems()
        return self.pairs.indexOfTopLevelItem(items[0]) if items else -1

    def select_pair(self, row: int) -> None:
        item = self.pairs.topLevelItem(row)
        if item is not None:
            self.pairs.setCurrentItem(item)

    def _on_pair(self) -> None:
        row = self.selected_pair_row()
        self.create_pair_button.setEnabled(row >= 0)
        self.pair_selected.emit(row)
