"""The Shapes panel, like Maya's Shape Editor: a slider and a number box per shape, a name filter,
reset, and presets. It shows weights and emits the user's gestures; the app turns them into undo steps.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

SLIDER_STEPS = 1000
ROWS_AT_ONCE = 32   # Shapes panel rows made in one turn of the event loop (~1-2 ms each) for a studio rig's list,
ALL_AT_ONCE = 64    # but every row at once up to this many (ICT FaceKit's 57)
# and no more rows in a later turn than fit in this many seconds: a turn of 32 rows took 55 ms beside a 422k-vertex
# rig's first render, which the same turn of the event loop may run (the window answers neither meanwhile)
ROWS_BUDGET = 0.012


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

    def focusInEvent(self, event) -> None:  # Qt override
        # The undo filter only while the box has the focus (the shortcuts go to the focus widget): on every box
        # all the time it ran Python for every event of hundreds of boxes (a 228-shape rig's rows being laid out),
        # each call waiting for the interpreter while a background job ran
        if _NumberBox._undo_filter is None:
            _NumberBox._undo_filter = _UndoShortcutFilter()
        self.installEventFilter(_NumberBox._undo_filter)            # the box has the focus, or
        self.lineEdit().installEventFilter(_NumberBox._undo_filter)  # its line edit does
        super().focusInEvent(event)

    def focusOutEvent(self, event) -> None:  # Qt override
        if _NumberBox._undo_filter is not None:
            self.removeEventFilter(_NumberBox._undo_filter)
            self.lineEdit().removeEventFilter(_NumberBox._undo_filter)
        super().focusOutEvent(event)


class _ShapeRow(QtWidgets.QWidget):
    """One shape: its name (click selects, Ctrl+click adds to the selection, right-click for the shape menu,
    F2 renames in place), Mute and Solo buttons, a slider over the shape's range and a number box.

    A row can start empty (``build=False``): as tall as a built row, holding its shape's state (name, mute, solo,
    range, in-betweens, weight, selection), its widgets made when it is built (``build``), or when one of them is
    first asked for. The panel builds a studio rig's rows a few dozen a turn of the event loop, those in view first
    (``ShapesPanel._build_some``): made in one go, 228 rows held the window 0.26-0.33 s and 700 rows 0.72-1.05 s;
    now the first 32 rows come with the list and each later turn makes rows for at most ``ROWS_BUDGET``."""

    _PARTS = frozenset({"label", "mute", "solo", "slider", "box"})
    height_hint = 0          # a built row's height, the height an empty row keeps

    def __init__(self, index: int, name: str, panel: "ShapesPanel", build: bool = True) -> None:
        super().__init__(panel)
        self.index, self.name, self.panel = index, "", panel
        self.lo, self.hi = 0.0, 1.0
        self.editor: QtWidgets.QLineEdit | None = None
        self.built = False
        self._dragging = False
        self._bold = False
        self._selected = False
        self._muted = self._solo = False
        self._value = 0.0
        self._inbetweens: tuple = ()
        self._press_at: QtCore.QPoint | None = None
        self.set_name(index, name)
        if build or not _ShapeRow.height_hint:
            self.build()
        else:
            self.setMinimumHeight(_ShapeRow.height_hint)

    def __getattr__(self, name: str):
        # only for attributes not found: an empty row's widgets are made when first asked for
        if name in _ShapeRow._PARTS and not self.__dict__.get("built", True):
            self.build()
            return getattr(self, name)
        raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")

    def build(self) -> None:
        """Make the row's widgets and show its shape's state in them (once)."""
        if self.built:
            return
        self.built = True
        panel = self.panel
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(2, 0, 2, 0)
        lay.setSpacing(3)
        self.label = QtWidgets.QLabel()
        self.label.setFixedWidth(150)        # the M and S buttons and the sliders line up
        self.mute = self._toggle("M", "Mute {}: leave it out of the pose (its correctives too); undoable", "#c9302c")
        self.solo = self._toggle("S", "Solo {}: show only the soloed shapes (Ctrl+click: solo only this one); undoable",
                                 "#d4a017")
        self.slider = _Slider(QtCore.Qt.Horizontal)
        self.slider.setFocusPolicy(QtCore.Qt.StrongFocus)
        self.slider.setRange(0, SLIDER_STEPS)
        self.box = _NumberBox()
        self.box.setFocusPolicy(QtCore.Qt.StrongFocus)
        self.box.setRange(self.lo, self.hi)
        self.box.setDecimals(3)
        self.box.setSingleStep(0.05)
        self.box.setKeyboardTracking(False)
        self.box.setFixedWidth(72)
        lay.addWidget(self.label)
        lay.addWidget(self.mute)
        lay.addWidget(self.solo)
        lay.addWidget(self.slider, 1)
        lay.addWidget(self.box)
        self._show_name()
        self.mute.setChecked(self._muted)
        self.solo.setChecked(self._solo)
        self.label.setEnabled(not self._muted)
        self._show_value()
        if self._selected:
            self.label.setForegroundRole(QtGui.QPalette.HighlightedText)
        self.label.setContextMenuPolicy(QtCore.Qt.CustomContextMenu)
        self.label.customContextMenuRequested.connect(self._menu)
        self.slider.setContextMenuPolicy(QtCore.Qt.CustomContextMenu)   # the slider's menu too (Key <shape>)
        self.slider.customContextMenuRequested.connect(lambda pos: self._menu(pos, self.slider))
        self.label.mousePressEvent = self._label_pressed
        self.label.mouseMoveEvent = self._label_moved
        self.label.mouseReleaseEvent = self._label_released
        self.label.mouseDoubleClickEvent = lambda _e: self.start_rename()
        self.mute.clicked.connect(lambda on: panel.shape_edited.emit(ShapeEdit("mute", self.name, on=on)))
        self.solo.clicked.connect(self._solo_clicked)
        self.slider.sliderPressed.connect(self._pressed)
        self.slider.sliderReleased.connect(self._released)
        self.slider.valueChanged.connect(self._slider_moved)
        self.box.valueChanged.connect(self._box_changed)
        if not _ShapeRow.height_hint:
            _ShapeRow.height_hint = self.sizeHint().height()
        self.setMinimumHeight(0)
        if self.isVisible():             # made inside a shown row: shown now, not on the event loop's next turn
            for w in (self.label, self.mute, self.solo, self.slider, self.box):
                w.show()

    def _toggle(self, text: str, tip: str, on_colour: str) -> QtWidgets.QToolButton:
        b = QtWidgets.QToolButton()
        b.setText(text)
        b.setCheckable(True)
        b.setAutoRaise(True)
        b.setFixedWidth(22)
        b.setStyleSheet(f"QToolButton:checked {{ background: {on_colour}; color: white; font-weight: bold; "
                        "border-radius: 3px; }")
        b.setProperty("tip", tip)
        return b

    def set_name(self, index: int, name: str) -> None:
        """Show shape ``name`` at list position ``index`` (rows are reused when shapes move or are renamed)."""
        self.index = index
        if name == self.name:
            return
        self.name = name
        if self.built:
            self._show_name()

    def _show_name(self) -> None:
        self.slider.setObjectName(f"slider_{self.name}")
        self.slider.setToolTip(f"Weight of {self.name}: drag to pose (one drag is one undo step)")
        for b in (self.mute, self.solo):
            b.setToolTip(b.property("tip").format(self.name))
        self._show_label()
        self._show_range_tip()

    def _show_label(self) -> None:
        mark = " ◆" if self._inbetweens else ""
        self.label.setText(self.name + mark)
        tip = f"{self.name} (click selects, F2 renames, right-click for the shape menu)"
        if self._inbetweens:
            tip += "\nIn-betweens at " + ", ".join(f"{w:g}" for w in self._inbetweens)
        self.label.setToolTip(tip)

    def _show_range_tip(self) -> None:
        self.box.setToolTip(f"Weight of {self.name} ({self.lo:g} to {self.hi:g}; right-click the name: Set Range)")

    def set_info(self, muted: bool, solo: bool, lo: float, hi: float, inbetweens: tuple) -> None:
        """Mute, solo, slider range and in-between weights of this row's shape."""
        self._muted, self._solo = bool(muted), bool(solo)
        if not self.built:
            self.lo, self.hi, self._inbetweens = lo, hi, tuple(inbetweens)
            return
        for b, on in ((self.mute, muted), (self.solo, solo)):
            if b.isChecked() != on:
                b.setChecked(on)
        self.label.setEnabled(not muted)
        if (lo, hi) != (self.lo, self.hi):
            self.lo, self.hi = lo, hi
            self.box.blockSignals(True)
            self.box.setRange(lo, hi)
            self.box.blockSignals(False)
            self._show_range_tip()
            self.set_value(self._value, force=True)
        if tuple(inbetweens) != self._inbetweens:
            self._inbetweens = tuple(inbetweens)
            self._show_label()

    def set_selected(self, on: bool) -> None:
        if on != self._selected:
            self._selected = on
            self.setAutoFillBackground(on)
            self.setBackgroundRole(QtGui.QPalette.Highlight if on else QtGui.QPalette.Window)
            if self.built:
                self.label.setForegroundRole(QtGui.QPalette.HighlightedText if on else QtGui.QPalette.WindowText)

    def _to_steps(self, value: float) -> int:
        return int(round((value - self.lo) / (self.hi - self.lo) * SLIDER_STEPS))

    def _from_steps(self, v: int) -> float:
        value = self.lo + v / SLIDER_STEPS * (self.hi - self.lo)
        return 0.0 if abs(value) < 1e-12 else round(value, 6)

    def set_value(self, value: float, force: bool = False) -> None:
        self._value = value
        if self.built:
            self._show_value()

    def _show_value(self) -> None:
        value = self._value
        for w in (self.slider, self.box):
            w.blockSignals(True)
        self.slider.setValue(self._to_steps(value))
        self.box.setValue(value)
        for w in (self.slider, self.box):
            w.blockSignals(False)
        active = value != 0
        if active != self._bold:  # style sheets are slow: only touch the label when it changes
            self._bold = active
            self.label.setStyleSheet("font-weight: bold;" if active else "")

    # --- gestures ---------------------------------------------------------------------------------------
    def _label_pressed(self, event) -> None:
        if event.button() == QtCore.Qt.LeftButton:
            extend = bool(event.modifiers() & QtCore.Qt.ControlModifier)
            if extend or self.name not in self.panel.selected:
                self.panel.select(self.name, extend=extend)
            else:
                self.panel._rows_host.setFocus()
            self._press_at = event.position().toPoint()

    def _label_moved(self, event) -> None:
        """Dragging a name moves the selected shapes: a line shows where they will go."""
        if self._press_at is None or not event.buttons() & QtCore.Qt.LeftButton:
            return
        if not self.panel.dragging and (event.position().toPoint() - self._press_at).manhattanLength() \
                < QtWidgets.QApplication.startDragDistance():
            return
        self.panel.drag_to(self.label.mapToGlobal(event.position().toPoint()))

    def _label_released(self, event) -> None:
        self._press_at = None
        if self.panel.dragging:
            self.panel.drop(self.label.mapToGlobal(event.position().toPoint()))
        elif event.button() == QtCore.Qt.LeftButton and not event.modifiers() & QtCore.Qt.ControlModifier \
                and self.panel.selected != [self.name]:
            self.panel.select(self.name)     # a click (no drag) on a selected shape selects it alone

    def _solo_clicked(self, on: bool) -> None:
        exclusive = bool(QtWidgets.QApplication.keyboardModifiers() & QtCore.Qt.ControlModifier)
        self.panel.shape_edited.emit(ShapeEdit("solo", self.name, on=on, exclusive=exclusive))

    def start_rename(self) -> None:
        """Edit the name in place (F2 or a double-click); Enter renames (one undo step), Escape cancels."""
        if self.editor is not None:
            return
        self.editor = ed = _NameEditor(self.name, self.label)
        ed.setGeometry(self.label.rect())
        ed.finished.connect(self._rename_done)
        ed.show()
        ed.setFocus()
        ed.selectAll()

    def _rename_done(self, text: str | None) -> None:
        ed, self.editor = self.editor, None
        if ed is not None:
            ed.hide()
            ed.deleteLater()
        self.panel._rows_host.setFocus()
        if text is not None and text.strip() and text.strip() != self.name:
            self.panel.shape_edited.emit(ShapeEdit("rename", self.name, text=text.strip()))

    def _menu(self, pos, where=None) -> None:
        """The shape's right-click menu, on its name or its slider (``where``)."""
        if self.name not in self.panel.selected:
            self.panel.select(self.name)
        menu = self.panel.shape_menu(self)
        self.context_menu = menu   # tests pick its actions
        menu.popup((where or self.label).mapToGlobal(pos))

    def _pressed(self) -> None:
        self._dragging = True
        self.panel.pose_edited.emit(PoseEdit("drag-start", self.index))

    def _released(self) -> None:
        self._dragging = False
        self.panel.pose_edited.emit(PoseEdit("drag-end", self.index))

    def _slider_moved(self, v: int) -> None:
        value = self._from_steps(v)
        self._value = value
        self.box.blockSignals(True)
        self.box.setValue(value)
        self.box.blockSignals(False)
        # while dragging: live; keyboard, wheel or a click on the groove: one step each
        self.panel.pose_edited.emit(PoseEdit("drag" if self._dragging else "set", self.index, value))

    def _box_changed(self, value: float) -> None:
        self.panel.pose_edited.emit(PoseEdit("set", self.index, float(value)))


