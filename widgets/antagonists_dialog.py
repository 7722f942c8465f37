"""The Antagonist Pairs dialog: the shape pairs that solves never leave both strongly on (ALGORITHMS.md §13).

A plain widget: it lists the pairs it is given (those found from the rig, and whether the list was edited),
and emits requests (add a pair, remove the selected pairs, go back to the rig's pairs); the controller turns
them into undo steps.
"""
from __future__ import annotations

from PySide6 import QtCore, QtWidgets


class AntagonistsDialog(QtWidgets.QDialog):
    add_requested = QtCore.Signal(str, str)
    remove_requested = QtCore.Signal(list)     # [(name, name), ...]
    reset_requested = QtCore.Signal()

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Antagonist Pairs")
        lay = QtWidgets.QVBoxLayout(self)
        self.info = QtWidgets.QLabel("")
        self.info.setWordWrap(True)
        lay.addWidget(self.info)
        self.table = QtWidgets.QTreeWidget()
        self.table.setHeaderLabels(["Shape", "Against", "From"])
        self.table.setRootIsDecorated(False)
        self.table.setAlternatingRowColors(True)
        self.table.setSelectionMode(QtWidgets.QAbstractItemView.ExtendedSelection)
        self.table.setToolTip("Pairs of shapes that act against each other: a drag or a take solve never "
                              "leaves both strongly on")
        lay.addWidget(self.table, 1)
        add = QtWidgets.QHBoxLayout()
        self.first = QtWidgets.QComboBox()
        self.second = QtWidgets.QComboBox()
        for combo in (self.first, self.second):
            combo.setEditable(True)                       # type to find a shape among dozens
            combo.setInsertPolicy(QtWidgets.QComboBox.NoInsert)
            combo.setMinimumContentsLength(14)
        self.add_button = QtWidgets.QPushButton("Add Pair")
        self.add_button.setToolTip("Keep these two shapes apart in every solve (undoable)")
        add.addWidget(self.first, 1)
        add.addWidget(QtWidgets.QLabel("against"))
        add.addWidget(self.second, 1)
        add.addWidget(self.add_button)
        lay.addLayout(add)
        row = QtWidgets.QHBoxLayout()
        self.remove_button = QtWidgets.QPushButton("Remove Selected")
        self.remove_button.setToolTip("Let the selected pairs be on together again (undoable)")
        self.reset_button = QtWidgets.QPushButton("Use the Rig's Pairs")
        self.reset_button.setToolTip("Forget the edits: the pairs found from the rig's shapes (undoable)")
        close = QtWidgets.QPushButton("Close")
        row.addWidget(self.remove_button)
        row.addWidget(self.reset_button)
        row.addStretch(1)
        row.addWidget(close)
        lay.addLayout(row)
        self.add_button.clicked.connect(
            lambda: self.add_requested.emit(self.first.currentText().strip(), self.second.currentText().strip()))
        self.remove_button.clicked.connect(lambda: self.remove_requested.emit(self.selected_pairs()))
        self.reset_button.clicked.connect(self.reset_requested)
        close.clicked.connect(self.close)
        self.table.itemSelectionChanged.connect(
            lambda: self.remove_button.setEnabled(bool(self.table.selectedItems())))
        self.remove_button.setEnabled(False)
        self.resize(460, 480)

    def set_state(self, pairs: list[tuple[str, str]], shape_names: list[str], found: list[tuple[str, str]],
                  edited: bool) -> None:
        """Show ``pairs``; ``found`` are the rig's own pairs (marked as such), ``edited`` whether the project's
        list differs from them."""
        keep = self.selected_pairs()
        found_keys = {frozenset(p) for p in found}
        self.table.clear()
        for a, b in pairs:
            item = QtWidgets.QTreeWidgetItem([a, b, "the rig" if frozenset((a, b)) in found_keys else "added"])
            item.setData(0, QtCore.Qt.UserRole, (a, b))
            self.table.addTopLevelItem(item)
            item.setSelected((a, b) in keep)
        for c in range(3):
            self.table.resizeColumnToContents(c)
        for combo in (self.first, self.second):
            text = combo.currentText()
            combo.blockSignals(True)
            combo.clear()
            combo.addItems(shape_names)
            combo.setCurrentText(text if text in shape_names else "")
            combo.blockSignals(False)
        self.info.setText(f"{len(pairs)} pairs are kept from being both on (held apart in marker drags, penalised "
                          "in take solves): " + ("edited for this project." if edited else "those found from the "
                                                 "rig's shapes (their displacements cancel where both act)."))
        self.reset_button.setEnabled(edited)

    def selected_pairs(self) -> list[tuple[str, str]]:
        return [tuple(it.data(0, QtCore.Qt.UserRole)) for it in self.table.selectedItems()]

    def pairs(self) -> list[tuple[str, str]]:
        return [tuple(self.table.topLevelItem(i).data(0, QtCore.Qt.UserRole))
                for i in range(self.table.topLevelItemCount())]
