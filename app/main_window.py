"""The main window: viewport in the centre, panels in docks, menus, undo, status bar.

It wires widgets' gestures to undo commands on the Document and redraws views on its signals.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from app import batch_controller, corrective_controller, mocap_controller, personalize_controller, \
    texture_controller
from app import session_state
from app import settings as app_settings
from app.autosave import AutosaveController
from app.background import JobQueue, run_modal
from app.commands import SetWeightsCommand
from app.document import Document
from app.export_controller import ExportController
from app.keyframe_controller import KeyframeController
from app.loading import LoadWorker
from app.marker_controller import MarkerController
from app.parts_controller import PartsController
from app.segmentation_controller import SegmentationController
from app.shape_list_controller import ShapeListController
from model.atomic import write_error
from model.errors import RigInputError
from model.project import Project
from model.rig_prep import focus_vertices
from model.wording import count
from solvers.mesh import extent
from widgets.file_drops import FileDropTarget
from widgets.segmentation_panel import SegmentationPanel
from widgets.shapes_panel import PoseEdit, ShapesPanel
from widgets.viewport import Viewport

RIG_FILTER = "Rigs and projects (*.bsproj *.gltf *.glb *.obj);;Projects (*.bsproj);;glTF (*.gltf *.glb);;OBJ (*.obj)"


# The menu bar, left to right: (stable key, label). Controllers address menus by key (``add_action("view", ...)``).
MENUS = (("file", "&File"), ("edit", "&Edit"), ("view", "&View"), ("animation", "&Animation"),
         ("correctives", "&Correctives"), ("help", "&Help"))


def _let_choices_shrink(panel: QtWidgets.QWidget) -> None:
    """A panel's drop-down lists may be narrower than their longest choice (the current one is cut, the open list
    shows every choice whole), so that a panel fits its dock at the window's default size instead of being cut
    off at the right behind a scroll bar. Qt's default sizes a combo box to its longest choice."""
    for combo in panel.findChildren(QtWidgets.QComboBox):
        if combo.sizeAdjustPolicy() == QtWidgets.QComboBox.AdjustToContentsOnFirstShow:   # Qt's default
            combo.setSizeAdjustPolicy(QtWidgets.QComboBox.AdjustToMinimumContentsLengthWithIcon)
            if not combo.minimumContentsLength():
                combo.setMinimumContentsLength(12)   # characters