class _NameEditor(QtWidgets.QLineEdit):
    """The in-place name editor: ``finished(text)`` on Enter, ``finished(None)`` on Escape or leaving it."""

    finished = QtCore.Signal(object)

    def __init__(self, text: str, parent) -> None:
        super().__init__(text, parent)
        self._done = False

    def _finish(self, value) -> None:
        if not self._done:
            self._done = True
            self.finished.emit(value)

    def keyPressEvent(self, event) -> None:
        if event.key() in (QtCore.Qt.Key_Return, QtCore.Qt.Key_Enter):
            self._finish(self.text())
        elif event.key() == QtCore.Qt.Key_Escape:
            self._finish(None)
        else:
            super().keyPressEvent(event)

    def focusOutEvent(self, event) -> None:
        super().focusOutEvent(event)
        self._finish(self.text())


@dataclass(frozen=True)
class ShapeEdit:
    """One gesture of the Shapes panel on the shape list (each one undo step, made by the app): ``kind`` is
    "rename" (``text``: the new name), "duplicate", "delete" (``names``), "move-up"/"move-down" (``names``), "move-to" (``names`` before list position ``text``),
    "sort" (``text``: "name" or "group"), "mute"/"solo" (``on``; solo ``exclusive``: the only soloed one),
    "range" (ask for the slider range), "inbetween-pose"/"inbetween-obj" (add an in-between from the shown
    surface or an OBJ file), "remove-inbetweens", "mirror"."""

    kind: str
    shape: str = ""
    names: tuple = ()
    text: str = ""
    on: bool = False
    exclusive: bool = False


