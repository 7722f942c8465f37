"""File ▸ Batch Solve…: the form of a batch (takes, output folder, the solve options of ``solve``, where to run),
its progress and the table of results. Holds no algorithm: the options become ``solve`` command-line options
(``solve_options``) that the controller (app.batch_controller) parses with the command's own parser.
"""
from __future__ import annotations

import os
import shlex

from PySide6 import QtCore, QtGui, QtWidgets

from .file_drops import FileDropTarget

TAKE_FILTER = "Marker takes (*.c3d *.trc *.csv);;All files (*)"
# titles over two lines where a long one would widen its column of short numbers (room for the error sentences)
COLUMNS = (("take", "Take"), ("status", "Status"), ("frames", "Frames"), ("rate", "Rate\n(fps)"),
           ("marker_rmse", "Marker RMSE"), ("motion_explained", "Motion\nexplained"), ("error", "Error"))
TAKE_COLUMN_MAX = 180     # pixels: the take names' column at most (set_rows)
PREVIEW_WIDTH = 288       # pixels: the preview pane's picture at least (the batch draws 480x360)
SORT_ARROW = 16           # pixels a column needs beside its title for the header's sort arrow
RESIDUALS = ("default", "none", "joshi", "gaussian", "multiquadric")


def _cell_text(key: str, value) -> str:
    """A summary value as the table shows it: the explained motion as a percentage, rates and counts whole."""
    if value is None or value == "":
        return ""
    if key == "motion_explained":
        return f"{100.0 * float(value):.1f} %"
    if key in ("frames", "rate"):
        return f"{float(value):g}"
    return f"{value:.4g}" if isinstance(value, float) else str(value)


class _Item(QtWidgets.QTableWidgetItem):
    """A results cell that sorts by its value (numbers as numbers, empty cells last), not by its text."""

    def __init__(self, text: str, key) -> None:
        super().__init__(text)
        self.key = key

    def __lt__(self, other) -> bool:
        a, b = self.key, getattr(other, "key", None)
        if a is None or b is None:
            # an empty cell sorts after every value whichever way the column is sorted
            ascending = (self.tableWidget() is None or
                         self.tableWidget().horizontalHeader().sortIndicatorOrder() == QtCore.Qt.AscendingOrder)
            return (a is not None) == ascending if (a is None) != (b is None) else False
        return a < b


def _sort_key(key: str, value):
    if value is None or value == "":
        return None
    if key in ("frames", "rate", "marker_rmse", "motion_explained"):
        try:
            return float(value)
        except (TypeError, ValueError):
            return None
    return str(value).lower()


