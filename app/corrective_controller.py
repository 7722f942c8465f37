"""Corrective shapes in the GUI (ALGORITHMS.md §6; Smith 2006 §4.5, §5.6–5.8): the Correctives panel,
sculpt mode, saving a sculpt as a corrective, correctives from scans, mirroring. The controller owns the
brush strokes on the viewport (``app.sculpt_tool``) and the interference finder with its heat map
(``app.interference_finder``).

``install(window)`` adds the dock, the menu and this controller to a MainWindow. Every edit is an undo
command on ``window.document.undo_stack``: a sculpt stroke is one ``SetEditOffsetCommand``; saving,
importing, mirroring, renaming, editing drivers or rule and deleting are ``SetCorrectivesCommand``s.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app import settings as app_settings
from app.commands import SetEditOffsetCommand, SetWeightsCommand
from app.corrective_commands import SetCorrectivesCommand
from app.interference_finder import InterferenceFinder
from app.sculpt_tool import SculptTool
from model.correctives import (Corrective, activation_for, corrective_activation, corrective_activations,
                               find_corrective, mirrored_corrective, symmetrized_corrective, validate_correctives,
                               why_not_mirrored)
from model.corrective_authoring import authoring_surface, corrective_from_scan, driver_pose
from model.errors import RigInputError
from model.sides import mirror_drivers
from model.wording import count
from solvers.correctives import corrective_delta
from solvers.mesh import extent
from widgets.correctives_panel import CORRECTIVES_TAB, INTERFERENCE_TAB, CorrectivesPanel


class CorrectiveController(QtCore.QObject):
    sculpting_changed = QtCore.Signal(bool)

    def __init__(self, window, panel: CorrectivesPanel, dock=None) -> None:
        super().__init__(window)
        self.window, self.panel, self.dock = window, panel, dock
        self.document, self.viewport = window.document, window.viewport
        self.authoring: list[str] | None = None   # drivers being sculpted (sculpt mode on when not None)
        self.new_rule = "product"
        self.sculpt_actions: dict = {}            # the Correctives menu's Save, Discard Sculpt and Stop Sculpting
        self.mirror_action = self.symmetrize_action = None   # the menu's Mirror and Symmetrize Corrective (install)
        self.sculpt = SculptTool(window.viewport, window.document, panel, lambda: self.authoring is not None)
        self.finder = InterferenceFinder(window, panel, self.start_authoring)
        d = self.document
        d.rig_changed.connect(self._on_rig_change)
        d.shapes_changed.connect(self._on_shapes_change)
        d.pose_changed.connect(self._on_pose_change)
        d.offset_changed.connect(self._on_offset_change)
        p = panel
        p.new_requested.connect(self.new_from_combination)
        p.use_pose_requested.connect(self.tick_posed_shapes)
        p.save_requested.connect(self.save)
        p.discard_requested.connect(self.discard_sculpt)
        p.cancel_requested.connect(self.stop_sculpting)
        p.scan_requested.connect(self.from_scan)
        p.edit_shape_requested.connect(self.sculpt_selected)
        p.rename_requested.connect(self.rename)
        p.drivers_requested.connect(self.edit_drivers)
        p.delete_requested.connect(self.delete)
        p.mirror_requested.connect(self.mirror)
        p.table.itemSelectionChanged.connect(self.show_mirror_state)   # after the panel's own buttons
        p.mute_requested.connect(self.set_muted)
        p.rule_requested.connect(self.set_rule)
        p.tab_changed.connect(self.finder.on_tab_change)
        p.brush_changed.connect(self.sculpt.update_cursor_radius)
        # the segmentation view repaints the surface when it finishes: keep the heat map on top
        window.segmentation.segmentation_ready.connect(self.finder.reapply_heat_map)
        if dock is not None:
            dock.visibilityChanged.connect(lambda vis: None if vis else self.finder.leave_heat_map())
        if d.project is not None:
            self._on_rig_change()

    # --- document signals --------------------------------------------------------------------------
    def _on_rig_change(self) -> None:
        self.stop_sculpting()
        self.finder.reset()
        self.sculpt.reset()
        rig = self.document.rig
        self.panel.set_shapes(rig.shape_names)
        self.panel.set_units(rig.units)
        self.panel.radius.setValue(float(f"{0.08 * extent(rig.neutral):.2g}"))
        self._refresh_table()

    def _on_shapes_change(self) -> None:
        rig = self.document.rig
        names = [self.panel.drivers.item(i).text() for i in range(self.panel.drivers.count())]
        if names != rig.shape_names:
            ticked = self.panel.ticked_drivers()
            self.panel.set_shapes(rig.shape_names)
            self.panel.set_ticked(ticked)
        self.finder.shapes_changed()   # it keeps its scores unless the deltas changed (Mirror to the Other Side)
        self._refresh_table()

    def _on_pose_change(self) -> None:
        self.panel.set_activations(self.activations())

    def _on_offset_change(self) -> None:
        self._show_sculpting()

    def _show_sculpting(self) -> None:
        """The panel's sculpt state and buttons, and the menu's Save Corrective and Stop Sculpting (sculpting) and
        Discard Sculpt (a sculpt pending) enabled as the panel's buttons are: enabled, they did nothing and said
        nothing (Save, an error box)."""
        has_offset = self.document.edit_offset is not None
        self.panel.set_sculpting(self.authoring, has_offset)
        for key, on in (("discard", has_offset), ("stop", self.authoring is not None),
                        ("save", self.authoring is not None)):
            if key in self.sculpt_actions:
                self.sculpt_actions[key].setEnabled(on)

    def activations(self) -> np.ndarray:
        rig = self.document.rig
        if rig is None or not rig.correctives:
            return np.zeros(0)
        return corrective_activations(rig.correctives, rig.shape_names, self.document.weights)

    def _refresh_table(self) -> None:
        rig = self.document.rig
        rows = [(c.name, list(c.drivers), c.rule, c.muted) for c in rig.correctives]
        self.panel.set_correctives(rows, self.activations())
        self.show_mirror_state()

    MIRROR_TIP = "Add the other side's version of the selected corrective (drivers _L↔_R, reflected across x = 0)"
    SYMMETRIZE_TIP = "Make the selected two-sided corrective (drivers that mirror onto themselves) exactly symmetric"

    def show_mirror_state(self) -> None:
        """Mirror (the menu's and the panel's) and Symmetrize enabled only for a selected corrective they can act on
        (``model.correctives.why_not_mirrored``); disabled, their tooltips say why. They were always enabled and
        answered with a message box."""
        rig = self.document.rig
        c = self.corrective(self.panel.selected_name()) if rig is not None else None
        no_mirror, no_symmetry = why_not_mirrored(c, rig.shape_names if rig is not None else [])
        self.panel.set_mirror_allowed(no_mirror is None, no_mirror)
        for action, why, tip in ((self.mirror_action, no_mirror, self.MIRROR_TIP),
                                 (self.symmetrize_action, no_symmetry, self.SYMMETRIZE_TIP)):
            if action is not None:
                action.setEnabled(why is None)
                action.setToolTip(tip if why is None else why)
                action.setStatusTip(tip if why is None else why)

    # --- helpers -----------------------------------------------------------------------------------
    def _error(self, message: str) -> None:
        self.window.show_error("Corrective shapes", message)

    def _check_cycle(self, drivers) -> None:
        rig = self.document.rig
        names = {c.name for c in rig.correctives} - set(rig.shape_names)
        for d in drivers:
            if d in names:
                raise RigInputError(f"'{d}' is a corrective, not a shape: a corrective driven by a corrective "
                                    "would make the hierarchy a cycle.")

    def _check_drivers(self, drivers) -> list[str]:
        """The drivers as a validated list (raises RigInputError with one sentence)."""
        rig = self.document.rig
        drivers = [str(d).strip() for d in drivers if str(d).strip()]
        self._check_cycle(drivers)
        if len(drivers) < 2:
            raise RigInputError(f"A corrective needs two or more driver shapes, got {len(drivers)}; tick at "
                                "least two shapes in the Drivers list.")
        probe = Corrective(drivers=drivers, delta=np.zeros((0, 3)))
        key = frozenset(drivers)
        others = [c for c in rig.correctives if frozenset(c.drivers) != key and c.name != probe.name]
        validate_correctives(others + [probe], rig.shape_names)
        return drivers

    def _push_correctives(self, new, text: str, **offsets) -> bool:
        rig = self.document.rig
        try:
            validate_correctives(new, rig.shape_names, rig.n_vertices)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        self.document.undo_stack.push(SetCorrectivesCommand(self.document, rig.correctives, new, text, **offsets))
        return True

    def corrective(self, name: str | None) -> Corrective | None:
        for c in self.document.rig.correctives:
            if c.name == name:
                return c
        return None

    # --- authoring (Smith §5.6) --------------------------------------------------------------------
    def tick_posed_shapes(self) -> None:
        rig = self.document.rig
        w = self.document.weights
        self.panel.set_ticked([n for n, x in zip(rig.shape_names, w) if x > 0])

    def new_from_combination(self) -> None:
        """Start a corrective on the ticked drivers, or on the shapes whose weight is > 0 if none are ticked."""
        if self.document.rig is None:
            return
        drivers = self.panel.ticked_drivers()
        if not drivers:
            w = self.document.weights
            drivers = [n for n, x in zip(self.document.rig.shape_names, w) if x > 0]
        self.start_authoring(drivers, self.panel.current_rule())

    def start_authoring(self, drivers, rule: str | None = None) -> bool:
        """Set the drivers to 1 and every other shape to 0 (one undoable pose change), enter sculpt mode."""
        try:
            drivers = self._check_drivers(drivers)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        rig = self.document.rig
        own = find_corrective(rig.correctives, drivers)
        self.new_rule = own.rule if own is not None else (rule or self.panel.current_rule())
        self.window.set_pose(driver_pose(rig, drivers), f"Pose {'+'.join(drivers)} for a corrective")
        self.authoring = drivers
        self.panel.set_ticked(drivers)
        # Symmetric strokes for a two-sided corrective (browInnerUp_L+browInnerUp_R), one-sided strokes for a
        # one-sided one: a symmetric stroke there would change the other side, where this corrective also fires
        two_sided = set(mirror_drivers(drivers)) == set(drivers)
        self.panel.symmetric.setChecked(two_sided)
        self.sculpt.enable()
        if self.dock is not None:
            self.dock.show()
            self.dock.raise_()
        self.panel.tabs.setCurrentIndex(CORRECTIVES_TAB)
        self._show_sculpting()
        self.panel.reveal_sculpt()
        self.window.statusBar().showMessage(
            f"Sculpt the corrective for {' + '.join(drivers)}: drag on the face, then Save corrective "
            f"(symmetric strokes {'on: the drivers are two-sided' if two_sided else 'off: one side'}).", 8000)
        self.sculpting_changed.emit(True)
        return True

    def sculpt_selected(self) -> None:
        c = self.corrective(self.panel.selected_name())
        if c is not None:
            self.start_authoring(c.drivers, c.rule)

    def stop_sculpting(self) -> None:
        was = self.authoring is not None
        self.authoring = None
        self.sculpt.disable()
        self._show_sculpting()
        if was:
            self.sculpting_changed.emit(False)

    @property
    def sculpting(self) -> bool:
        return self.authoring is not None

    def save(self) -> bool:
        """Store e = (x_des − x_cur) / a (Smith §5.6): x_des the surface shown (pose + sculpt), x_cur from
        ``authoring_surface`` (every lower-order corrective applied); clears the sculpt. One undo step."""
        doc, rig = self.document, self.document.rig
        if self.authoring is None:
            self._error("Start a corrective first: tick two or more drivers and press New corrective.")
            return False
        drivers = self.authoring
        w = doc.weights
        idx = [rig.shape_index(d) for d in drivers]
        others = np.delete(w, idx)
        if np.any(others != 0):
            self._error(f"Set every shape except {' + '.join(drivers)} to 0 before saving: a corrective is "
                        "authored at its drivers' pose.")
            return False
        own = find_corrective(rig.correctives, drivers)
        if doc.edit_offset is None and own is None:
            self._error("Nothing to save yet: sculpt the surface with a brush first.")
            return False
        x_cur, _ = authoring_surface(rig, drivers, weights=w[idx], evaluator=doc.evaluator64())
        x_des = x_cur.copy()
        if own is not None:
            x_des += corrective_activation(own, rig.shape_names, w) * own.delta
        if doc.edit_offset is not None:
            x_des += doc.edit_offset
        rule = own.rule if own is not None else self.new_rule
        name = own.name if own is not None else "+".join(drivers)
        try:
            delta = corrective_delta(x_des, x_cur, activation_for(drivers, rule, rig.shape_names, w))
            made = Corrective(name=name, drivers=drivers, rule=rule, delta=delta,
                              muted=own.muted if own is not None else False)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        new = [c for c in rig.correctives if frozenset(c.drivers) != frozenset(drivers)] + [made]
        if not self._push_correctives(new, f"Save corrective {name}", new_offset=None):
            return False
        self.stop_sculpting()
        self.panel.select(name)
        twin = mirror_drivers(drivers)
        hint = (" Mirror (Ctrl+Shift+M) makes the other side's." if set(twin) != set(drivers)
                and all(d in rig.shape_names for d in twin) else "")
        self.window.statusBar().showMessage(f"Saved corrective {name}.{hint}", 8000)
        return True

    def discard_sculpt(self) -> None:
        doc = self.document
        if doc.edit_offset is not None:
            doc.undo_stack.push(SetEditOffsetCommand(doc, doc.edit_offset, None, "Discard sculpt"))

    # --- from a scan (Smith, future work 1) --------------------------------------------------------
    def from_scan(self, path=None, drivers=None, mode: str | None = None) -> bool:
        """Make the corrective of ``drivers`` (default: the sculpted, else the ticked drivers) from an OBJ scan.

        mode 'drivers': the scan is the drivers at 1, e = (scan − x_cur) / a. mode 'fit': fit all weights
        (bounded least squares), keep the residual over the drivers' region (``corrective_from_scan``).
        """
        from model.obj_io import read_obj
        doc, rig = self.document, self.document.rig
        if rig is None:
            return False
        if drivers is None:
            drivers = self.authoring or self.panel.ticked_drivers()
        try:
            drivers = self._check_drivers(drivers)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        if path is None:
            path = app_settings.open_file(self.window, "scanFolder", "Corrective from Scan", "OBJ (*.obj)")
            if not path:
                return False
        path = Path(path)
        mode = mode or self.panel.scan_mode.currentData()
        own = find_corrective(rig.correctives, drivers)
        rule = own.rule if own is not None else self.panel.current_rule()
        name = own.name if own is not None else "+".join(drivers)
        try:
            made, w = corrective_from_scan(rig, drivers, read_obj(path).vertices, rule, fit=mode == "fit",
                                           name=name, source=path.name, evaluator=doc.evaluator64())
            new = [c for c in rig.correctives if frozenset(c.drivers) != frozenset(drivers)] + [made]
            validate_correctives(new, rig.shape_names, rig.n_vertices)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        except OSError as exc:
            self._error(f"{path}: could not be read ({exc.strerror or exc}).")
            return False
        stack = doc.undo_stack
        stack.beginMacro(f"Corrective {name} from {path.name}")
        stack.push(SetCorrectivesCommand(doc, rig.correctives, new, f"Corrective {name} from {path.name}",
                                         new_offset=None))
        if not np.array_equal(w, doc.weights):
            stack.push(SetWeightsCommand(doc, doc.weights, w, f"Pose of {path.name}"))
        stack.endMacro()
        self.stop_sculpting()
        self.panel.select(name)
        self.window.statusBar().showMessage(f"Made corrective {name} from {path.name}.", 5000)
        return True

    # --- rename, drivers, rule, delete -------------------------------------------------------------
    def _selected(self, name):
        c = self.corrective(name if name is not None else self.panel.selected_name())
        if c is None:
            self._error("Select a corrective in the list first.")
        return c

    def rename(self, name: str | None = None, new_name: str | None = None) -> bool:
        c = self._selected(name)
        if c is None:
            return False
        if new_name is None:
            new_name, ok = QtWidgets.QInputDialog.getText(self.window, "Rename Corrective", "Name:", text=c.name)
            if not ok:
                return False
        new_name = new_name.strip()
        if not new_name:
            self._error("A corrective needs a name; the name was empty.")
            return False
        if new_name == c.name:
            return False
        new = [replace(x, name=new_name) if x is c else x for x in self.document.rig.correctives]
        ok = self._push_correctives(new, f"Rename corrective {c.name} to {new_name}")
        if ok:
            self.panel.select(new_name)
        return ok

    def edit_drivers(self, name: str | None = None, drivers=None) -> bool:
        c = self._selected(name)
        if c is None:
            return False
        if drivers is None:
            text, ok = QtWidgets.QInputDialog.getText(self.window, "Corrective Drivers",
                                                      "Driver shapes, separated by commas:", text=", ".join(c.drivers))
            if not ok:
                return False
            drivers = text.split(",")
        try:
            drivers = [str(d).strip() for d in drivers if str(d).strip()]
            self._check_cycle(drivers)
            new_name = "+".join(drivers) if c.name == "+".join(c.drivers) else c.name
            made = replace(c, name=new_name, drivers=drivers)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        new = [made if x is c else x for x in self.document.rig.correctives]
        ok = self._push_correctives(new, f"Drivers of {c.name}: {', '.join(drivers)}")
        if ok:
            self.panel.select(new_name)
        return ok

    def set_rule(self, rule: str, name: str | None = None) -> bool:
        c = self._selected(name)
        if c is None or c.rule == rule:
            return False
        new = [replace(x, rule=rule) if x is c else x for x in self.document.rig.correctives]
        return self._push_correctives(new, f"Rule of {c.name}: {rule}")

    def mirror(self, name: str | None = None) -> bool:
        """Add the other side's version of a corrective (``model.correctives.mirrored_corrective``); an
        existing corrective on the mirrored drivers is replaced. One undoable edit."""
        c = self._selected(name)
        if c is None:
            return False
        rig = self.document.rig
        try:
            made = mirrored_corrective(c, rig.shape_names, rig.neutral, self.document.mirror_map(), units=rig.units)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        old = find_corrective(rig.correctives, made.drivers)
        new = [made if x is old else x for x in rig.correctives] if old is not None else rig.correctives + [made]
        if not self._push_correctives(new, f"Mirror corrective {c.name} to {made.name}"):
            return False
        self.panel.select(made.name)
        what = f"Replaced {old.name} with" if old is not None else "Made"
        self.window.statusBar().showMessage(f"{what} {made.name}, the mirror image of {c.name}.", 5000)
        return True

    def symmetrize(self, name: str | None = None) -> bool:
        """Make a corrective whose drivers mirror onto themselves exactly symmetric (one undoable edit)."""
        c = self._selected(name)
        if c is None:
            return False
        rig = self.document.rig
        try:
            made = symmetrized_corrective(c, rig.neutral, self.document.mirror_map(), units=rig.units)
        except RigInputError as exc:
            self._error(str(exc))
            return False
        new = [made if x is c else x for x in rig.correctives]
        if not self._push_correctives(new, f"Symmetrize corrective {c.name}"):
            return False
        self.panel.select(made.name)
        change = float(np.linalg.norm(made.delta - c.delta, axis=1).max())
        self.window.statusBar().showMessage(f"Made {c.name} symmetric (it moved by up to {change:.3g} "
                                            f"{rig.units}).", 5000)
        return True

    def mirror_all(self) -> int:
        """Add the mirror image of every corrective whose other side is missing (one undoable edit); returns how
        many were made. Correctives that are their own mirror image are left alone."""
        rig = self.document.rig
        if rig is None:
            return 0
        have = {frozenset(c.drivers) for c in rig.correctives}
        made, problems = [], []
        for c in rig.correctives:
            twin = frozenset(mirror_drivers(c.drivers))
            if twin == frozenset(c.drivers) or twin in have:
                continue
            try:
                made.append(mirrored_corrective(c, rig.shape_names, rig.neutral, self.document.mirror_map(),
                                                units=rig.units))
            except RigInputError as exc:
                problems.append(str(exc))
                continue
            have.add(twin)
        if problems:
            self._error(" ".join(problems))
        if not made:
            if not problems:
                self.window.statusBar().showMessage("Every corrective already has its other side.", 5000)
            return 0
        names = ", ".join(c.name for c in made)
        if not self._push_correctives(rig.correctives + made, f"Mirror {count(len(made), 'corrective')}"):
            return 0
        self.window.statusBar().showMessage(f"Made {count(len(made), 'mirrored corrective')}: {names}.", 8000)
        return len(made)

    def set_muted(self, name: str, muted: bool) -> bool:
        """Mute a corrective (it adds nothing to the face and exports until unmuted) or unmute it; undoable."""
        c = self.corrective(name)
        if c is None or c.muted == bool(muted):
            self._refresh_table()
            return False
        new = [replace(x, muted=bool(muted)) if x is c else x for x in self.document.rig.correctives]
        return self._push_correctives(new, f"{'Mute' if muted else 'Unmute'} corrective {c.name}")

    def delete(self, name: str | None = None) -> bool:
        c = self._selected(name)
        if c is None:
            return False
        new = [x for x in self.document.rig.correctives if x is not c]
        return self._push_correctives(new, f"Delete corrective {c.name}")

    # --- brush shortcuts ---------------------------------------------------------------------------
    def set_brush(self, brush: str) -> None:
        self.panel.brush.setCurrentIndex(max(0, self.panel.brush.findData(brush)))

    def scale_radius(self, factor: float) -> None:
        self.panel.radius.setValue(self.panel.radius.value() * factor)


def install(window) -> CorrectiveController:
    """Plug the Correctives dock, the Correctives menu and its controller into ``window`` (a MainWindow, through
    its public interface: ``add_dock``, ``add_menu``, ``add_action``); the window calls it once and keeps the
    controller as ``window.correctives``."""
    panel = CorrectivesPanel(window)
    dock = window.add_dock("Correctives", panel, QtCore.Qt.LeftDockWidgetArea, scroll=True)
    ctrl = CorrectiveController(window, panel, dock)
    _remember_options(panel)

    def act(text, slot, shortcut, tip, menu="correctives"):
        return window.add_action(menu, text, lambda _=False: slot(), shortcut, tip)
    act("&New Corrective from Combination", ctrl.new_from_combination, "Ctrl+Shift+N",
        "Set the ticked drivers (or the posed shapes) to 1 and sculpt their corrective")
    act("Corrective from &Scan…", ctrl.from_scan, "Ctrl+Shift+I",
        "Make the corrective of the ticked drivers from an OBJ of the desired combination")
    ctrl.sculpt_actions = {
        "save": act("&Save Corrective", ctrl.save, "Ctrl+Return",
                    "Store the sculpt as the corrective: e = (x_des − x_cur) / a"),
        "discard": act("&Discard Sculpt", ctrl.discard_sculpt, None, "Drop the pending sculpt (undoable)"),
        "stop": act("S&top Sculpting", ctrl.stop_sculpting, None, "Leave sculpt mode")}
    ctrl._show_sculpting()
    ctrl.mirror_action = act("&Mirror Corrective", ctrl.mirror, "Ctrl+Shift+M", ctrl.MIRROR_TIP)
    act("Mirror &All Correctives", ctrl.mirror_all, None,
        "Add the other side's version of every corrective that lacks one (one undoable edit)")
    ctrl.symmetrize_action = act("Symmetri&ze Corrective", ctrl.symmetrize, None, ctrl.SYMMETRIZE_TIP)
    ctrl.show_mirror_state()
    window.add_separator("correctives")

    def _find():
        dock.show()
        dock.raise_()
        panel.tabs.setCurrentIndex(INTERFERENCE_TAB)
        ctrl.finder.find_pairs_in_background()
    act("&Find Interfering Pairs", _find, "Ctrl+Shift+F", "Rank shape pairs by the overlap of their displacements")
    window.add_separator("correctives")
    window.add_menu("brush", "&Brush", parent="correctives")
    ctrl.sculpt.brush_actions = [
        act("&Grab", lambda: ctrl.set_brush("grab"), "G", "Grab brush: drag the surface", "brush"),
        act("&Smooth", lambda: ctrl.set_brush("smooth"), "Shift+S", "Smooth brush: relax the surface", "brush"),
        act("&Inflate", lambda: ctrl.set_brush("inflate"), "I", "Inflate brush: push along the normals", "brush"),
        act("&Deflate", lambda: ctrl.set_brush("deflate"), "D", "Deflate brush: pull along the normals", "brush"),
        act("S&ymmetric", panel.symmetric.toggle, "X", "Mirror strokes across x = 0", "brush"),
        act("S&maller Brush", lambda: ctrl.scale_radius(1 / 1.25), "[", "Shrink the brush radius", "brush"),
        act("&Larger Brush", lambda: ctrl.scale_radius(1.25), "]", "Grow the brush radius", "brush"),
    ]
    ctrl.sculpt.set_brush_actions(False)
    return ctrl


def _remember_options(panel: CorrectivesPanel) -> None:
    """The finder's measure, list length and mirror merging, and the brush, its falloff and strength come back
    in the next session (the radius is in rig units and follows each rig's size instead)."""
    from app.settings import remember
    for widget, key in ((panel.measure, "interference/measure"), (panel.top, "interference/top"),
                        (panel.merge_mirrored, "interference/mergeMirrored"), (panel.brush, "sculpt/brush"),
                        (panel.falloff, "sculpt/falloff"), (panel.strength, "sculpt/strength")):
        remember(widget, key)