GROUPINGS = (("none", "No groups"), ("prefix", "By face part"), ("side", "By side"))
# the panel's own keys, live while the shape list has the focus: (key, kind, what Help ▸ Keyboard Shortcuts says)
SHAPE_KEYS = (("F2", "rename", "Rename Shape"), ("Delete", "delete", "Delete Shape (with its correctives)"),
              ("Ctrl+D", "duplicate", "Duplicate Shape"), ("Alt+Up", "move-up", "Move Shape Up"),
              ("Alt+Down", "move-down", "Move Shape Down"))


class _GroupHeader(QtWidgets.QToolButton):
    """A collapsible group of the shape list ("brow (6)"): click folds or unfolds it."""

    def __init__(self, name: str, panel: "ShapesPanel") -> None:
        super().__init__(panel)
        self.group = name
        self.setCheckable(True)
        self.setChecked(True)
        self.setAutoRaise(True)
        self.setToolButtonStyle(QtCore.Qt.ToolButtonTextBesideIcon)
        self.setSizePolicy(QtWidgets.QSizePolicy.Expanding, QtWidgets.QSizePolicy.Fixed)
        self.setStyleSheet("QToolButton { font-weight: bold; text-align: left; }")
        self.setToolTip(f"Fold or unfold the {name} shapes")
        self.setArrowType(QtCore.Qt.DownArrow)
        self.toggled.connect(lambda on: self.setArrowType(QtCore.Qt.DownArrow if on else QtCore.Qt.RightArrow))
        self.setObjectName(f"group_{name}")