class BatchDialog(FileDropTarget, QtWidgets.QDialog):
    """Non-modal: the window stays usable while a batch runs."""

    run_requested = QtCore.Signal()
    cancel_requested = QtCore.Signal()
    open_requested = QtCore.Signal(int)     # a take of the results: its index in the rows given to set_rows
    results_requested = QtCore.Signal(str)  # Open Results…: a batch.json (or the folder holding one) chosen
    dropped = QtCore.Signal(list)           # local files and folders dropped on the dialog (their paths)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Batch Solve")
        self.setObjectName("batch_dialog")
        self.resize(1180, 720)
        self.setAcceptDrops(True)     # takes, folders of takes, a marker map or a batch.json dropped anywhere on it
        lay = QtWidgets.QVBoxLayout(self)

        takes_box = QtWidgets.QGroupBox("Takes")
        tl = QtWidgets.QHBoxLayout(takes_box)
        self.take_list = QtWidgets.QListWidget()
        self.take_list.setSelectionMode(QtWidgets.QAbstractItemView.ExtendedSelection)
        tl.addWidget(self.take_list, 1)
        buttons = QtWidgets.QVBoxLayout()
        self.add_files_button = QtWidgets.QPushButton("Add Takes…")
        self.add_folder_button = QtWidgets.QPushButton("Add Folder…")
        self.remove_button = QtWidgets.QPushButton("Remove")
        for b in (self.add_files_button, self.add_folder_button, self.remove_button):
            buttons.addWidget(b)
        buttons.addStretch(1)
        tl.addLayout(buttons)
        lay.addWidget(takes_box, 1)

        form = QtWidgets.QFormLayout()
        self.output_edit, out_row = self._path_row("Choose…", self._choose_output)
        form.addRow("Output folder:", out_row)
        self.map_edit, map_row = self._path_row("Choose…", self._choose_map)
        self.map_edit.setPlaceholderText("automatic, from each take's calibration frames")
        form.addRow("Marker map:", map_row)
        self.mode_combo = QtWidgets.QComboBox()
        self.mode_combo.addItems(["Global", "Per region"])
        form.addRow("Solve:", self.mode_combo)
        self.residual_combo = QtWidgets.QComboBox()
        self.residual_combo.addItems(RESIDUALS)
        form.addRow("Residual:", self.residual_combo)
        self.calibration_spin = QtWidgets.QSpinBox()
        self.calibration_spin.setRange(0, 10000)
        self.calibration_spin.setValue(30)
        form.addRow("Calibration frames:", self.calibration_spin)
        self.fixed_head_check = QtWidgets.QCheckBox("Markers already head-stabilised in rig space")
        form.addRow("", self.fixed_head_check)
        self.extra_edit = QtWidgets.QLineEdit()
        self.extra_edit.setPlaceholderText("more solve options, as on the command line (e.g. --threshold 0.8 --level 1)")
        form.addRow("More options:", self.extra_edit)
        self.cache_check = QtWidgets.QCheckBox("Also write each take's dense result (PC2, large)")
        form.addRow("", self.cache_check)
        self.force_check = QtWidgets.QCheckBox("Solve again takes whose outputs are complete")
        form.addRow("", self.force_check)
        where = QtWidgets.QHBoxLayout()
        self.workers_spin = QtWidgets.QSpinBox()
        self.workers_spin.setRange(1, 256)
        self.workers_spin.setValue(os.cpu_count() or 1)
        where.addWidget(QtWidgets.QLabel("local workers"))
        where.addWidget(self.workers_spin)
        self.scheduler_edit = QtWidgets.QLineEdit()
        self.scheduler_edit.setPlaceholderText("or a Dask scheduler: tcp://host:8786")
        where.addWidget(self.scheduler_edit, 1)
        form.addRow("Run on:", where)
        lay.addLayout(form)

        run_row = QtWidgets.QHBoxLayout()
        self.run_button = QtWidgets.QPushButton("Run")
        self.run_button.setDefault(True)
        self.cancel_button = QtWidgets.QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.results_button = QtWidgets.QPushButton("Open Results…")
        self.results_button.setToolTip("Show an earlier batch's results (its batch.json, from this window or the "
                                       "batch command): sort them, see each take's preview, open a take")
        self.progress_bar = QtWidgets.QProgressBar()
        self.progress_bar.setRange(0, 1)
        self.progress_bar.setValue(0)
        run_row.addWidget(self.run_button)
        run_row.addWidget(self.cancel_button)
        run_row.addWidget(self.progress_bar, 1)
        run_row.addWidget(self.results_button)
        lay.addLayout(run_row)
        self.status_label = QtWidgets.QLabel("")
        self.status_label.setTextInteractionFlags(QtCore.Qt.TextBrowserInteraction)
        self.status_label.setOpenExternalLinks(True)
        self.status_label.setWordWrap(True)
        lay.addWidget(self.status_label)

        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels([c[1] for c in COLUMNS])
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.NoEditTriggers)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectRows)
        self.table.setSelectionMode(QtWidgets.QAbstractItemView.SingleSelection)
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.verticalHeader().setVisible(False)
        self.table.setWordWrap(True)
        self.table.setTextElideMode(QtCore.Qt.ElideNone)   # an error sentence wraps whole (set_rows)
        # a header click sorts (the worst first: the largest marker RMSE, the least motion explained, failed); the
        # rows stay in the batch's order until then
        self.table.horizontalHeader().setSortIndicator(-1, QtCore.Qt.AscendingOrder)
        self.table.setSortingEnabled(True)
        self.table.horizontalHeader().setToolTip("Click to sort by this column")
        # the rows' heights follow the error column's width as the dialog is resized
        self.table.horizontalHeader().sectionResized.connect(
            lambda column, _old, _new: self._fit_rows() if column == len(COLUMNS) - 1 else None)
        # the selected take's preview (its most expressive frame, as the batch drew it) beside the table
        preview_box = QtWidgets.QGroupBox("Preview")
        pl = QtWidgets.QVBoxLayout(preview_box)
        self.preview_label = QtWidgets.QLabel("Select a take to see its preview.")
        self.preview_label.setAlignment(QtCore.Qt.AlignCenter)
        self.preview_label.setMinimumSize(PREVIEW_WIDTH, PREVIEW_WIDTH * 3 // 4)
        self.preview_label.setWordWrap(True)
        self.preview_caption = QtWidgets.QLabel("")
        self.preview_caption.setWordWrap(True)
        pl.addWidget(self.preview_label, 1)
        pl.addWidget(self.preview_caption)
        self.open_button = QtWidgets.QPushButton("Open in Mocap Panel")
        self.open_button.setEnabled(False)
        self.open_button.setToolTip("Open the selected take, with the batch's marker map, in the Mocap panel "
                                    "(or double-click its row, or press Enter)")
        pl.addWidget(self.open_button, 0, QtCore.Qt.AlignRight)
        results = QtWidgets.QSplitter(QtCore.Qt.Horizontal)
        results.addWidget(self.table)
        results.addWidget(preview_box)
        results.setStretchFactor(0, 1)
        results.setChildrenCollapsible(False)
        lay.addWidget(results, 2)
        self._previews: list = []       # per row given to set_rows: its preview PNG's path or None
        self._rows: list[dict] = []
        self._picture = (None, QtGui.QPixmap())    # the preview shown: (its path, the picture read from it)

        self.add_files_button.clicked.connect(self._choose_takes)
        self.add_folder_button.clicked.connect(self._choose_folder)
        self.remove_button.clicked.connect(self._remove_selected)
        self.run_button.clicked.connect(self.run_requested)
        self.cancel_button.clicked.connect(self.cancel_requested)
        self.results_button.clicked.connect(self._choose_results)
        self.table.itemSelectionChanged.connect(self._show_selected)
        # a double-click or Enter on a row opens its take
        self.table.activated.connect(lambda index: self.open_requested.emit(self._take_at(index.row())))
        self.open_button.clicked.connect(self._open_selected)

    def _path_row(self, label: str, slot) -> tuple[QtWidgets.QLineEdit, QtWidgets.QWidget]:
        w = QtWidgets.QWidget()
        h = QtWidgets.QHBoxLayout(w)
        h.setContentsMargins(0, 0, 0, 0)
        edit = QtWidgets.QLineEdit()
        button = QtWidgets.QPushButton(label)
        button.clicked.connect(slot)
        h.addWidget(edit, 1)
        h.addWidget(button)
        return edit, w

    # --- choosing ---------------------------------------------------------------------------------
    def _choose_takes(self) -> None:
        paths, _ = QtWidgets.QFileDialog.getOpenFileNames(self, "Add Takes", "", TAKE_FILTER)
        self.add_takes(paths)

    def _choose_folder(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Add a Folder of Takes")
        if path:
            self.add_takes([path])

    def _choose_output(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Output Folder")
        if path:
            self.output_edit.setText(path)

    def _choose_map(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Marker Map", "", "Marker maps (*.json)")
        if path:
            self.map_edit.setText(path)

    def files_dropped(self, paths: list[str]) -> None:   # FileDropTarget
        self.dropped.emit(paths)

    def _choose_results(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open Batch Results", self.output(),
                                                        "Batch summaries (batch.json);;JSON files (*.json)")
        if path:
            self.results_requested.emit(path)

    def add_takes(self, paths) -> None:
        have = set(self.takes())
        for p in paths:
            if str(p) not in have:
                self.take_list.addItem(str(p))
                have.add(str(p))

    def _remove_selected(self) -> None:
        for item in self.take_list.selectedItems():
            self.take_list.takeItem(self.take_list.row(item))

    def _take_at(self, row: int) -> int:
        """The index (in the rows given to ``set_rows``) of the take shown on table row ``row``, however sorted."""
        item = self.table.item(row, 0)
        return -1 if item is None else int(item.data(QtCore.Qt.UserRole))

    def selected_take(self) -> int:
        """The selected take's index in the rows given to ``set_rows``; -1 if none is selected."""
        rows = self.table.selectionModel().selectedRows()
        return self._take_at(rows[0].row()) if rows else -1

    def _open_selected(self) -> None:
        i = self.selected_take()
        if i >= 0:
            self.open_requested.emit(i)

    def _show_selected(self) -> None:
        """The selected take's preview, scaled to the pane, and what its row says under it."""
        i = self.selected_take()
        self.open_button.setEnabled(i >= 0)
        if i < 0:
            self.preview_label.setPixmap(QtGui.QPixmap())
            self.preview_label.setText("Select a take to see its preview.")
            self.preview_caption.setText("")
            return
        row, path = self._rows[i], self._previews[i]
        if self._picture[0] != path:           # read once a selection: a resize only scales it again
            self._picture = (path, QtGui.QPixmap(str(path)) if path is not None else QtGui.QPixmap())
        pixmap = self._picture[1]
        if pixmap.isNull():
            self.preview_label.setPixmap(QtGui.QPixmap())
            self.preview_label.setText(row.get("preview_error") or "This take has no preview"
                                       + (" (it failed)." if row.get("status") == "failed" else "."))
        else:
            self.preview_label.setPixmap(pixmap.scaled(self.preview_label.size(), QtCore.Qt.KeepAspectRatio,
                                                       QtCore.Qt.SmoothTransformation))
        frame = row.get("preview_frame")
        self.preview_caption.setText(f"{row.get('take')}: {row.get('status')}"
                                     + (f", frame {frame}" if frame is not None and not pixmap.isNull() else ""))

    def resizeEvent(self, event) -> None:
        super().resizeEvent(event)
        if self._rows:
            self._show_selected()          # the preview scaled to its pane's new size

    # --- what the form says -----------------------------------------------------------------------
    def takes(self) -> list[str]:
        return [self.take_list.item(i).text() for i in range(self.take_list.count())]

    def output(self) -> str:
        return self.output_edit.text().strip()

    def scheduler(self) -> str:
        return self.scheduler_edit.text().strip()

    def solve_options(self) -> list[str]:
        """The form's solve options as ``solve``'s command-line options (shlex-split ``More options`` last)."""
        argv = []
        if self.map_edit.text().strip():
            argv += ["--map", self.map_edit.text().strip()]
        if self.mode_combo.currentIndex() == 0:
            argv.append("--global")
        if self.residual_combo.currentText() != "default":
            argv += ["--residual", self.residual_combo.currentText()]
        argv += ["--calibration-frames", str(self.calibration_spin.value())]
        if self.fixed_head_check.isChecked():
            argv.append("--fixed-head")
        return argv + shlex.split(self.extra_edit.text())

    # --- showing the run --------------------------------------------------------------------------
    def set_running(self, running: bool) -> None:
        self.run_button.setEnabled(not running)
        self.cancel_button.setEnabled(running)
        if running:
            self.table.setRowCount(0)
            self.progress_bar.setRange(0, 0)     # busy until the first count arrives

    def set_progress(self, done: int, total: int, text: str) -> None:
        self.progress_bar.setRange(0, max(total, 1))
        self.progress_bar.setValue(done)
        self.status_label.setText(text)

    def set_status(self, text: str) -> None:
        self.status_label.setText(text)

    def set_rows(self, rows: list[dict], units: str = "", previews: list | None = None) -> None:
        """The results table: one row a take, in the given order until a header click sorts it. ``units``: the
        rig's length unit, which the marker RMSE is in. ``previews``: per row, the path of its preview PNG or
        None. The error column takes the room left and wraps its sentence over as many lines as it needs."""
        labels = dict(COLUMNS)
        if units:
            labels["marker_rmse"] = f"Marker RMSE\n({units})"
        self._rows = list(rows)
        self._previews = list(previews) if previews is not None else [None] * len(rows)
        self._picture = (None, QtGui.QPixmap())       # a batch run again writes its previews anew
        self.table.setSortingEnabled(False)          # rows filled in the given order, then sorted as the header says
        self.table.clearContents()
        self.table.setHorizontalHeaderLabels([labels[key] for key, _ in COLUMNS])
        for j, (key, _) in enumerate(COLUMNS):
            order = QtCore.Qt.DescendingOrder if key == "marker_rmse" else QtCore.Qt.AscendingOrder
            self.table.horizontalHeaderItem(j).setData(QtCore.Qt.InitialSortOrderRole, order)
        self.table.setRowCount(len(rows))
        for i, r in enumerate(rows):
            for j, (key, _) in enumerate(COLUMNS):
                item = _Item(_cell_text(key, r.get(key)), _sort_key(key, r.get(key)))
                if j == 0:
                    item.setData(QtCore.Qt.UserRole, i)
                if key in ("frames", "rate", "marker_rmse", "motion_explained"):
                    item.setTextAlignment(QtCore.Qt.AlignRight | QtCore.Qt.AlignVCenter)
                if key == "error" and r.get(key):
                    item.setToolTip(str(r[key]))
                if key == "take" and r.get("path"):
                    item.setToolTip(f"{r.get('take')}: {r['path']}")
                self.table.setItem(i, j, item)
        error_column = len(COLUMNS) - 1
        for j in range(error_column):
            self.table.resizeColumnToContents(j)
            self.table.setColumnWidth(j, self.table.columnWidth(j) + SORT_ARROW)
        # a long take name is cut (its tooltip has it whole), so that the error sentences keep room to be read
        self.table.setColumnWidth(0, min(self.table.columnWidth(0), TAKE_COLUMN_MAX))
        self.table.setSortingEnabled(True)
        self._fit_rows()
        self._show_selected()

    def _fit_rows(self) -> None:
        """Each row as tall as its wrapped error sentence. Qt's item delegate measures wrapped text a few pixels
        wider than it paints it, so a sentence can need one line more than it is given: a row with an error gets
        one more line."""
        self.table.resizeRowsToContents()
        line = self.table.fontMetrics().lineSpacing()
        for i in range(self.table.rowCount()):
            item = self.table.item(i, len(COLUMNS) - 1)
            if item is not None and item.text():
                self.table.setRowHeight(i, self.table.rowHeight(i) + line)