class MainWindow(FileDropTarget, QtWidgets.QMainWindow):
    """The viewport, the panels in docks, the menus, undo and the status bar; it owns the controllers.

    Controllers plug in through a small public interface: ``add_dock``, ``add_menu``, ``add_action``,
    ``add_separator`` (menus by stable key, see MENUS), ``request_render``, ``show_status``, ``show_error``,
    ``save_dialog`` and ``set_pose``; they read ``document``, ``viewport``, ``segmentation``, ``shapes_panel``
    and ``segmentation_panel``. Nothing outside this class touches its private members.
    """

    load_failed = QtCore.Signal(str)  # the message shown to the user

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Blendshape Studio")
        self.resize(1400, 900)
        self.confirm_discard = True   # tests turn the unsaved-changes question off
        self.last_error: str | None = None
        self.shortcuts_dialog: QtWidgets.QDialog | None = None   # Help ▸ Keyboard Shortcuts, once opened
        self.image_size_dialog: QtWidgets.QDialog | None = None  # File ▸ Export Image's size, while open
        self._worker: LoadWorker | None = None
        self._shut_down = False   # the window is going: a load finishing now is dropped
        self._after_open: list = []   # what a drop opens once its rig is open (a take, a marker map)
        self.setAcceptDrops(True)     # files dropped on the window open (open_dropped)
        self._progress: QtWidgets.QProgressDialog | None = None
        self._drag_old: np.ndarray | None = None
        self._pose_stale = False   # the pose changed since the viewport's points were set (``_show_pose``)
        self._new_surface: np.ndarray | None = None   # the surface a rig change just gave the viewport
        self._menus: dict[str, QtWidgets.QMenu] = {}
        self._menu_ends: dict[str, QtGui.QAction] = {}   # actions added to a menu go before its end (File: Quit)
        self.document = Document(self)
        # an edit that copies the shapes' arrays (a reorder on a studio rig: seconds) runs off the GUI thread, the
        # window drawn and its input held, a busy dialog after 0.2 s (Document.edit_rig)
        self.document.run_edit = lambda label, fn: run_modal(self, "Shapes", f"{label}…", fn)
        self.jobs = JobQueue(self)   # exports and saves off the GUI thread (run_in_background)
        self.viewport = Viewport(self)
        self.viewport.before_render = self._show_pose   # every render of the viewport draws the pose of now
        self.setCentralWidget(self.viewport)
        self._build_menus()
        self.shapes_panel = ShapesPanel(self)
        app_settings.remember(self.shapes_panel.grouping, "shapes/grouping")   # by face part or side, next session too
        self.shapes_dock = self.add_dock("Shapes", self.shapes_panel, QtCore.Qt.RightDockWidgetArea)
        self.segmentation_panel = SegmentationPanel(self)
        self.segmentation_dock = self.add_dock("Segmentation", self.segmentation_panel, QtCore.Qt.LeftDockWidgetArea,
                                               scroll=True)
        self.undo_view = QtWidgets.QUndoView(self.document.undo_stack)
        self.undo_view.setEmptyLabel("<opened>")
        self.history_dock = self.add_dock("History", self.undo_view, QtCore.Qt.RightDockWidgetArea)
        self._build_status_bar()
        self._connect()
        # The controllers, each plugged in through the interface above (their panels, docks and actions).
        self.segmentation = SegmentationController(self, self.segmentation_panel)
        self.markers = MarkerController(self)
        self.keyframes = KeyframeController(self)
        self.correctives = corrective_controller.install(self)
        self.shape_list = ShapeListController(self)   # the Shapes list's edits (rename, reorder, mute, in-betweens...)
        self.mocap = mocap_controller.install(self)
        self.exports = ExportController(self)
        self.batch = batch_controller.install(self)
        self.actor = personalize_controller.install(self)   # personalisation, its heat map, antagonist pairs
        self.textures = texture_controller.install(self)
        self.autosave = AutosaveController(self)
        # one viewport tool at a time: sculpting turns marker mode off, marker mode (M) stops sculpting
        self.correctives.sculpting_changed.connect(lambda on: self.markers.mode_action.setChecked(False) if on else None)
        self.markers.mode_action.toggled.connect(
            lambda on: self.correctives.stop_sculpting() if on and self.correctives.sculpting else None)
        # a saved project's view, take and marker map come back once every controller has the new rig
        self.document.rig_changed.connect(lambda: session_state.restore(self))
        self._build_toolbar()
        self._arrange_docks()
        self._restore_layout()

    # --- the interface controllers use -------------------------------------------------------------
    def add_dock(self, title: str, widget: QtWidgets.QWidget, area, scroll: bool = False) -> QtWidgets.QDockWidget:
        """A dockable panel, listed in View ▸ Panels. ``scroll``: inside a scroll area, so a tall panel never
        forces the window taller than the screen (the left panels are ~700 px high; the window opens at 1400x900)."""
        dock = QtWidgets.QDockWidget(title, self)
        dock.setObjectName(f"dock_{title.replace(' ', '_')}")
        _let_choices_shrink(widget)
        if scroll:
            area_widget = QtWidgets.QScrollArea()
            area_widget.setWidget(widget)
            area_widget.setWidgetResizable(True)
            area_widget.setFrameShape(QtWidgets.QFrame.NoFrame)
            widget = area_widget
        dock.setWidget(widget)
        self.addDockWidget(area, dock)
        self._menus["panels"].addAction(dock.toggleViewAction())
        return dock

    def add_menu(self, key: str, title: str, parent: str) -> QtWidgets.QMenu:
        """A submenu ``title`` at the end of menu ``parent``, addressed as ``key`` from then on."""
        menu = QtWidgets.QMenu(title, self)
        self._menus[parent].insertMenu(self._menu_ends.get(parent), menu)
        self._menus[key] = menu
        return menu

    def add_action(self, menu: str, text: str, slot=None, shortcut=None, tip: str | None = None,
                   checkable: bool = False) -> QtGui.QAction:
        """An action at the end of menu ``menu`` (a key of MENUS or of ``add_menu``; File: before Quit), its
        shortcut live in the whole window. ``slot`` gets ``toggled(bool)`` if ``checkable``, else ``triggered``."""
        act = QtGui.QAction(text, self)
        if shortcut:
            act.setShortcut(QtGui.QKeySequence(shortcut))
        if tip:
            act.setStatusTip(tip)
            act.setToolTip(tip)
        act.setCheckable(checkable)
        if slot is not None:
            (act.toggled if checkable else act.triggered).connect(slot)
        self._menus[menu].insertAction(self._menu_ends.get(menu), act)
        self.addAction(act)
        return act

    def add_separator(self, menu: str) -> None:
        self._menus[menu].insertSeparator(self._menu_ends.get(menu))

    def request_render(self, *, after_input: bool = False) -> None:
        """Redraw the viewport with the current pose once this turn of the event loop is over: bursts of pose
        changes (slider drags, marker drags) coalesce into one render, the tools' overlays with them
        (``Viewport.request_render``; ``after_input``: after the input and timers waiting too)."""
        self._pose_stale = True
        self.viewport.request_render(after_input=after_input)

    def when_drawn(self, fn) -> None:
        """Call ``fn`` once the viewport shows what has changed: after the pending redraw, and after the input and
        timers waiting then (``Viewport.when_drawn``); at once when none is pending. A new studio rig's segmentation
        starts so (``app.segmentation_controller``): begun before the rig's first render, its thread made that render
        wait for the interpreter (0.04-0.15 s more of a frozen window at 422k vertices)."""
        self.viewport.when_drawn(fn)

    def redraw_now(self) -> None:
        """Redraw the viewport with the current pose now (a requested render still to come is then dropped)."""
        self._pose_stale = True
        self.viewport.render()

    def _show_pose(self) -> None:
        """The viewport's points set to the pose if it changed since (its ``before_render``). The very surface a rig
        change has just given the viewport (``_on_rig_change``) is only rendered: the document announces a new rig
        and then its pose, and the new surface is drawn once (~50 ms a render at 106k vertices, 0.16 s at 422k)."""
        if not self._pose_stale:
            return
        self._pose_stale = False
        given, self._new_surface = self._new_surface, None
        if self.document.project is not None:
            surface = self.document.surface()
            if surface is not given:
                self.viewport.update_points(surface, render=False)

    @property
    def redraw_pending(self) -> bool:
        """Whether a requested render has not happened yet."""
        return self.viewport.render_pending

    def run_in_background(self, text: str, job, on_done, on_failed=None) -> None:
        """Run ``job()`` off the GUI thread, control returning at once, a busy bar saying ``text`` meanwhile; then
        ``on_done(result)`` on the GUI thread, or ``on_failed(message)`` (default: an error box titled ``text``).
        Jobs run in turn, each one (exports, saves); a job must not touch widgets or the live document."""
        fail = on_failed or (lambda message: self.show_error(text.rstrip("…"), message))
        self.jobs.submit(text, job, on_done, fail)

    def show_status(self, message: str, timeout: int = 5000) -> None:
        """A message in the status bar for ``timeout`` ms (0: until the next one)."""
        self.statusBar().showMessage(message, timeout)

    # --- construction ------------------------------------------------------------------------------
    def _build_menus(self) -> None:
        mb = self.menuBar()
        for key, title in MENUS:
            self._menus[key] = mb.addMenu(title)
        act = self.add_action
        act("file", "Open Rig &Folder…", self.open_folder_dialog, "Ctrl+O",
            "Open a folder of OBJ blendshapes (the neutral is the file named *neutral*)")
        act("file", "&Open File…", self.open_file_dialog, "Ctrl+Shift+O",
            "Open a project (.bsproj), a glTF/GLB with morph targets, or an OBJ in a rig folder")
        self.recent_menu = self.add_menu("recent", "Open &Recent", parent="file")
        act("file", "Open &Sample Rig", self.open_sample, None, "Open the bundled sample face")
        self.add_separator("file")
        act("file", "&Save", self.save, QtGui.QKeySequence.Save, "Save the project (.bsproj)")
        act("file", "Save &As…", self.save_as, QtGui.QKeySequence.SaveAs, "Save the project under a new name")
        self.add_separator("file")
        act("file", "&Export Pose as OBJ…", self.export_pose, "Ctrl+E",
            "Write the posed surface as an OBJ, vertex order kept, with the rig's UVs, groups and materials")
        act("file", "Export &Image…", self.save_image_dialog, "Ctrl+Shift+E",
            "Write what the viewport shows (with its colour bar) as a PNG, at a width and height you choose")
        self.add_separator("file")
        self._menu_ends["file"] = act("file", "&Quit", self.close, QtGui.QKeySequence.Quit)

        e = self._menus["edit"]
        undo = self.document.undo_stack.createUndoAction(self, "&Undo")
        undo.setShortcut(QtGui.QKeySequence.Undo)
        redo = self.document.undo_stack.createRedoAction(self, "&Redo")
        redo.setShortcuts([QtGui.QKeySequence.Redo, QtGui.QKeySequence("Ctrl+Y")])
        e.addAction(undo)
        e.addAction(redo)
        self.undo_action, self.redo_action = undo, redo
        for action, name in ((undo, "Undo"), (redo, "Redo")):   # their text names the step ("Undo Key the pose…")
            action.setProperty("shortcutName", name)
        self.add_separator("edit")
        act("edit", "Reset &Pose", self.reset_pose, "Ctrl+0", "Set every weight to 0")
        act("edit", "&Mirror Pose", self.mirror_pose, "Ctrl+M",
            "Swap the weights of left and right shapes (_L↔_R): the pose of the other side")

        act("view", "&Wireframe", self.viewport.set_wireframe, "W", "Draw polygon edges over the surface",
            checkable=True)
        self.parts = PartsController(self)     # View ▸ Parts and View ▸ Material Colours
        self.add_separator("view")
        for i, (name, label) in enumerate([("front", "&Front"), ("left", "&Left Side"),
                                           ("right", "&Right Side"), ("three-quarter", "&Three-Quarter")]):
            act("view", f"{label} Camera", lambda _=False, n=name: self.viewport.set_camera(n), str(i + 1),
                f"Look at the face from the {name.replace('-', ' ')}")
        self.frame_selected_action = act("view", "&Frame Selected", self.frame_selected, "F",
                                         "Frame the selected marker (Marker mode) or region (Segmentation panel), "
                                         "else the face")
        self.frame_all_action = act("view", "Frame &All", self.frame_all, "A",
                                    "Frame the whole model as posed, from where the camera looks now (also Home in "
                                    "the view)")
        # Home too, but only in the viewport: lists, sliders and boxes keep Home for their first item
        home = QtGui.QShortcut(QtGui.QKeySequence("Home"), self.viewport, self.frame_all)
        home.setContext(QtCore.Qt.WidgetWithChildrenShortcut)
        home.setWhatsThis("Frame All (in the viewport)")
        act("view", "Reset &View", self.viewport.reset_view, None, "Back to the camera preset, framing the face")
        self.add_separator("view")
        self.add_menu("panels", "&Panels", parent="view")

        act("help", "&Keyboard Shortcuts", self.show_shortcuts, "F1")
        act("help", "&About Blendshape Studio", self.show_about)
        self._rebuild_recent_menu()

    def _build_toolbar(self) -> None:
        """The viewport's tools above it: Marker mode (a toggle that is orange and bold while on), Frame Selected
        and Frame All."""
        bar = self.addToolBar("Tools")
        bar.setObjectName("toolbar_tools")
        bar.setMovable(False)
        bar.setToolButtonStyle(QtCore.Qt.ToolButtonTextOnly)
        button = QtWidgets.QToolButton()     # its own button (not the action's): its text says the state
        button.setCheckable(True)
        button.setFocusPolicy(QtCore.Qt.NoFocus)
        button.toggled.connect(self.markers.mode_action.setChecked)
        bar.addWidget(button)
        self.marker_mode_button = button
        self.marker_mode_button.setObjectName("marker_mode_button")
        self.marker_mode_button.setStyleSheet(
            "QToolButton { padding: 3px 12px; border: 1px solid #8a8a8a; border-radius: 4px; }"
            "QToolButton:checked { background: #f0a030; color: #141414; font-weight: bold; border: 1px solid #ffd080; }")
        self.markers.mode_action.toggled.connect(self._on_marker_mode_toggled)
        self._on_marker_mode_toggled(self.markers.mode_action.isChecked())
        bar.addSeparator()
        bar.addAction(self.frame_selected_action)
        bar.addAction(self.frame_all_action)
        self.tools_bar = bar

    def _on_marker_mode_toggled(self, on: bool) -> None:
        self.marker_mode_button.blockSignals(True)
        self.marker_mode_button.setChecked(on)
        self.marker_mode_button.blockSignals(False)
        self.marker_mode_button.setText("● Marker Mode: On" if on else "Marker Mode")
        self.marker_mode_button.setToolTip("Marker mode is on: clicks add markers, drags pose (M turns it off)" if on
                                           else "Marker mode (M): click the face to add markers, drag them to pose")

    def _arrange_docks(self) -> None:
        """Left: Segmentation, Correctives, Markers as tabs. Right: Shapes, History, Texture, Mocap as tabs.
        Bottom: the timeline with the mocap views above it when they are shown."""
        # each tabified onto the group's first dock, in tab order: tabifying onto a dock that was itself just moved
        # into a group left the dock tabified before it on its own in one Qt version (6.11) and not in another
        for dock in (self.history_dock, self.textures.dock, self.mocap.dock):
            self.tabifyDockWidget(self.shapes_dock, dock)
        self.tabifyDockWidget(self.segmentation_dock, self.correctives.dock)
        self.tabifyDockWidget(self.segmentation_dock, self.markers.dock)
        self.splitDockWidget(self.mocap.views_dock, self.keyframes.dock, QtCore.Qt.Vertical)
        self.tabifyDockWidget(self.mocap.views_dock, self.keyframes.graph_dock)   # above the timeline, full width
        self.segmentation_dock.raise_()
        self.shapes_dock.raise_()

    def _build_status_bar(self) -> None:
        self.jobs_bar = QtWidgets.QProgressBar()   # busy while background work runs, with what it is
        self.jobs_bar.setRange(0, 0)
        self.jobs_bar.setMaximumWidth(260)
        self.jobs_bar.setTextVisible(True)
        self.jobs_bar.hide()
        self.statusBar().addPermanentWidget(self.jobs_bar)
        self.counts_label = QtWidgets.QLabel("no rig")
        self.statusBar().addPermanentWidget(self.counts_label)
        self.solver_build_label = QtWidgets.QLabel()   # while the take solver compiles (prepare_take_solver)
        self.solver_build_label.hide()
        self.statusBar().addPermanentWidget(self.solver_build_label)
        self.jobs.changed.connect(self._on_jobs_changed)

    def _on_jobs_changed(self, n: int, text: str) -> None:
        self.jobs_bar.setVisible(n > 0)
        self.jobs_bar.setFormat(text if n == 1 else f"{text} (+{n - 1} more)")

    def _connect(self) -> None:
        doc = self.document
        doc.rig_changed.connect(self._on_rig_change)
        doc.shapes_changed.connect(self._on_rig_shapes_change)
        doc.pose_changed.connect(self._on_pose_change)
        doc.path_changed.connect(self._update_title)
        doc.undo_stack.cleanChanged.connect(self._on_clean_change)
        p = self.shapes_panel
        p.pose_edited.connect(self._on_pose_edit)
        p.mirror_shape_requested.connect(lambda k: self.mirror_shape(self.document.rig.shape_names[k]))

    # --- document signals --------------------------------------------------------------------------
    def _on_rig_change(self) -> None:
        rig = self.document.rig
        self.mocap.views_dock.hide()   # a fresh rig has no solve to show (a solve shows the dock again)
        self.shapes_panel.set_shapes(rig.shape_names, sorted(rig.presets))
        shown, colors = self.parts.view_for(rig)
        focus = focus_vertices(rig.neutral, self.document.shape_reach())
        surface = self.document.surface()
        # its first render (0.16 s at 422k vertices) on the event loop's next turn, not in this one with the rest
        self.viewport.set_surface(surface, rig.face_counts, rig.face_indices, focus=focus, shown_faces=shown,
                                  base_colors=colors, prepared=self.document.default_view, render=False)
        self._new_surface = surface     # in the viewport: the pose change announced next need not upload it again
        self.request_render(after_input=True)
        self._update_counts()
        self._update_title()

    def _update_counts(self) -> None:
        rig = self.document.rig
        self.counts_label.setText(f"{count(rig.n_vertices, 'vertex', 'vertices')} · {count(rig.n_faces, 'face')} · "
                                  f"{count(rig.n_shapes, 'shape')} · {count(len(rig.correctives), 'corrective')} · {rig.units}")

    def _on_rig_shapes_change(self) -> None:
        rig = self.document.rig
        self.shapes_panel.set_shapes(rig.shape_names, sorted(rig.presets))
        self.shapes_panel.set_weights(self.document.weights)
        self._update_counts()

    def _on_pose_change(self) -> None:
        self.shapes_panel.set_weights(self.document.weights)
        self.request_render()

    def _on_clean_change(self, _clean: bool) -> None:
        self._update_title()

    def _update_title(self) -> None:
        name = self.document.path.name if self.document.path else (self.document.rig.name if self.document.rig else "")
        self.setWindowTitle(f"{name}[*] — Blendshape Studio" if name else "Blendshape Studio")
        self.setWindowModified(self.document.is_modified)

    # --- pose edits (each one undo step) -----------------------------------------------------------
    def _on_pose_edit(self, edit: PoseEdit) -> None:
        """The Shapes panel's gestures: on the global pose here, on a regional pose by the marker controller
        (the selected region's weights, or every region's)."""
        doc = self.document
        if doc.rig is None:
            return
        if doc.is_regional:
            self.markers.edit_regional_pose(edit)
            return
        k, name = edit.shape, doc.rig.shape_names[edit.shape] if edit.shape >= 0 else ""
        if edit.kind == "drag-start":
            self._drag_old = doc.weights
        elif edit.kind == "drag":
            w = doc.weights
            w[k] = edit.value
            doc.set_weights(w)
        elif edit.kind == "drag-end":
            if self._drag_old is not None:
                old, self._drag_old = self._drag_old, None
                new = doc.weights
                if not np.array_equal(old, new):
                    doc.undo_stack.push(SetWeightsCommand(doc, old, new, f"Drag {name}"))
        elif edit.kind == "set":
            new = doc.weights.copy()
            new[k] = edit.value
            self.set_pose(new, f"Set {name} to {edit.value:.3g}")
        elif edit.kind == "reset":
            self.reset_pose()
        elif edit.kind == "preset":
            self.apply_preset(edit.preset)

    def set_pose(self, weights: np.ndarray, text: str) -> None:
        """Make ``weights`` the global pose (one undo step); a regional pose is replaced even when the row the
        Shapes panel shows already equals them (Reset Pose on a regional pose whose background row is 0)."""
        old = self.document.weights
        if self.document.is_regional or not np.array_equal(old, weights):
            self.document.undo_stack.push(SetWeightsCommand(self.document, old, weights, text))

    def reset_pose(self) -> None:
        if self.document.rig is not None:
            self.set_pose(np.zeros(self.document.rig.n_shapes), "Reset pose")

    def mirror_pose(self) -> bool:
        """Swap each left shape's weight with its right twin's (model.sides), one undoable pose change. A
        regional pose gets the per-region weights closest to its mirror image (solvers.symmetry)."""
        from app.document import PoseState
        from app.marker_commands import SetPoseCommand
        from model.sides import mirror_indices
        from solvers.symmetry import mirrored_region_weights
        doc = self.document
        rig = doc.rig
        if rig is None:
            return False
        idx = mirror_indices(rig.shape_names)
        if idx == list(range(rig.n_shapes)):
            self.show_error("Mirror Pose", f"{rig.name} has no left and right shapes (names ending _L/_R, .L/.R "
                                           "or Left/Right) to swap.")
            return False
        if not doc.is_regional:
            self.set_pose(doc.weights[idx], "Mirror pose")
            return True
        old = doc.pose_state()
        W = mirrored_region_weights(old.region_weights, old.blend, doc.mirror_map(), idx)
        doc.undo_stack.push(SetPoseCommand(doc, old, PoseState(old.weights[idx], W, old.blend, old.level),
                                           "Mirror pose"))
        return True

    def mirror_shape(self, name: str) -> bool:
        """Make the other side's shape the mirror image of ``name`` across x = 0 (browInnerUp_L → browInnerUp_R),
        its in-betweens too: added if the rig lacks it, replaced if it has it; one undoable edit (Maya's Mirror
        Target)."""
        from app.commands import AddShapeCommand, SetShapeDeltaCommand, SetShapeSettingsCommand
        from model.errors import RigInputError
        from model.shape_edits import ShapeSettings, with_mirrored_inbetweens
        from model.sides import check_mirrorable, mirror_name
        from solvers.symmetry import mirror_delta
        rig = self.document.rig
        twin = mirror_name(name)
        if twin == name:
            self.show_error("Mirror Shape", f"{name} has no side in its name (_L/_R, .L/.R or Left/Right), so it "
                                            "has no other side to mirror to.")
            return False
        k = rig.shape_index(name)
        m = self.document.mirror_map()
        try:
            check_mirrorable(name, rig.deltas[k], rig.neutral, m, rig.units)
        except RigInputError as exc:
            self.show_error("Mirror Shape", str(exc))
            return False
        delta = mirror_delta(rig.deltas[k], m)
        replace = twin in rig.shape_names
        text = f"Mirror {name} onto {twin}" if replace else f"Mirror {name} to new {twin}"
        stack = self.document.undo_stack
        stack.beginMacro(text)   # the shape and its in-betweens: one undo step
        try:
            stack.push(SetShapeDeltaCommand(self.document, twin, delta, text) if replace else
                       AddShapeCommand(self.document, twin, delta, text, takes_offset=False))
            rig = self.document.rig
            if rig.inbetweens.get(name) or rig.inbetweens.get(twin):   # the twin's follow name's, mirrored
                stack.push(SetShapeSettingsCommand(self.document, ShapeSettings.of(rig),
                                                   with_mirrored_inbetweens(rig, name, twin, m), text))
        finally:
            stack.endMacro()
        self.show_status(f"Replaced {twin} with the mirror image of {name}." if replace else
                         f"Added {twin}, the mirror image of {name}.")
        return True

    def apply_preset(self, name: str) -> None:
        rig = self.document.rig
        self.set_pose(rig.weights_from_dict(rig.presets[name]), f"Preset {name}")

    def selection_points(self) -> tuple[str, np.ndarray] | None:
        """What F frames: (what, points) of the selected marker (in Marker mode) or the selected region, else
        None (the face)."""
        if self.document.project is None:
            return None
        surface = self.document.surface()
        m = self.markers.selected_marker
        if self.markers.mode and m is not None and self.markers.markers is not None and m < len(self.markers.markers):
            p = self.markers.marker_positions()[m]
            r = 0.08 * extent(self.viewport.focus_points())
            return f"marker {self.markers.markers.names[m]}", p + np.array([[-r, -r, -r], [r, r, r]])
        seg, region = self.segmentation.segmentation, self.segmentation_panel.selected_region()
        if seg is not None and region >= 0 and self.segmentation.level < len(seg.levels):
            labels = seg.levels[self.segmentation.level].core_labels(len(surface))
            if (labels == region).any():
                return f"region {region}", surface[labels == region]
        return None

    def frame_all(self) -> None:
        """View ▸ Frame All (A, Home in the view): every vertex of the surface as posed, from where the camera looks
        now (the camera presets and Frame Selected with nothing selected frame the face)."""
        points = self.viewport.points()
        if points is not None:
            self.viewport.frame_points(points)

    def frame_selected(self) -> None:
        """View ▸ Frame Selected (F): frame the selected marker or region from where the camera looks now."""
        sel = self.selection_points()
        if sel is None:
            self.viewport.frame_points()
            self.show_status("Framed the face (select a region or, in Marker mode, a marker to frame it).", 4000)
        else:
            self.viewport.frame_points(sel[1])
            self.show_status(f"Framed {sel[0]}.", 3000)

    # --- files -------------------------------------------------------------------------------------
    def open_sample(self) -> None:
        from resources.sample_rig import build_sample_rig, sample_project_sections
        if not self._maybe_discard():
            return
        self.document.set_project(Project(rig=build_sample_rig(), sections=sample_project_sections()), None)

    def open_folder_dialog(self) -> None:
        s = app_settings.settings()
        folder = QtWidgets.QFileDialog.getExistingDirectory(self, "Open Rig Folder", s.value("lastFolder", ""))
        if folder:
            s.setValue("lastFolder", str(Path(folder).parent))   # beside it next time: not inside the rig
            self.open_path(folder)

    def open_file_dialog(self) -> None:
        s = app_settings.settings()
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open", s.value("lastFolder", ""), RIG_FILTER)
        if path:
            s.setValue("lastFolder", str(Path(path).parent))
            self.open_path(path)

    def open_path(self, path: str | Path) -> None:
        """Open a rig or project in the background; on failure keep what is open and say why. A take or a marker
        map (the command line's ``blendshape-studio TAKE``, a recent file) goes to the Mocap panel, as if dropped:
        on the rig that is open (the window opens the bundled sample first when it starts on a take)."""
        from app.loading import opens_as
        if opens_as(path) != "rig":
            self.open_dropped([path])
            return
        if self._worker is not None or not self._maybe_discard():
            return
        path = Path(path)
        self._progress = QtWidgets.QProgressDialog(f"Opening {path.name}…", None, 0, 0, self)
        self._progress.setWindowTitle("Opening")
        self._progress.setMinimumDuration(300)
        self._progress.setWindowModality(QtCore.Qt.WindowModal)
        self._progress.setValue(0)   # starts its show-after timer: a project's load reports no steps to show it by
        self._worker = LoadWorker(path, self)
        self._worker.progress.connect(self._on_load_progress)
        self._worker.loaded.connect(lambda project, prep: self._on_loaded(project, path, prep))
        self._worker.failed.connect(self._on_load_failed)
        self._worker.finished.connect(self._on_worker_finished)
        self.show_status(f"Opening {path}…", 0)
        self._worker.start()

    def _on_load_progress(self, done: int, total: int, what: str) -> None:
        dialog = self._progress  # setValue on a modal dialog processes events: it may close meanwhile
        if dialog is not None:
            dialog.setLabelText(f"Reading {what} ({done}/{total})" if total else f"Preparing {what}…")
            dialog.setMaximum(total)
            dialog.setValue(done)

    def _on_loaded(self, project: Project, path: Path, prep=None) -> None:
        if self._shut_down:      # delivered after the window closed (the loader finished while it did)
            return
        self.document.set_project(project, path if path.suffix.lower() == ".bsproj" else None, prep)
        app_settings.add_recent_file(str(path))
        self._rebuild_recent_menu()
        self.show_status(f"Opened {path}")
        after, self._after_open = self._after_open, []
        for step in after:
            step()

    def _on_load_failed(self, message: str) -> None:
        self._after_open = []
        self.show_error("Could not open", message)
        self.load_failed.emit(message)

    # --- files dropped on the window ---------------------------------------------------------------
    def files_dropped(self, paths: list[str]) -> None:   # FileDropTarget
        self.open_dropped(paths)

    def open_dropped(self, paths) -> bool:
        """Open dropped files through the menus' paths: a rig folder, project, glTF or OBJ as File ▸ Open, a take
        and a marker map as the Mocap panel's Load (after the rig when both are dropped). A file that is none of
        these is one sentence, and nothing is opened."""
        from app.loading import sort_dropped
        try:
            items = sort_dropped(paths)
        except RigInputError as exc:
            self.show_error("Could not open", str(exc))
            return False
        rigs = [p for kind, p in items if kind == "rig"]
        if len(rigs) > 1:
            self.show_error("Could not open", f"{len(rigs)} rigs or projects were dropped ({rigs[0].name}, "
                                              f"{rigs[1].name}, …): drop one at a time.")
            return False
        steps = [lambda kind=kind, p=p: self.mocap.open_in_panel(kind, p) for kind, p in items if kind != "rig"]
        if rigs:
            if self.is_loading:
                return False
            self.open_path(rigs[0])
            if self.is_loading:        # opening (not cancelled at the unsaved-changes question)
                self._after_open = steps
            return self.is_loading
        if self.document.project is None:
            self.show_error("Could not open", f"{items[0][1].name} needs a rig: open or drop a rig first.")
            return False
        for step in steps:
            step()
        return True

    def _on_worker_finished(self) -> None:
        if self._progress is not None:
            # reset() stops the dialog's own show-after-300-ms timer: close() alone left it to pop up, modal and
            # without a Cancel button, after every fast open
            self._progress.reset()
            self._progress.close()
            self._progress.deleteLater()
            self._progress = None
        self._worker = None

    @property
    def is_loading(self) -> bool:
        """Whether a rig or project is being opened in the background."""
        return self._worker is not None

    def save(self) -> bool:
        if self.document.project is None:
            return False
        if self.document.path is None or self.document.path.suffix.lower() != ".bsproj":
            return self.save_as()
        return self.save_to(self.document.path)

    def save_as(self) -> bool:
        if self.document.project is None:
            return False
        s = app_settings.settings()
        # the project's own folder, else the last folder a project was saved in or files were opened from
        folder = self.document.path.parent if self.document.path else Path(s.value("lastProjectFolder", "") or
                                                                            s.value("lastFolder", ""))
        start = str(folder / (self.document.path.name if self.document.path else f"{self.document.rig.name}.bsproj"))
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Save Project", start, "Projects (*.bsproj)")
        if not path:
            return False
        if not path.lower().endswith(".bsproj"):
            path += ".bsproj"
        return self.save_to(path)

    def save_to(self, path: str | Path) -> bool:
        session_state.store(self)   # the view, the take and the marker map come back with the project
        try:   # off the GUI thread, the window drawn but holding input (a studio rig's project takes seconds)
            self.document.save(path, write=lambda fn: run_modal(self, "Saving", f"Saving {Path(path).name}…", fn))
        except OSError as exc:      # a full disk too: one sentence, the document and its undo history as they were
            self.show_error("Could not save", str(write_error(path, exc)))
            return False
        app_settings.add_recent_file(str(path))
        app_settings.settings().setValue("lastProjectFolder", str(Path(path).parent))
        self._rebuild_recent_menu()
        self.show_status(f"Saved {path}")
        return True

    def save_dialog(self, title: str, default_name: str, file_filter: str, write) -> None:
        """Ask where to write (a file dialog with ``default_name`` in ``export_folder``) and call ``write(path)``;
        nothing without an open rig or when the user cancels. Every export of the window and its panels uses it."""
        if self.document.project is None:
            return
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, title, str(self.export_folder() / default_name),
                                                        file_filter)
        if path:
            self.remember_export_folder(path)
            write(path)

    def export_folder(self) -> Path:
        """Where an export's file dialog starts: the folder the last export went to (in this session or an earlier
        one), else the project's folder, else the last folder a project was saved in or a file opened from, else
        the home folder; never the folder the program was started in (the dialogs opened there, wherever that was)
        and never an OBJ rig's own folder (an OBJ written there is read as one of its shapes next time)."""
        s = app_settings.settings()
        rig_folder = Path(self.document.rig.source) if self.document.project is not None else None
        for folder in (s.value("export/folder", ""), self.document.path.parent if self.document.path else "",
                       s.value("lastProjectFolder", ""), s.value("lastFolder", "")):
            if folder and Path(folder).is_dir():
                return Path(folder).parent if rig_folder is not None and Path(folder) == rig_folder else Path(folder)
        return Path.home()

    @staticmethod
    def remember_export_folder(path: str | Path) -> None:
        app_settings.settings().setValue("export/folder", str(Path(path).parent))

    def export_inputs(self) -> list[tuple[str, str | None]]:
        """The files the window has open, which no export may write over: the project's, the rig's (an OBJ folder,
        a glTF with its buffers and images, a project), the Mocap panel's take and marker map."""
        doc = self.document
        if doc.project is None:
            return []
        inputs = [("the project", str(doc.path) if doc.path else None), ("the rig", doc.rig.source)]
        mocap = getattr(self, "mocap", None)
        if mocap is not None:
            mm = mocap.workspace.marker_map
            inputs += [("the take", str(mocap.workspace.take_path or "") or None),
                       ("the marker map", mm.source if mm is not None else None)]
        return inputs

    def refuses_export_over_inputs(self, path: str | Path, title: str = "Could not export", *,
                                   rewrites: str | None = None, rig=None) -> bool:
        """True, after one sentence in a dialog, when an export's ``path`` is one of the files the window has open
        (``export_inputs``; but ``rewrites``, the one this export saves again, e.g. "the marker map"), by the rule of
        the command line's outputs (``model.beside_inputs.check_not_inputs``); nothing is written then. ``rig``: an OBJ
        of it also writes its material library, checked too (``model.export.check_files_beside``)."""
        try:
            self.check_export_over_inputs(path, rewrites=rewrites, rig=rig)
        except RigInputError as exc:
            self.show_error(title, str(exc))
            return True
        return False

    def check_export_over_inputs(self, path: str | Path, *, rewrites: str | None = None, rig=None) -> None:
        """Raise RigInputError (one sentence) when an export's ``path`` (or, with ``rig``, the material library an
        OBJ of it writes beside it) is one of the files the window has open (``refuses_export_over_inputs``)."""
        from model.beside_inputs import check_not_inputs
        from model.export import check_files_beside
        inputs = [(name, source) for name, source in self.export_inputs() if name != rewrites]
        check_not_inputs(path, inputs)
        if rig is not None:
            check_files_beside(rig, path, lambda p: check_not_inputs(p, inputs))

    def export_pose(self) -> None:
        if self.document.project is not None:
            self.save_dialog("Export Pose as OBJ", f"{self.document.rig.name}_pose.obj", "OBJ (*.obj)",
                             self.export_pose_to)

    def export_pose_to(self, path: str | Path) -> None:
        """Write the posed surface as an OBJ in the background (control returns at once; 1.6 s on ICT), with the
        rig's UVs, groups and materials as ``export`` writes them (``model.export.write_surface_obj``); a file the
        rig's own OBJ folder would read is refused in a dialog, as the command line refuses it."""
        from model.export import write_surface_obj
        from model.pose import PoseEvaluator
        rig, state = self.document.rig, self.document.pose_state()
        if self.refuses_export_over_inputs(path, rig=rig):   # e.g. into the rig's own OBJ folder, as one more shape
            return

        def job() -> None:
            w = state.weights if state.region_weights is None else state.region_weights
            points = PoseEvaluator(rig, dtype=np.float64).pose(w, state.blend)
            try:
                write_surface_obj(rig, path, points, header=f"Blendshape Studio pose of {rig.name}")
            except OSError as exc:
                raise write_error(path, exc) from exc
        self.run_in_background("Exporting the pose…", job, lambda _: self.show_status(f"Exported {path}"),
                               lambda message: self.show_error("Could not export", message))

    def save_image_dialog(self) -> None:
        """File ▸ Export Image…: the width and height (the view's size at first, then the last ones chosen; the
        ``render`` command's 16..8192 pixels), then where to write the PNG."""
        if self.document.project is None:
            return
        dialog = QtWidgets.QDialog(self)
        dialog.setWindowTitle("Export Image")
        form = QtWidgets.QFormLayout(dialog)
        vw, vh = self.viewport.plotter.window_size
        boxes = []
        for label, value, key in (("Width", vw, "export/imageWidth"), ("Height", vh, "export/imageHeight")):
            box = QtWidgets.QSpinBox()
            box.setRange(16, 8192)
            box.setSuffix(" px")
            box.setValue(int(value))
            app_settings.remember(box, key)
            form.addRow(label, box)
            boxes.append(box)
        view_size = QtWidgets.QPushButton(f"The view's size ({vw} × {vh})")
        view_size.clicked.connect(lambda: (boxes[0].setValue(vw), boxes[1].setValue(vh)))
        form.addRow("", view_size)
        buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.Ok | QtWidgets.QDialogButtonBox.Cancel)
        buttons.accepted.connect(dialog.accept)
        buttons.rejected.connect(dialog.reject)
        form.addRow(buttons)
        dialog.setAttribute(QtCore.Qt.WA_DeleteOnClose)
        self.image_size_dialog = dialog   # tests answer it

        def chosen() -> None:
            size = (boxes[0].value(), boxes[1].value())
            self.save_dialog("Export Image", f"{self.document.rig.name}.png", "PNG image (*.png)",
                             lambda path: self.save_image(path, size))
        dialog.accepted.connect(chosen)
        dialog.open()

    def save_image(self, path: str | Path, size: tuple[int, int] | None = None) -> bool:
        """Write the viewport as it is shown (camera, colour map and bar, wireframe) as a PNG at ``size`` (w, h)
        pixels (default: the view's). The picture is drawn now (``Viewport.picture``: VTK draws on this thread, under
        a busy cursor and a status line), then encoded and written on the background queue (``self.jobs``): a
        3840x2160 PNG is ~1.6 s of zlib, which froze the window with the render's ~0.4 s. False, with an error box,
        when ``path`` cannot be written (said before anything is drawn)."""
        from model.atomic import check_output_file, write_png
        path = Path(path)
        if path.suffix.lower() != ".png":
            path = path.with_suffix(path.suffix + ".png") if path.suffix else path.with_suffix(".png")

        def unwritable(exc: OSError) -> str:
            return str(write_error(path, exc))
        if self.refuses_export_over_inputs(path, "Could not save the image"):
            return False
        try:
            check_output_file(path).parent.mkdir(parents=True, exist_ok=True)
        except (OSError, RigInputError) as exc:   # OutputPathError is both: its own sentence
            self.show_error("Could not save the image", str(exc) if isinstance(exc, RigInputError) else unwritable(exc))
            return False
        self.show_status(f"Drawing {path.name}…", 0)
        self.statusBar().repaint()     # shown now: the render holds this thread until it is done
        QtWidgets.QApplication.setOverrideCursor(QtCore.Qt.WaitCursor)
        try:
            pixels = self.viewport.picture(size)
        finally:
            QtWidgets.QApplication.restoreOverrideCursor()
        h, w = pixels.shape[:2]
        self.show_status(f"Writing {path.name} ({w}x{h} pixels)…", 0)

        def job() -> None:
            try:
                write_png(path, pixels)
            except OSError as exc:
                raise RigInputError(unwritable(exc)) from None
        self.run_in_background(f"Writing {path.name}…", job,
                               lambda _: self.show_status(f"Saved {path} ({w}x{h} pixels)"),
                               lambda message: self.show_error("Could not save the image", message))
        return True

    def _rebuild_recent_menu(self) -> None:
        self.recent_menu.clear()
        files = app_settings.recent_files()
        for i, f in enumerate(files):
            act = self.recent_menu.addAction(f"&{i + 1} {f}")
            act.triggered.connect(lambda _=False, p=f: self.open_path(p))
        if files:
            self.recent_menu.addSeparator()
            self.recent_menu.addAction("Clear Recent", lambda: (app_settings.clear_recent_files(),
                                                                self._rebuild_recent_menu()))
        self.recent_menu.setEnabled(bool(files))

    def _maybe_discard(self) -> bool:
        if not self.confirm_discard or not self.document.is_modified:
            return True
        answer = QtWidgets.QMessageBox.question(
            self, "Unsaved changes", "The project has unsaved changes. Save them first?",
            QtWidgets.QMessageBox.Save | QtWidgets.QMessageBox.Discard | QtWidgets.QMessageBox.Cancel)
        if answer == QtWidgets.QMessageBox.Save:
            return self.save()
        return answer == QtWidgets.QMessageBox.Discard

    # --- messages ----------------------------------------------------------------------------------
    def show_error(self, title: str, message: str) -> None:
        """A clear, non-blocking error dialog; the message is kept in last_error (tests read it)."""
        self.last_error = message
        self.statusBar().showMessage(message, 10000)
        box = QtWidgets.QMessageBox(QtWidgets.QMessageBox.Warning, title, message, QtWidgets.QMessageBox.Ok, self)
        box.setAttribute(QtCore.Qt.WA_DeleteOnClose)
        box.open()

    def show_about(self) -> None:
        QtWidgets.QMessageBox.about(self, "About Blendshape Studio",
                                    "Blendshape Studio — pose, segment, solve and correct blendshape face rigs.")

    def shortcut_rows(self) -> list[tuple[str, str, str]]:
        """(menu, action, keys) for every action with a shortcut: the menus' in menu order (submenus as
        "Correctives ▸ Brush"), then those that live outside the menus, then the panels' own QShortcuts."""
        ordered: list[tuple[str, QtGui.QAction]] = []
        seen: set = set()

        def walk(actions, where: str) -> None:
            for act in actions:
                sub = act.menu()
                if sub is not None:
                    name = act.text().replace("&", "")
                    walk(sub.actions(), f"{where} ▸ {name}" if where else name)
                elif act not in seen:
                    seen.add(act)
                    ordered.append((where, act))
        walk(self.menuBar().actions(), "")
        ordered += [("", a) for a in self.findChildren(QtGui.QAction) if a not in seen]
        rows = []
        for where, act in ordered:
            keys = ", ".join(dict.fromkeys(k.toString(QtGui.QKeySequence.NativeText) for k in act.shortcuts()
                                           if not k.isEmpty()))
            if keys:
                rows.append((where or "Window", act.property("shortcutName") or act.text().replace("&", ""), keys))
        for sc in self.findChildren(QtGui.QShortcut):   # panel keys that are not menu actions (region nudges)
            if not sc.key().isEmpty():
                rows.append(("Panels", sc.whatsThis() or "(panel shortcut)",
                             sc.key().toString(QtGui.QKeySequence.NativeText)))
        return rows

    def show_shortcuts(self) -> None:
        """Help ▸ Keyboard Shortcuts: every shortcut of the window in a sortable, resizable list."""
        dialog = QtWidgets.QDialog(self)
        dialog.setWindowTitle("Keyboard Shortcuts")
        lay = QtWidgets.QVBoxLayout(dialog)
        table = QtWidgets.QTreeWidget()
        table.setHeaderLabels(["Shortcut", "Action", "Menu"])
        table.setRootIsDecorated(False)
        table.setAlternatingRowColors(True)
        for where, name, keys in self.shortcut_rows():
            table.addTopLevelItem(QtWidgets.QTreeWidgetItem([keys, name, where]))
        for c in range(3):
            table.resizeColumnToContents(c)
        table.header().setSortIndicator(-1, QtCore.Qt.AscendingOrder)   # menu order until a header is clicked
        table.setSortingEnabled(True)
        lay.addWidget(table)
        buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.Close)
        buttons.rejected.connect(dialog.reject)
        lay.addWidget(buttons)
        dialog.resize(560, 520)
        self.shortcuts_dialog = dialog
        dialog.show()

    # --- window state ------------------------------------------------------------------------------
    def _restore_layout(self) -> None:
        """The last session's window and docks; on first start the window maximised, the side panels narrow and
        the timeline low so the viewport is the largest part. The Mocap Views dock never comes back empty: it
        shows a solve, and there is none at start."""
        s = app_settings.settings()
        geo = s.value("window/geometry")
        if geo is not None:
            self.restoreGeometry(geo)
        else:   # the screen's size (without a window manager, maximising alone changes nothing), maximised
            screen = self.screen() or QtGui.QGuiApplication.primaryScreen()
            if screen is not None:
                self.setGeometry(screen.availableGeometry())
            self.setWindowState(self.windowState() | QtCore.Qt.WindowMaximized)
        state = s.value("window/state")
        if state is None or not self.restoreState(state):
            self.resizeDocks([self.segmentation_dock, self.shapes_dock], [370, 330], QtCore.Qt.Horizontal)
            self.resizeDocks([self.keyframes.dock], [60], QtCore.Qt.Vertical)
        self.mocap.views_dock.hide()
        self._retire_stale_tab_bars()

    def _retire_stale_tab_bars(self) -> None:
        """Hide every dock tab bar before the window first shows; its first layout shows again the ones in use.
        QMainWindow makes a new tab bar for a tab group when docks are tabified one by one or a saved state is
        restored, and only retires the old one once the window is visible: bars made before then stayed shown
        at their first place (a ghost 'Segmentation | Correctives' bar behind the left panels, and the right
        panels' tabs a second time, peeking out under the viewport)."""
        if self.isVisible():
            return
        for bar in self.findChildren(QtWidgets.QTabBar, options=QtCore.Qt.FindDirectChildrenOnly):
            bar.hide()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:
        if not self._maybe_discard():
            event.ignore()
            return
        s = app_settings.settings()
        s.setValue("window/geometry", self.saveGeometry())
        s.setValue("window/state", self.saveState())
        self.shutdown_background()
        self.autosave.shutdown(clean_quit=True)
        self.viewport.close_viewport()
        super().closeEvent(event)

    def prepare_take_solver(self) -> None:
        """Compile the take solver in a process of its own when this installation has not yet
        (``solvers.take_kernel.start_background_build``), so that the first solve does not sit for up to half a
        minute; the status bar says so until it is done. The application calls this when it opens."""
        from solvers import take_kernel
        proc = take_kernel.start_background_build()
        if proc is None:
            return
        self.solver_build_label.setText(take_kernel.BUILD_MESSAGE)
        self.solver_build_label.setToolTip("A solve started meanwhile waits for this build; it is kept for later runs")
        self.solver_build_label.show()
        timer = QtCore.QTimer(self)
        timer.setInterval(250)

        def check() -> None:
            if proc.poll() is not None:
                timer.stop()
                self.solver_build_label.hide()
        timer.timeout.connect(check)
        timer.start()
        self._solver_build = proc

    def shutdown_background(self) -> None:
        """Finish or stop every background job before the window goes: a thread must not outlive it."""
        self._shut_down = True
        if self._worker is not None:
            self._worker.wait()
        self.segmentation.runner.shutdown()
        self.actor.shutdown()
        self.jobs.shutdown()
        self.mocap.shutdown()
        self.exports.shutdown()
        self.batch.shutdown()
        self.textures.shutdown()