_MANY_ROWS = 16     # rows whose visibility changes at once, above which the host is hidden meanwhile


@contextmanager
def _layout_held(host: QtWidgets.QWidget, many: bool):
    """Hide ``host`` while its rows are shown or hidden (``many``), then show it again, keeping the keyboard focus
    where it was. A row shown inside a visible host lays the host out again at once (~3 ms a row at 228 rows, and
    more with more: 0.27 s for 228 rows, 2.0 s for 700); inside a hidden one it is only marked, and the host is laid
    out once when shown."""
    if not (many and host.isVisible()):
        yield
        return
    focus = QtWidgets.QApplication.focusWidget()
    focus = focus if focus is not None and (focus is host or host.isAncestorOf(focus)) else None
    host.setUpdatesEnabled(False)
    host.hide()
    try:
        yield
    finally:
        host.show()
        host.setUpdatesEnabled(True)
        if focus is not None and focus.isVisible():
            focus.setFocus(QtCore.Qt.OtherFocusReason)


class ShapesPanel(QtWidgets.QWidget):
    """Sliders for every shape, in the rig's order, optionally in collapsible groups (by face part or side).
    Every gesture on the pose is one ``pose_edited(PoseEdit)``; every gesture on the shape list one
    ``shape_edited(ShapeEdit)``; the window turns them into undo steps."""

    pose_edited = QtCore.Signal(object)           # a PoseEdit
    shape_edited = QtCore.Signal(object)          # a ShapeEdit
    mirror_shape_requested = QtCore.Signal(int)   # make the other side's shape from this one (right-click)
    key_shape_requested = QtCore.Signal(int)      # key this shape alone at the current time (right-click)
    selection_changed = QtCore.Signal(list)       # the selected shape names

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
        self.grouping = QtWidgets.QComboBox()
        for key, label in GROUPINGS:
            self.grouping.addItem(label, key)
        self.grouping.setSizeAdjustPolicy(QtWidgets.QComboBox.AdjustToContents)
        self.grouping.setToolTip("Show the shapes in collapsible groups by face part (brow, eye, mouth...: the "
                                 "first word of the name) or by side (_L, _R, centre)")
        self.grouping.currentIndexChanged.connect(lambda _i: self._arrange())
        top.addWidget(self.filter, 1)
        top.addWidget(self.active_only)
        top.addWidget(self.grouping)     # here, not in the edit buttons' row: there it was cut ("No grc") at 400 px
        lay.addLayout(top)
        row = QtWidgets.QHBoxLayout()
        self.presets = QtWidgets.QComboBox()
        self.presets.setToolTip("Emotion presets: choose one, then Apply sets its weights (undoable)")
        # none chosen until the user picks one: the first preset shown as if chosen made picking it no change
        self.presets.setPlaceholderText("Choose a preset…")
        self.apply_preset = QtWidgets.QPushButton("Apply")
        self.apply_preset.setToolTip("Set the weights of the selected preset (with none chosen, opens the list)")
        self.apply_preset.clicked.connect(self._preset_clicked)
        self.reset = QtWidgets.QPushButton("Reset all")
        self.reset.setToolTip("Set every weight to 0 (undoable)")
        self.reset.clicked.connect(lambda: self.pose_edited.emit(PoseEdit("reset")))
        row.addWidget(QtWidgets.QLabel("Preset"))
        row.addWidget(self.presets, 1)
        row.addWidget(self.apply_preset)
        row.addWidget(self.reset)
        lay.addLayout(row)
        edit_row = QtWidgets.QHBoxLayout()
        self.buttons: dict[str, QtWidgets.QToolButton] = {}
        for kind, text, tip in (("move-up", "▲", "Move the selected shapes up (Alt+Up; undoable)"),
                                ("move-down", "▼", "Move the selected shapes down (Alt+Down; undoable)"),
                                ("rename", "Rename", "Rename the selected shape (F2 or double-click the name; undoable)"),
                                ("duplicate", "Duplicate", "Copy the selected shape, with its in-betweens (Ctrl+D; undoable)"),
                                ("delete", "Delete", "Delete the selected shapes and the correctives that need them "
                                                     "(Delete; undo brings all of it back)")):
            b = QtWidgets.QToolButton()
            b.setText(text)
            b.setToolTip(tip)
            b.setObjectName(f"shape_{kind}")
            b.clicked.connect(lambda _=False, k=kind: self.request(k))
            edit_row.addWidget(b)
            self.buttons[kind] = b
        sort = QtWidgets.QToolButton()
        sort.setText("Sort")
        sort.setToolTip("Reorder the shape list by name or by face part (undoable)")
        sort.setPopupMode(QtWidgets.QToolButton.InstantPopup)
        sort_menu = QtWidgets.QMenu(sort)
        self.sort_actions = {}
        for by, label in (("name", "Sort by Name"), ("group", "Sort by Face Part")):
            act = sort_menu.addAction(label)
            act.triggered.connect(lambda _=False, b=by: self.shape_edited.emit(ShapeEdit("sort", text=b)))
            self.sort_actions[by] = act
        sort.setMenu(sort_menu)
        edit_row.addWidget(sort)
        edit_row.addStretch(1)
        lay.addLayout(edit_row)
        self.scroll = QtWidgets.QScrollArea()
        self.scroll.setWidgetResizable(True)
        self._rows_host = QtWidgets.QWidget()
        self._rows_host.setFocusPolicy(QtCore.Qt.ClickFocus)
        self._rows_layout = QtWidgets.QVBoxLayout(self._rows_host)
        self._rows_layout.setSpacing(1)
        self._rows_layout.addStretch(1)
        self.scroll.setWidget(self._rows_host)
        lay.addWidget(self.scroll, 1)
        for key, kind, what in SHAPE_KEYS:
            # while the list has the focus (a click on a shape's name gives it): a number box keeps its Delete
            sc = QtGui.QShortcut(QtGui.QKeySequence(key), self._rows_host)
            sc.setContext(QtCore.Qt.WidgetShortcut)
            sc.setWhatsThis(what)
            sc.activated.connect(lambda k=kind: self.request(k))
        self.rows: list[_ShapeRow] = []
        self.headers: dict[str, _GroupHeader] = {}
        self.selected: list[str] = []
        self._groups: list[tuple[str, list[int]]] = []
        self._weights = np.zeros(0)
        self._arranged: tuple | None = None
        self._drop_line: QtWidgets.QFrame | None = None
        self._build_timer = QtCore.QTimer(self)   # the next turn of _build_some (the panel's own: none after it)
        self._build_timer.setSingleShot(True)
        self._build_timer.setInterval(0)
        self._build_timer.timeout.connect(self._build_some)
        self.scroll.verticalScrollBar().valueChanged.connect(self._build_later)

    # --- content ---------------------------------------------------------------------------------------
    def set_shapes(self, names: list[str], presets: list[str] | None = None) -> None:
        """One row per shape, in list order. Rows are reused (a reorder or rename relabels them; a corrective
        edit changes nothing here and rebuilding 57 rows made the panel flicker)."""
        names = list(names)
        current = [self.presets.itemText(i) for i in range(self.presets.count())]
        if current != list(presets or []):
            chosen = self.presets.currentText() if self.presets.currentIndex() >= 0 else ""
            self.presets.clear()
            self.presets.addItems(presets or [])
            self.presets.setCurrentIndex(self.presets.findText(chosen) if chosen else -1)   # -1: the placeholder
        # enabled only with presets to apply, whatever the list was (a window opened straight on a rig without
        # presets kept the empty list's controls enabled: Apply did nothing)
        self.presets.setEnabled(bool(presets))
        self.apply_preset.setEnabled(bool(presets))
        if [r.name for r in self.rows] == names:
            return
        old = [r.name for r in self.rows]
        keep = 0   # rows showing the same names in the same places keep their weights
        while keep < min(len(old), len(names)) and old[keep] == names[keep]:
            keep += 1
        for r in self.rows[len(names):]:
            r.setParent(None)
            r.deleteLater()
        self.rows = self.rows[:len(names)]
        for i, name in enumerate(names):
            if i < len(self.rows):
                self.rows[i].set_name(i, name)
            else:   # a screenful or two made now, the rest a few dozen a turn of the event loop (_build_some)
                self.rows.append(_ShapeRow(i, name, self, build=len(names) <= ALL_AT_ONCE or i < ROWS_AT_ONCE))
        w = np.full(len(names), np.nan)        # rows that now show another shape are refreshed by set_weights
        w[:keep] = self._weights[:keep]
        self._weights = w
        self.selected = [n for n in self.selected if n in names]
        self._arrange()
        self._build_later()

    def _build_later(self, _value=None) -> None:
        """Make the empty rows on the next turns of the event loop (a new list, a scroll of the list)."""
        if not self._build_timer.isActive() and not all(r.built for r in self.rows):
            self._build_timer.start()

    def _build_some(self) -> None:
        """Build the next rows still empty: those in view first, then in list order, ``ROWS_AT_ONCE`` a turn at
        most, and no more once ``ROWS_BUDGET`` has passed (one at least)."""
        empty = [r for r in self.rows if not r.built]
        if not empty:
            return
        view = self.scroll.viewport()
        top = self._rows_host.mapFrom(view, QtCore.QPoint(0, 0)).y()
        seen = [r for r in empty if not r.isHidden() and r.y() + r.height() >= top and r.y() <= top + view.height()]
        chosen = seen[:ROWS_AT_ONCE]
        chosen += [r for r in empty if r not in chosen][:ROWS_AT_ONCE - len(chosen)]
        # the list's layout off meanwhile: a row whose widgets are shown would lay out the whole list again each
        # time (the rows keep their places: an empty row is as tall as a built one)
        self._rows_layout.setEnabled(False)
        end = time.perf_counter() + ROWS_BUDGET
        built = 0
        try:
            for r in chosen:
                r.build()
                built += 1
                if time.perf_counter() > end:
                    break
        finally:
            self._rows_layout.setEnabled(True)
            self._rows_layout.update()
        if built < len(empty):
            self._build_timer.start()

    def finish_rows(self) -> None:
        """Build every row now (what waits for a studio rig's last rows, e.g. a test or a screenshot)."""
        for r in self.rows:
            r.build()

    def set_shape_info(self, muted, solo, ranges: dict, inbetweens: dict) -> None:
        """Mute and solo state, slider ranges {name: (lo, hi)} and in-between weights {name: [w, ...]}."""
        muted, solo = set(muted), set(solo)
        for r in self.rows:
            lo, hi = ranges.get(r.name, (0.0, 1.0))
            r.set_info(r.name in muted, r.name in solo, lo, hi, tuple(inbetweens.get(r.name, ())))

    def _arrange(self) -> None:
        """Lay the rows out in list order, under group headers when grouping."""
        from model.shape_edits import shape_groups
        names = [r.name for r in self.rows]
        by = self.grouping.currentData()
        key = (tuple(names), by)
        if key == self._arranged:
            return
        self._arranged = key
        self._groups = [] if by == "none" else shape_groups(names, by)
        lay = self._rows_layout
        while lay.count() > 1:          # everything but the final stretch
            lay.takeAt(0)
        wanted = {g for g, _ in self._groups}
        for g in list(self.headers):
            if g not in wanted:
                self.headers.pop(g).deleteLater()
        if not self._groups:
            for i, r in enumerate(self.rows):
                lay.insertWidget(i, r)
        else:
            pos = 0
            for g, idx in self._groups:
                h = self.headers.get(g)
                if h is None:
                    h = self.headers[g] = _GroupHeader(g, self)
                    h.toggled.connect(lambda _on: self._apply_filter(self.filter.text()))
                h.setText(f"{g} ({len(idx)})")
                lay.insertWidget(pos, h)
                pos += 1
                for i in idx:
                    lay.insertWidget(pos, self.rows[i])
                    pos += 1
        for h in self.headers.values():
            h.setVisible(bool(self._groups))
        self._apply_filter(self.filter.text())
        self._show_selection()

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

    def set_group_expanded(self, group: str, expanded: bool) -> None:
        self.headers[group].setChecked(expanded)

    def _apply_filter(self, text: str) -> None:
        text = text.strip().lower()
        only_active = self.active_only.isChecked()
        folded = {i for g, idx in self._groups if not self.headers[g].isChecked() for i in idx}
        shown_in: dict[str, int] = {}
        changes = []
        for r in self.rows:
            w = self._weights[r.index] if r.index < self._weights.size else 0.0
            match = bool(text in r.name.lower() and (not only_active or (np.isfinite(w) and w != 0)))
            visible = match and r.index not in folded
            if r.isHidden() == visible:   # only the rows that change
                changes.append((r, visible))
            if match:
                shown_in[r.name] = 1
        with _layout_held(self._rows_host, len(changes) > _MANY_ROWS):
            for r, visible in changes:
                r.setVisible(visible)
        for g, idx in self._groups:      # a group with no matching shape hides its header too
            any_match = any(self.rows[i].name in shown_in for i in idx)
            h = self.headers[g]
            if h.isHidden() == any_match:
                h.setVisible(any_match)

    # --- selection and shape-list requests -------------------------------------------------------------
    def select(self, name: str | None, extend: bool = False) -> None:
        """Select a shape (``extend``: add it to the selection, or take it out if it was in)."""
        if name is None:
            self.selected = []
        elif extend:
            self.selected = [n for n in self.selected if n != name] + ([] if name in self.selected else [name])
        else:
            self.selected = [name]
        self._show_selection()
        self._rows_host.setFocus()
        self.selection_changed.emit(list(self.selected))

    def _show_selection(self) -> None:
        chosen = set(self.selected)
        for r in self.rows:
            r.set_selected(r.name in chosen)

    @property
    def dragging(self) -> bool:
        return self._drop_line is not None and self._drop_line.isVisible()

    def _drop_place(self, global_pos: QtCore.QPoint) -> tuple[int, int]:
        """(list position the dragged shapes go before, y of the line in the list) for the pointer."""
        y = self._rows_host.mapFromGlobal(global_pos).y()
        shown = [r for r in self.rows if not r.isHidden()]
        if not shown:
            return 0, 0
        for r in shown:
            g = r.geometry()
            if y < g.center().y():
                return r.index, g.top()
        last = shown[-1]
        return last.index + 1, last.geometry().bottom()

    def drag_to(self, global_pos: QtCore.QPoint) -> None:
        if self._drop_line is None:
            self._drop_line = QtWidgets.QFrame(self._rows_host)
            self._drop_line.setFrameShape(QtWidgets.QFrame.HLine)
            self._drop_line.setStyleSheet("color: palette(highlight); background: palette(highlight);")
        _, y = self._drop_place(global_pos)
        self._drop_line.setGeometry(0, max(0, y - 1), self._rows_host.width(), 3)
        self._drop_line.raise_()
        self._drop_line.show()

    def drop(self, global_pos: QtCore.QPoint) -> None:
        """End a drag: the selected shapes move (one undo step) to before the shape under the pointer."""
        place, _ = self._drop_place(global_pos)
        self._drop_line.hide()
        if self.selected:
            self.shape_edited.emit(ShapeEdit("move-to", self.selected[0], names=tuple(self.selected), text=str(place)))

    def request(self, kind: str) -> None:
        """A shape-list gesture on the selection (a button, a key, a menu entry): one ``shape_edited``."""
        if not self.selected:
            return
        first = self.selected[0]
        if kind == "rename":
            self.row(first).start_rename()
            return
        self.shape_edited.emit(ShapeEdit(kind, first, names=tuple(self.selected)))

    def shape_menu(self, row: _ShapeRow) -> QtWidgets.QMenu:
        """The right-click menu of a shape (Maya's Shape Editor's target menu)."""
        menu = QtWidgets.QMenu(row)
        menu.setAttribute(QtCore.Qt.WA_DeleteOnClose)
        name = row.name

        def add(text: str, tip: str, slot) -> QtGui.QAction:
            act = menu.addAction(text)
            act.setToolTip(tip)
            act.triggered.connect(slot)
            return act
        add(f"Key {name}", "Key this shape alone at the current time (its own curve in the Graph Editor)",
            lambda: self.key_shape_requested.emit(row.index))
        menu.addSeparator()
        add("Rename\tF2", f"Rename {name} everywhere it is used (correctives, presets)", lambda: row.start_rename())
        add("Duplicate\tCtrl+D", f"Copy {name} with its in-betweens and range", lambda: self.request("duplicate"))
        add("Delete\tDel", "Delete the selected shapes and the correctives that need them", lambda: self.request("delete"))
        menu.addSeparator()
        add("Move Up\tAlt+Up", "Move the selected shapes one place up", lambda: self.request("move-up"))
        add("Move Down\tAlt+Down", "Move the selected shapes one place down", lambda: self.request("move-down"))
        menu.addSeparator()
        add("Set Range…", f"The slider range of {name}: overdrive beyond 1, negative weights",
            lambda: self.shape_edited.emit(ShapeEdit("range", name)))
        add("Add In-between from Current Pose…", f"The surface shown now becomes {name}'s target at a weight "
            "between its keys (Maya's in-between)", lambda: self.shape_edited.emit(ShapeEdit("inbetween-pose", name)))
        add("Add In-between from OBJ…", f"An OBJ with the neutral's vertex order becomes {name}'s target at a weight",
            lambda: self.shape_edited.emit(ShapeEdit("inbetween-obj", name)))
        rm = add("Remove In-betweens", f"Remove every in-between of {name}",
                 lambda: self.shape_edited.emit(ShapeEdit("remove-inbetweens", name)))
        rm.setEnabled(bool(row._inbetweens))
        menu.addSeparator()
        add("Mirror to the Other Side", "Make (or replace) the other side's shape as this one's mirror image "
            "across x = 0", lambda: self.mirror_shape_requested.emit(row.index))
        menu.setToolTipsVisible(True)
        return menu

    def _preset_clicked(self) -> None:
        if self.presets.currentIndex() >= 0 and self.presets.currentText():
            self.pose_edited.emit(PoseEdit("preset", preset=self.presets.currentText()))
        elif self.presets.count():
            self.presets.showPopup()     # nothing chosen yet: the list to choose from

    def set_target(self, text: str) -> None:
        """Say which weights the sliders edit (the global pose, a region's weights)."""
        self.target.setText(text)
