"""Personalise to an actor (Ma et al. 2016 §3): the dialog that gathers the actor's measurements, and the panel
that lists how much each shape changed.

Plain widgets: ``PersonalizeDialog.request()`` is what the user chose; ``ShapeChangePanel`` shows the rows it is
given and emits the shape the user picks. ``app.personalize_controller`` does the work.
"""
from __future__ import annotations

import os
from pathlib import Path

from PySide6 import QtCore, QtWidgets

SCAN_FILTER = "OBJ scans (*.obj)"
TAKE_FILTER = "Marker takes (*.c3d *.trc *.csv)"


def _file_row(edit: QtWidgets.QLineEdit, button_text: str, pick) -> QtWidgets.QHBoxLayout:
    row = QtWidgets.QHBoxLayout()
    row.addWidget(edit, 1)
    button = QtWidgets.QPushButton(button_text)
    button.clicked.connect(pick)
    row.addWidget(button)
    return row


def _same_file(a: str, b: str) -> bool:
    """Whether two typed paths name the same file (``~``, ``..``, links and a trailing space aside)."""
    def real(text: str) -> str:
        return os.path.realpath(os.path.expanduser(text.strip()))
    return real(a) == real(b)


class PersonalizeDialog(QtWidgets.QDialog):
    """The actor's neutral scan, pose scans or a marker take (+ its map), and the project to write."""

    def __init__(self, parent=None, *, rig_name: str = "rig", output: str = "", take: str = "", marker_map: str = "",
                 folder: str = "", calibration_frames: int = 30, neutral_frames: str = "") -> None:
        super().__init__(parent)
        self.setWindowTitle("Personalize to Actor")
        self._folder = folder
        lay = QtWidgets.QVBoxLayout(self)
        intro = QtWidgets.QLabel(
            f"Build the actor's own version of {rig_name}: the same shape names, correctives and presets, each "
            "shape refined to reproduce the actor's scans (Ma et al. 2016). Give a neutral scan and pose scans "
            "(OBJ, the rig's vertices in the rig's order), or a marker take of the actor. The current rig is not "
            "changed: a new project is written and opened.")
        intro.setWordWrap(True)
        lay.addWidget(intro)
        self._intro = intro

        scans = QtWidgets.QGroupBox("Scans")
        sl = QtWidgets.QVBoxLayout(scans)
        self.neutral_edit = QtWidgets.QLineEdit()
        self.neutral_edit.setPlaceholderText("the actor's neutral scan (optional)")
        sl.addWidget(QtWidgets.QLabel("Neutral scan"))
        sl.addLayout(_file_row(self.neutral_edit, "Browse…", self._pick_neutral))
        sl.addWidget(QtWidgets.QLabel("Pose scans"))
        self.scan_list = QtWidgets.QListWidget()
        self.scan_list.setSelectionMode(QtWidgets.QAbstractItemView.ExtendedSelection)
        self.scan_list.setToolTip("OBJ files or folders of them: the actor's poses (weights unknown)")
        self.scan_list.setMinimumHeight(90)
        self.scan_list.setMaximumHeight(140)
        sl.addWidget(self.scan_list)
        buttons = QtWidgets.QHBoxLayout()
        for text, slot in (("Add Files…", self._add_files), ("Add Folder…", self._add_folder),
                           ("Remove", self._remove_scans)):
            b = QtWidgets.QPushButton(text)
            b.clicked.connect(slot)
            buttons.addWidget(b)
        buttons.addStretch(1)
        sl.addLayout(buttons)
        lay.addWidget(scans)

        mocap = QtWidgets.QGroupBox("Or a marker take (without pose scans)")
        form = QtWidgets.QFormLayout(mocap)
        self.take_edit = QtWidgets.QLineEdit(take)
        self.take_edit.setPlaceholderText("C3D, TRC or CSV of the actor (optional)")
        self.map_edit = QtWidgets.QLineEdit(marker_map)
        self.map_edit.setPlaceholderText("automatic")
        self.calibration_spin = QtWidgets.QSpinBox()
        self.calibration_spin.setRange(1, 100000)
        self.calibration_spin.setValue(calibration_frames)
        self.calibration_spin.setToolTip("The take's neutral frames at its start (used when no neutral frames are "
                                         "chosen below)")
        self.neutral_frames_edit = QtWidgets.QLineEdit(neutral_frames)
        self.neutral_frames_edit.setPlaceholderText("the frames at its start")
        self.neutral_frames_edit.setToolTip("The actor's neutral: frames A:B of the take (inclusive, counted from 0), "
                                            "as chosen in the Mocap panel (Use This Frame as Neutral); empty: the "
                                            "neutral frames at its start")
        self.neutral_frames_edit.textChanged.connect(self._on_neutral_frames)
        # the neutral frames given with the take (the Mocap panel's) are frames of that take only
        self._given_take, self._given_neutral, self._neutral_cleared = take, neutral_frames, False
        self.neutral_frames_edit.textEdited.connect(lambda _text: setattr(self, "_neutral_cleared", False))
        self.take_edit.textChanged.connect(self._on_take)
        form.addRow("Take", _file_row(self.take_edit, "Browse…", self._pick_take))
        form.addRow("Marker map", _file_row(self.map_edit, "Browse…", self._pick_map))
        form.addRow("Neutral frames at its start", self.calibration_spin)
        form.addRow("Or the neutral frames A:B", self.neutral_frames_edit)
        self._on_neutral_frames(neutral_frames)
        lay.addWidget(mocap)

        out = QtWidgets.QFormLayout()
        self.output_edit = QtWidgets.QLineEdit(output)
        self.output_edit.setToolTip("The actor's project (.bsproj) to write and open")
        out.addRow("Write project", _file_row(self.output_edit, "Browse…", self._pick_output))
        lay.addLayout(out)
        self.buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.Ok | QtWidgets.QDialogButtonBox.Cancel)
        self.ok_button = self.buttons.button(QtWidgets.QDialogButtonBox.Ok)
        self.ok_button.setText("Personalize")
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        lay.addWidget(self.buttons)
        self._fit_screen(560)

    # --- size -----------------------------------------------------------------------------------------
    # A dialog's layout takes a wrapped text's minimum height as one line: the introduction's four lines at 560 px
    # pushed the Scans group's Add buttons into the Pose scans list and the next group over its border. The text's
    # minimum height follows its width, and the dialog opens at least at its preferred size.
    def _hold_intro(self) -> None:
        need = self._intro.heightForWidth(self._intro.width())
        if need > 0 and need != self._intro.minimumHeight():
            self._intro.setMinimumHeight(need)

    def _fit_screen(self, width: int) -> None:
        """Open ``width`` wide (at least the preferred width) and as tall as the content needs, within the
        screen."""
        screen = (self.parentWidget() or self).screen().availableGeometry()
        width = min(max(width, self.sizeHint().width()), screen.width())
        margins = self.layout().contentsMargins()
        self._intro.setMinimumHeight(self._intro.heightForWidth(width - margins.left() - margins.right()))
        self.resize(width, min(max(self.sizeHint().height(), self.minimumSizeHint().height()), screen.height()))

    def resizeEvent(self, event) -> None:
        super().resizeEvent(event)
        self._hold_intro()

    def _on_neutral_frames(self, text: str) -> None:
        self.calibration_spin.setEnabled(not text.strip())   # a chosen range is the neutral: the count is unused

    def _on_take(self, text: str) -> None:
        """The neutral frames filled in with the take are frames of that take (the one the Mocap panel has): another
        take's path clears them (its neutral: the frames at its start, or a range typed for it), the given take's
        path brings them back. A range the user typed is left as it is."""
        if not self._given_neutral:
            return
        same = bool(text.strip()) and _same_file(text, self._given_take)
        shown = self.neutral_frames_edit.text()
        if not same and shown == self._given_neutral:
            self.neutral_frames_edit.setText("")
            self._neutral_cleared = True
        elif same and self._neutral_cleared and not shown.strip():
            self.neutral_frames_edit.setText(self._given_neutral)
            self._neutral_cleared = False

    # --- choosing files -------------------------------------------------------------------------------
    def _pick_neutral(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Neutral Scan", self._folder, SCAN_FILTER)
        if path:
            self.neutral_edit.setText(path)
            self._folder = str(Path(path).parent)

    def _add_files(self) -> None:
        paths, _ = QtWidgets.QFileDialog.getOpenFileNames(self, "Pose Scans", self._folder, SCAN_FILTER)
        self.add_scans(paths)

    def _add_folder(self) -> None:
        folder = QtWidgets.QFileDialog.getExistingDirectory(self, "Folder of Pose Scans", self._folder)
        if folder:
            self.add_scans([folder])

    def add_scans(self, paths) -> None:
        have = set(self.scans())
        for p in paths:
            if str(p) not in have:
                self.scan_list.addItem(str(p))
        if paths:
            self._folder = str(Path(paths[0]).parent)

    def _remove_scans(self) -> None:
        for item in self.scan_list.selectedItems():
            self.scan_list.takeItem(self.scan_list.row(item))

    def _pick_take(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Marker Take", self._folder, TAKE_FILTER)
        if path:
            self.take_edit.setText(path)

    def _pick_map(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Marker Map", self._folder, "Marker maps (*.json)")
        if path:
            self.map_edit.setText(path)

    def _pick_output(self) -> None:
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Write the Actor's Project", self.output_edit.text(),
                                                        "Projects (*.bsproj)")
        if path:
            self.output_edit.setText(path)

    # --- what was chosen ------------------------------------------------------------------------------
    def scans(self) -> list[str]:
        return [self.scan_list.item(i).text() for i in range(self.scan_list.count())]

    def request(self) -> dict:
        """{neutral_scan, scans, take, marker_map, calibration_frames, neutral_frames, output}: paths and the neutral
        range as typed (None when empty)."""
        def text(edit):
            return edit.text().strip() or None
        return {"neutral_scan": text(self.neutral_edit), "scans": self.scans(), "take": text(self.take_edit),
                "marker_map": text(self.map_edit), "calibration_frames": self.calibration_spin.value(),
                "neutral_frames": text(self.neutral_frames_edit),
                "output": text(self.output_edit)}


class ShapeChangePanel(QtWidgets.QWidget):
    """How far personalisation moved each shape from the template (mm), largest first; picking a row shows
    that shape's change as a heat map."""

    shape_picked = QtCore.Signal(str)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        lay = QtWidgets.QVBoxLayout(self)
        self.info = QtWidgets.QLabel("This rig was not personalised (File ▸ Personalize to Actor…).")
        self.info.setWordWrap(True)
        lay.addWidget(self.info)
        self.table = QtWidgets.QTreeWidget()
        self.table.setHeaderLabels(["Shape", "RMS (mm)", "Max (mm)", "Of shape"])
        self.table.setRootIsDecorated(False)
        self.table.setAlternatingRowColors(True)
        self.table.setToolTip("Change of each shape's displacements, personalised minus template; click a shape "
                              "to see where it changed")
        lay.addWidget(self.table, 1)
        self.table.currentItemChanged.connect(
            lambda item, _prev: self.shape_picked.emit(item.text(0)) if item is not None else None)

    def set_rows(self, rows: list[dict], info: str) -> None:
        """rows: {shape, rms, max, relative} with lengths in mm."""
        self.table.blockSignals(True)
        self.table.clear()
        for r in rows:
            item = QtWidgets.QTreeWidgetItem([r["shape"], f"{r['rms']:.3f}", f"{r['max']:.3f}",
                                              f"{100 * r['relative']:.0f}%"])
            for c in (1, 2, 3):
                item.setTextAlignment(c, QtCore.Qt.AlignRight | QtCore.Qt.AlignVCenter)
            self.table.addTopLevelItem(item)
        for c in range(4):
            self.table.resizeColumnToContents(c)
        self.table.blockSignals(False)
        self.info.setText(info)

    def select_shape(self, name: str) -> None:
        """Mark ``name`` as the shown shape (no signal)."""
        self.table.blockSignals(True)
        for i in range(self.table.topLevelItemCount()):
            item = self.table.topLevelItem(i)
            if item.text(0) == name:
                self.table.setCurrentItem(item)
                self.table.scrollToItem(item)
                break
        self.table.blockSignals(False)
