"""The Mocap panel: load a take and a marker map, solver settings, solve, exports, and a take transport.

A plain widget: it shows what it is given and emits requests; ``app.mocap_controller`` does the work.
"""
from __future__ import annotations

from PySide6 import QtCore, QtWidgets

from model.take_data import MAX_RATE, MIN_RATE
from model.units import unit_scale
from solvers.take_solve import DEFAULTS
from widgets.length_box import length_units, show_length_in

RESIDUALS = ("none", "joshi", "gaussian", "multiquadric")


class _VerticalScroll(QtWidgets.QScrollArea):
    """Scrolls a panel up and down, never sideways: as wide as the panel needs beside the scroll bar, as short as
    a few lines (the height left to it is what the dock has after what is kept in view)."""

    def __init__(self, widget: QtWidgets.QWidget) -> None:
        super().__init__()
        self.setWidget(widget)
        self.setWidgetResizable(True)
        self.setFrameShape(QtWidgets.QFrame.NoFrame)
        self.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarAlwaysOff)
        widget.installEventFilter(self)

    def eventFilter(self, watched, event) -> bool:
        if watched is self.widget() and event.type() == QtCore.QEvent.LayoutRequest:
            self.updateGeometry()    # the panel's minimum width is this area's
        return super().eventFilter(watched, event)

    def _with_bar(self, size: QtCore.QSize, height: int) -> QtCore.QSize:
        bar = self.style().pixelMetric(QtWidgets.QStyle.PM_ScrollBarExtent, None, self.verticalScrollBar())
        return QtCore.QSize(size.width() + bar + 2 * self.frameWidth(), height)

    def minimumSizeHint(self) -> QtCore.QSize:
        return self._with_bar(self.widget().minimumSizeHint(), 4 * self.fontMetrics().lineSpacing())

    def sizeHint(self) -> QtCore.QSize:
        hint = self.widget().sizeHint()
        return self._with_bar(hint, hint.height() + 2 * self.frameWidth())


class MocapPanel(QtWidgets.QWidget):
    load_take_requested = QtCore.Signal()
    load_map_requested = QtCore.Signal()
    auto_map_requested = QtCore.Signal()
    solve_requested = QtCore.Signal()
    export_weights_requested = QtCore.Signal()
    export_pc2_requested = QtCore.Signal()
    export_report_requested = QtCore.Signal()
    frame_requested = QtCore.Signal(int)
    play_toggled = QtCore.Signal(bool)
    curves_changed = QtCore.Signal()
    # the actor's neutral from the transport's context menu: (first, last) frames, or (-1, -1) for the first
    # calibration frames and (-2, -2) for the most neutral stretch found automatically
    neutral_frames_requested = QtCore.Signal(int, int)
    map_shown = QtCore.Signal(bool)        # show the marker map on the rig (and let its points be dragged)
    save_map_requested = QtCore.Signal()
    rate_requested = QtCore.Signal(float)  # the frame rate of a take whose file gives none (fps)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        # The take, the solve and the curves scroll; under them the transport and the status stay in view
        # whatever the dock's height: after a solve the Mocap Views dock leaves the panel ~360 px at 1366x768.
        body = QtWidgets.QWidget()
        lay = QtWidgets.QVBoxLayout(body)

        files = QtWidgets.QGroupBox("Take")
        fl = QtWidgets.QGridLayout(files)
        self.load_take_button = QtWidgets.QPushButton("Load Take…")
        self.load_take_button.setToolTip("Open marker trajectories (C3D, TRC, CSV) or a Live Link Face CSV")
        self.load_map_button = QtWidgets.QPushButton("Load Map…")
        self.load_map_button.setToolTip("Open a marker map (JSON: marker label → rig vertex)")
        self.auto_map_button = QtWidgets.QPushButton("Auto Map")
        self.auto_map_button.setToolTip("Bind each marker to the rig from the neutral calibration frames")
        fl.addWidget(self.load_take_button, 0, 0)
        fl.addWidget(self.load_map_button, 0, 1)
        fl.addWidget(self.auto_map_button, 0, 2)
        self.take_label = QtWidgets.QLabel("no take")
        self.take_label.setWordWrap(True)
        self.map_label = QtWidgets.QLabel("no marker map")
        self.map_label.setWordWrap(True)
        for label, lines in ((self.take_label, 3), (self.map_label, 2)):
            # a fixed height: a long take description must not push the Solve button from under the pointer
            label.setFixedHeight(label.fontMetrics().lineSpacing() * lines + 4)
            label.setAlignment(QtCore.Qt.AlignLeft | QtCore.Qt.AlignTop)
        fl.addWidget(self.take_label, 1, 0, 1, 3)
        fl.addWidget(self.map_label, 2, 0, 1, 3)
        self.show_map_button = QtWidgets.QPushButton("Show Map on Rig")
        self.show_map_button.setCheckable(True)
        self.show_map_button.setToolTip("Show where each marker sits on the rig (and the actor's neutral markers "
                                        "aligned to it); drag a point along the face to correct the map (undoable)")
        self.save_map_button = QtWidgets.QPushButton("Save Map…")
        self.save_map_button.setToolTip("Write the marker map (with your corrections) as JSON, for `solve --map`")
        fl.addWidget(self.show_map_button, 3, 0, 1, 2)
        fl.addWidget(self.save_map_button, 3, 2)
        # a take whose file gives no frame rate (a plain marker CSV, a weights CSV without times) is read at an
        # assumed one: its rate is given here; a rate the file gives is not editable (the row is hidden)
        self.rate_label = QtWidgets.QLabel("Frame rate")
        self.rate_spin = QtWidgets.QDoubleSpinBox()
        self.rate_spin.setDecimals(3)
        self.rate_spin.setRange(MIN_RATE, MAX_RATE)
        self.rate_spin.setSuffix(" fps")
        self.rate_spin.setKeyboardTracking(False)   # one re-read when the typed rate is entered, not per digit
        self.rate_spin.setToolTip("The take's file gives no frame rate: the rate its frames were recorded at "
                                  "(the take is read again at it; remembered for this file)")
        self.rate_label.setBuddy(self.rate_spin)
        fl.addWidget(self.rate_label, 4, 0)
        fl.addWidget(self.rate_spin, 4, 1, 1, 2)
        self.set_take_rate(None)
        lay.addWidget(files)

        solve = QtWidgets.QGroupBox("Solve")
        form = QtWidgets.QFormLayout(solve)
        self.mode_combo = QtWidgets.QComboBox()
        self.mode_combo.addItems(["global", "per region"])
        self.mode_combo.setToolTip("Global: one solve over all markers (measured best on the ICT take); per "
                                   "region: one solve per segmentation region of the level below, blended")
        self.level_spin = QtWidgets.QSpinBox()
        self.level_spin.setRange(0, 20)
        self.level_spin.setToolTip("Segmentation level for a per-region solve (0 = finest)")
        self.residual_combo = QtWidgets.QComboBox()
        self.residual_combo.addItems(RESIDUALS)
        self.residual_combo.setCurrentText(DEFAULTS["residual"])
        self.residual_combo.setToolTip("Radial-basis residual that carries the marker errors the shapes cannot "
                                       "reach to the dense surface (Joshi Eq. 3; Fidaleo), or none")
        # the λ's weigh squared lengths: given per cm² whatever the rig's units (model.units converts them)
        self.lam_sparsity = self._spin(DEFAULTS["lam_sparsity"], 0.0, 10.0, 4,
                                       "Sparsity λ_s (Ma et al. 2016, Eq. 3), per cm² whatever the rig's units")
        self.lam_temporal = self._spin(DEFAULTS["lam_temporal"], 0.0, 10.0, 4,
                                       "Temporal λ_t (Ma et al. 2016, Eq. 4), per cm² whatever the rig's units")
        self.rbf_scale = self._spin(DEFAULTS["rbf_scale"], 0.01, 100.0, 3, "RBF kernel length (rig units)")
        self.rbf_lambda = self._spin(DEFAULTS["rbf_lambda"], 0.0, 10.0, 4, "RBF Tikhonov λ (Fidaleo)")
        self.calibration_spin = QtWidgets.QSpinBox()
        self.calibration_spin.setRange(1, 10000)
        self.calibration_spin.setValue(int(DEFAULTS["calibration_frames"]))
        self.calibration_spin.setToolTip("Neutral frames at the start of the take used for calibration")
        form.addRow("Mode", self.mode_combo)
        form.addRow("Level", self.level_spin)
        form.addRow("Calibration frames", self.calibration_spin)
        self.neutral_edit = QtWidgets.QLineEdit()
        self.neutral_edit.setPlaceholderText("the calibration frames")
        self.neutral_edit.setToolTip("The actor's neutral: frames A:B (inclusive, counted from 0), 'auto' for the "
                                     "most neutral stretch, or empty for the first calibration frames; right-click "
                                     "the take's slider: Use This Frame as Neutral")
        self.stable_edit = QtWidgets.QLineEdit()
        self.stable_edit.setPlaceholderText("all markers")
        self.stable_edit.setToolTip("Markers the head motion is taken from: names or patterns, comma-separated "
                                    "(e.g. root-* for a head band's markers)")
        form.addRow("Neutral frames", self.neutral_edit)
        form.addRow("Stable markers", self.stable_edit)
        # the residual kernel and the weights of the solve's terms: measured defaults, rarely changed; folded
        # away so that Solve stays in view above the transport
        self.advanced_button = QtWidgets.QToolButton()
        self.advanced_button.setText("Advanced solver settings")
        self.advanced_button.setCheckable(True)
        self.advanced_button.setAutoRaise(True)
        self.advanced_button.setToolButtonStyle(QtCore.Qt.ToolButtonTextBesideIcon)
        self.advanced_button.setToolTip("Show or hide the residual kernel, the sparsity and temporal λ and the "
                                        "RBF kernel length and λ")
        form.addRow(self.advanced_button)
        self._advanced = (self.residual_combo, self.lam_sparsity, self.lam_temporal, self.rbf_scale, self.rbf_lambda)
        for label, box in zip(("Residual", "λ sparsity", "λ temporal", "RBF scale", "RBF λ"), self._advanced):
            form.addRow(label, box)
        self._solve_form = form
        self.advanced_button.toggled.connect(self.show_advanced)
        self.solve_button = QtWidgets.QPushButton("Solve")
        self.solve_button.setToolTip("Solve head motion, weights and residual for every frame of the take "
                                     "(in the background, with progress; Esc cancels)")
        form.addRow(self.solve_button)
        exp = QtWidgets.QHBoxLayout()
        self.export_weights_button = QtWidgets.QPushButton("Weights CSV…")
        self.export_pc2_button = QtWidgets.QPushButton("PC2…")
        self.export_report_button = QtWidgets.QPushButton("Solve Report…")
        for b, tip in ((self.export_weights_button, "Write the solved weights per frame as a CSV (frame, time, "
                                                    "one column per shape)"),
                       (self.export_pc2_button, "Write the dense solved surface per frame as a PC2 point cache "
                                                "(Blender, Maya, Max), head-stabilised, rig units"),
                       (self.export_report_button, "Write the solve report as JSON (marker errors per frame and "
                                                   "per marker, rig units), as `solve --report` does")):
            b.setToolTip(tip)
            exp.addWidget(b)
        form.addRow(QtWidgets.QLabel("Export"))
        form.addRow(exp)  # under their label, full width: the panel stays narrow enough for its dock
        lay.addWidget(solve)

        curves = QtWidgets.QGroupBox("Curves")
        cl = QtWidgets.QVBoxLayout(curves)
        self.curve_list = QtWidgets.QListWidget()
        self.curve_list.setMaximumHeight(110)
        self.curve_list.setToolTip("Shapes whose weight curves are plotted")
        cl.addWidget(self.curve_list)
        lay.addWidget(curves)
        lay.addStretch(1)
        self.scroll = _VerticalScroll(body)

        play = QtWidgets.QGroupBox("Playback")
        pl = QtWidgets.QGridLayout(play)
        self.play_button = QtWidgets.QPushButton("Play")
        self.play_button.setCheckable(True)
        self.loop_check = QtWidgets.QCheckBox("Loop")
        self.loop_check.setChecked(True)
        self.loop_check.setToolTip("Start again at the first frame after the last")
        self.slider = QtWidgets.QSlider(QtCore.Qt.Horizontal)
        self.slider.setRange(0, 0)
        self.slider.setToolTip("Scrub the take (Alt+, and Alt+. step a frame)")
        self.frame_label = QtWidgets.QLabel("frame –")
        self.fps_label = QtWidgets.QLabel("")
        pl.addWidget(self.play_button, 0, 0)
        pl.addWidget(self.loop_check, 0, 1)
        pl.addWidget(self.frame_label, 0, 2, 1, 2)
        pl.addWidget(self.slider, 1, 0, 1, 4)
        pl.addWidget(self.fps_label, 2, 0, 1, 4)
        self.status_label = QtWidgets.QLabel("")
        self.status_label.setWordWrap(True)

        outer = QtWidgets.QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        outer.setSpacing(0)
        outer.addWidget(self.scroll, 1)
        edge = QtWidgets.QFrame()     # where the settings scroll under what stays
        edge.setFrameShape(QtWidgets.QFrame.HLine)
        edge.setFrameShadow(QtWidgets.QFrame.Sunken)
        outer.addWidget(edge)
        footer = self._footer = QtWidgets.QVBoxLayout()
        margins = lay.contentsMargins()
        footer.setContentsMargins(margins.left(), 0, margins.right(), margins.bottom())
        footer.addWidget(play)
        footer.addWidget(self.status_label)
        outer.addLayout(footer)

        self.load_take_button.clicked.connect(self.load_take_requested)
        self.load_map_button.clicked.connect(self.load_map_requested)
        self.auto_map_button.clicked.connect(self.auto_map_requested)
        self.solve_button.clicked.connect(self.solve_requested)
        self.export_weights_button.clicked.connect(self.export_weights_requested)
        self.export_pc2_button.clicked.connect(self.export_pc2_requested)
        self.export_report_button.clicked.connect(self.export_report_requested)
        self.slider.valueChanged.connect(self.frame_requested)
        self.play_button.toggled.connect(self._on_play_toggled)
        self.curve_list.itemChanged.connect(lambda _item: self.curves_changed.emit())
        self.show_map_button.toggled.connect(self.map_shown)
        self.save_map_button.clicked.connect(self.save_map_requested)
        self.rate_spin.valueChanged.connect(self.rate_requested)
        for w in (self.slider, self.frame_label):   # right-click the transport: this frame as the actor's neutral
            w.setContextMenuPolicy(QtCore.Qt.CustomContextMenu)
            w.customContextMenuRequested.connect(lambda pos, w=w: self.neutral_menu(w.mapToGlobal(pos)))
        self.set_marker_mode(False)
        self.show_advanced(False)

    def show_advanced(self, on: bool) -> None:
        """Unfold (or fold) the advanced solver settings: the residual kernel, the λs, the RBF kernel."""
        if self.advanced_button.isChecked() != on:
            self.advanced_button.setChecked(on)    # comes back here through toggled
            return
        self.advanced_button.setArrowType(QtCore.Qt.DownArrow if on else QtCore.Qt.RightArrow)
        for box in self._advanced:
            self._solve_form.setRowVisible(box, on)

    def heightForWidth(self, width: int) -> int:
        """The least height at ``width``: the transport and the wrapped status, and a few lines of the settings
        (they scroll). The dock's scroll area asks this of a panel with a wrapped text; the layout's answer, the
        settings' whole height, pushed the transport below the dock's bottom."""
        footer = self._footer
        need = footer.heightForWidth(width) if footer.hasHeightForWidth() else footer.sizeHint().height()
        return need + self.scroll.minimumSizeHint().height()

    @staticmethod
    def _spin(value, lo, hi, decimals, tip) -> QtWidgets.QDoubleSpinBox:
        s = QtWidgets.QDoubleSpinBox()
        s.setDecimals(decimals)
        s.setRange(lo, hi)
        s.setSingleStep(10 ** -decimals * 10)
        s.setValue(value)
        s.setToolTip(tip)
        return s

    def _on_play_toggled(self, on: bool) -> None:
        self.play_button.setText("Pause" if on else "Play")
        self.play_toggled.emit(on)

    def neutral_menu_actions(self, menu: QtWidgets.QMenu) -> list:
        """Fill ``menu`` with the neutral-frame choices for the frame shown; returns its actions."""
        f = self.slider.value()
        n = self.calibration_spin.value()
        last = min(f + n - 1, self.slider.maximum())
        choices = ((f"Use This Frame as Neutral (frame {f + 1})", f, f),
                   (f"Use Frames {f + 1}–{last + 1} as Neutral", f, last),
                   ("Neutral: the First Calibration Frames", -1, -1),
                   ("Neutral: Find the Most Neutral Stretch", -2, -2))
        acts = []
        for text, a, b in choices:
            act = menu.addAction(text)
            act.triggered.connect(lambda _=False, a=a, b=b: self.neutral_frames_requested.emit(a, b))
            acts.append(act)
        acts[0].setToolTip("The actor's neutral for the next solve: this frame (undoable)")
        return acts

    def neutral_menu(self, global_pos) -> QtWidgets.QMenu:
        menu = QtWidgets.QMenu(self)
        menu.setAttribute(QtCore.Qt.WA_DeleteOnClose)
        self.neutral_menu_actions(menu)
        menu.popup(global_pos)
        self.last_menu = menu
        return menu

    def set_neutral_frames(self, value: str | None) -> None:
        """Show the neutral frames setting ('A:B' with frames counted from 0, 'auto', or None: the first
        calibration frames)."""
        self.neutral_edit.setText(value or "")

    # --- state shown ------------------------------------------------------------------------------
    def settings(self) -> dict:
        """Solve settings for ``model.take_workspace.TakeWorkspace.solve``: ``mode`` (global / region), ``level``,
        the solver options, the calibration length, the neutral frames and the stable markers."""
        return {"mode": "region" if self.mode_combo.currentIndex() == 1 else "global",
                "level": self.level_spin.value(), "residual": self.residual_combo.currentText(),
                "lam_sparsity": self.lam_sparsity.value(), "lam_temporal": self.lam_temporal.value(),
                "rbf_scale": self.rbf_scale.value() * unit_scale(length_units(self.rbf_scale), "cm"),
                "rbf_lambda": self.rbf_lambda.value(),
                "calibration_frames": self.calibration_spin.value(),
                "neutral_frames": self.neutral_edit.text().strip() or None,
                "stable": self.stable_edit.text().strip() or None}

    def set_units(self, units: str) -> None:
        """Lengths (the RBF kernel length) are in the rig's units: show them, the length kept physically the same
        (``settings`` gives it in cm, as the solve settings are)."""
        show_length_in(self.rbf_scale, units)

    def set_marker_mode(self, markers: bool, solved: bool = False) -> None:
        """Enable what makes sense: map and solve for a marker take, exports once something is playable."""
        for w in (self.load_map_button, self.auto_map_button, self.solve_button):
            w.setEnabled(markers)
        self.show_map_button.setEnabled(markers)
        self.save_map_button.setEnabled(markers)
        self.export_pc2_button.setEnabled(solved)
        self.export_report_button.setEnabled(solved and markers)

    def set_take_rate(self, rate: float | None) -> None:
        """Show the frame rate of a take whose file gives none, to be changed (None: no such take, no field)."""
        for w in (self.rate_label, self.rate_spin):
            w.setVisible(rate is not None)
        if rate is not None and self.rate_spin.value() != rate:
            self.rate_spin.blockSignals(True)
            self.rate_spin.setValue(rate)
            self.rate_spin.blockSignals(False)

    def set_weights_exportable(self, on: bool) -> None:
        self.export_weights_button.setEnabled(on)

    def set_frames(self, n_frames: int, rate: float) -> None:
        """The take's length (0: none, and no frame shown)."""
        self.slider.blockSignals(True)
        self.slider.setRange(0, max(0, n_frames - 1))
        self.slider.setValue(0)
        self.slider.blockSignals(False)
        self.rate = rate
        if n_frames == 0:
            self.frame_label.setText("frame –")

    def show_frame(self, frame: int, n_frames: int, rate: float) -> None:
        if self.slider.value() != frame:
            self.slider.blockSignals(True)
            self.slider.setValue(frame)
            self.slider.blockSignals(False)
        self.frame_label.setText(f"frame {frame + 1}/{n_frames} · {frame / rate:.2f} s")

    def set_playing(self, on: bool) -> None:
        if self.play_button.isChecked() != on:
            self.play_button.blockSignals(True)
            self.play_button.setChecked(on)
            self.play_button.setText("Pause" if on else "Play")
            self.play_button.blockSignals(False)

    def set_curve_shapes(self, names: list[str], checked: list[str]) -> None:
        self.curve_list.blockSignals(True)
        self.curve_list.clear()
        for n in names:
            item = QtWidgets.QListWidgetItem(n)
            item.setFlags(item.flags() | QtCore.Qt.ItemIsUserCheckable)
            item.setCheckState(QtCore.Qt.Checked if n in checked else QtCore.Qt.Unchecked)
            self.curve_list.addItem(item)
        self.curve_list.blockSignals(False)

    def checked_curves(self) -> list[str]:
        return [self.curve_list.item(i).text() for i in range(self.curve_list.count())
                if self.curve_list.item(i).checkState() == QtCore.Qt.Checked]

    def set_status(self, text: str) -> None:
        self.status_label.setText(text)
