"""Actors who are not the rig, in the window (issue 15): File ▸ Personalize to Actor…, the per-shape change heat map
(View ▸ Personalisation Change), and Edit ▸ Antagonist Pairs….

* Personalise: the dialog (``widgets.personalize_dialog``) gathers the actor's scans or marker take; the work is
  ``model.actor_project.personalize_project`` on a copy of the rig, in a child process (``app.personalize_job``:
  the solver has no cancel of its own, a process can be stopped), with a progress dialog whose Cancel stops it and
  writes nothing; the window stays usable. The result is written as a new project -- the rig's presets,
  correctives, antagonist pairs and project sections come along, with each shape's change per vertex -- and opened
  (the window asks first if the current project has unsaved changes); the current rig's file is never touched.
* The heat map colours the surface by ``‖d_k − d*_k‖`` in mm of one shape, the one picked in the Actor Change panel
  or last touched in the Shapes panel, with a colour bar in mm. It is the Segmentation controller's colour map
  while shown (``view_override``); choosing a view there turns it off.
* Antagonist pairs: the project's list (``Project.antagonists``; by default the pairs found from the rig), edited in
  ``widgets.antagonists_dialog`` with undoable commands (``app.actor_commands``), used by marker drags and take
  solves.
"""
from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.actor_commands import ANTAGONISTS, SetAntagonistsCommand
from model.actor_project import CHANGE, SECTION, change_rows
from model.errors import RigInputError
from model.rig import unit_scale
from widgets.antagonists_dialog import AntagonistsDialog
from widgets.personalize_dialog import PersonalizeDialog, ShapeChangePanel
from widgets.scene import ColorMap


class PersonalizeController(QtCore.QObject):
    personalized = QtCore.Signal(str)      # the actor's project was written (its path)
    failed = QtCore.Signal(str)
    cancelled = QtCore.Signal()
    heat_map_changed = QtCore.Signal(str)  # the shape the heat map shows ("" when off)
    progress_changed = QtCore.Signal(str)  # the progress window's text (the stage reached, the time so far)

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window, self.document = window, window.document
        self.busy = False
        self.job = None                      # the running app.personalize_job.PersonalizeJob
        self.progress: QtWidgets.QProgressDialog | None = None
        self._started = 0.0                  # time.monotonic() when the running job started
        self._rig_name = ""
        self._timer = QtCore.QTimer(self)    # polls the job's child process
        self._timer.setInterval(200)
        self._timer.timeout.connect(self._poll)
        self.last_summary: dict | None = None
        self.dialog: PersonalizeDialog | None = None
        self._open_when_loaded: Path | None = None
        self.heat_shape: str | None = None
        self._change: tuple | None = None    # (section, (K, V) change) of the open project, or None
        self.action = window.add_action("file", "&Personalize to Actor…", self.show_dialog, "Ctrl+Shift+P",
                                        "Build the actor's own rig from their scans or a marker take (Ma et al. "
                                        "2016) as a new project; the current rig is not changed")
        self.heat_action = window.add_action("view", "Personalisation &Change", self.show_heat_map, "Ctrl+Shift+H",
                                             "Colour the face by how far personalisation moved the selected "
                                             "shape from the template (mm)", checkable=True)
        self.panel = ShapeChangePanel(window)
        self.dock = window.add_dock("Actor Change", self.panel, QtCore.Qt.RightDockWidgetArea)
        self.dock.hide()
        self.panel.shape_picked.connect(self.show_shape)
        d = self.document
        d.rig_changed.connect(self._on_rig_change)
        d.shapes_changed.connect(self._on_shapes_change)
        window.shapes_panel.pose_edited.connect(self._on_pose_edit)
        window.segmentation_panel.view_changed.connect(lambda _v: self.heat_action.setChecked(False))
        QtWidgets.QApplication.instance().focusChanged.connect(self._on_focus)
        if d.project is not None:
            self._on_rig_change()

    # --- personalising ----------------------------------------------------------------------------
    def show_dialog(self) -> PersonalizeDialog | None:
        doc = self.document
        if doc.project is None:
            return None
        if self.busy:
            self.window.show_status("A personalisation is already running; it finishes in the background.")
            return None
        ws = self.window.mocap.workspace
        from app import settings as app_settings
        s = app_settings.settings()
        folder = doc.path.parent if doc.path else Path(s.value("lastProjectFolder", "") or s.value("lastFolder", "")
                                                       or Path.home())
        base = doc.path.stem if doc.path else doc.rig.name
        take = str(ws.take_path) if ws.marker_take is not None and ws.take_path else ""
        mm = ws.marker_map.source if ws.marker_map is not None and Path(ws.marker_map.source or "").is_file() else ""
        dlg = PersonalizeDialog(self.window, rig_name=doc.rig.name, output=str(folder / f"{base}_actor.bsproj"),
                                take=take, marker_map=mm, folder=str(folder),   # the take's neutral as solved
                                calibration_frames=self.window.mocap.panel.settings()["calibration_frames"],
                                neutral_frames=self._chosen_neutral() if take else "")
        dlg.setAttribute(QtCore.Qt.WA_DeleteOnClose)
        dlg.accepted.connect(lambda: self.personalize(dlg.request()))
        dlg.destroyed.connect(lambda *_: setattr(self, "dialog", None))
        self.dialog = dlg
        dlg.open()
        return dlg

    def _chosen_neutral(self) -> str:
        """The actor's neutral frames chosen in the Mocap panel ("Use This Frame as Neutral", typed, or 'auto' as the
        last solve found them) as 'A:B', or "" for the first calibration frames."""
        mocap = self.window.mocap
        chosen = mocap.panel.settings()["neutral_frames"]
        if chosen is not None and chosen.strip().lower() == "auto":
            solution = mocap.workspace.solution
            found = getattr(solution, "neutral_frames", None)
            return f"{int(found[0])}:{int(found[1])}" if found is not None else ""
        return chosen or ""

    def personalize(self, request: dict) -> bool:
        """Start the personalisation of the open rig with ``request`` (``PersonalizeDialog.request``) in the
        background; the result is written and then opened. False (and a message box) for a request that cannot
        start."""
        doc = self.document
        if doc.project is None or self.busy:
            return False
        try:
            out = request.get("output")
            if not out:
                raise RigInputError("Choose where to write the actor's project (.bsproj).")
            out = Path(out)
            if out.suffix.lower() != ".bsproj":
                out = out.with_name(out.name + ".bsproj")
            self._check_output(out, request)
            if not (request.get("neutral_scan") or request.get("scans") or request.get("take")):
                raise RigInputError("Personalising needs measurements of the actor: a neutral scan, pose scans "
                                    "or a marker take.")
            if request.get("neutral_frames") and request.get("take"):
                from model.take_workspace import parse_neutral_frames
                if parse_neutral_frames(request["neutral_frames"], "Neutral frames") == "auto":
                    raise RigInputError("Neutral frames: personalising takes the actor's neutral as a frame range "
                                        "A:B, not 'auto'.")
        except RigInputError as exc:
            self._fail(str(exc))
            return False
        request = dict(request, output=str(out))
        from app import session_state
        session_state.store(self.window)      # the take, its map and the view come along
        p = doc.project
        state = {"weights": doc.weights.copy() if not doc.is_regional else None,
                 "sections": copy.deepcopy(p.sections), "arrays": {k: np.array(a) for k, a in p.arrays.items()
                                                                   if k != CHANGE},
                 "antagonists": None if p.antagonists is None else list(p.antagonists),
                 "template": str(doc.path) if doc.path else doc.rig.name}
        state["sections"].pop(SECTION, None)
        template = doc.rig.snapshot()   # the job never sees the live rig (edits go on meanwhile)
        from app.personalize_job import PersonalizeJob
        try:
            self.job = PersonalizeJob(template, state, request)
        except OSError as exc:
            self._fail(f"The personalisation could not start ({exc.strerror or exc}).")
            return False
        self.busy = True
        self.action.setEnabled(False)
        self.window.show_status(f"Personalising {template.name} to the actor in the background…", 0)
        self._started, self._rig_name = time.monotonic(), template.name
        dlg = QtWidgets.QProgressDialog(self._progress_text(), "Cancel", 0, 0, self.window)
        dlg.setWindowTitle("Personalize to Actor")
        dlg.setWindowModality(QtCore.Qt.NonModal)
        dlg.setMinimumDuration(0)
        dlg.canceled.connect(self.cancel)
        self.progress = dlg
        dlg.show()
        self._timer.start()
        return True

    def _check_output(self, out: Path, request: dict) -> None:
        """Refuse (RigInputError, one sentence) before any work an actor's project ``out`` that cannot be written
        (``model.atomic.check_output_file``: a folder, a read-only folder, ...) or that is a file the window has open
        (``model.beside_inputs``: the project, the rig's file, which after Save As is another project, the Mocap
        panel's take and map) or one the request reads (the scans, the take, its map). The job found the first at
        its very end, and only the open project itself was guarded."""
        from model.atomic import check_output_file
        from model.beside_inputs import check_not_input, check_not_inputs
        fix = "write the actor's project to {}"
        check_output_file(out)
        check_not_inputs(out, self.window.export_inputs(), fix)
        for name, value in (("the neutral scan", request.get("neutral_scan")), ("the take", request.get("take")),
                            ("the marker map", request.get("marker_map")),
                            *(("a pose scan", scan) for scan in request.get("scans") or ())):
            if value:
                check_not_input(out, value, name, "this personalisation reads", fix, reads="scans")

    def _progress_text(self) -> str:
        """The progress window's text: the stage the job reported last and the time it has run."""
        stage = self.job.stage if self.job is not None and self.job.stage else "starting"
        seconds = int(time.monotonic() - self._started)
        took = f"{seconds} s" if seconds < 60 else f"{seconds // 60} min {seconds % 60:02d} s"
        return (f"Personalising {self._rig_name} to the actor: {stage}… ({took})\nIt runs on its own: the window "
                "stays usable. Cancel stops it and writes nothing.")

    def _show_progress(self) -> None:
        if self.progress is None:
            return
        text = self._progress_text()
        if text != self.progress.labelText():
            self.progress.setLabelText(text)
            self.progress_changed.emit(text)

    def cancel(self) -> None:
        """Stop the running personalisation (Cancel in its progress dialog): nothing is written."""
        job = self.job
        if job is None:
            return
        job.cancel()
        self._finish()
        self.window.show_status("Personalisation cancelled; nothing was written.")
        self.cancelled.emit()

    def shutdown(self) -> None:
        """The window is closing: stop a running personalisation at once."""
        if self.job is not None:
            self.job.cancel()
            self._finish()

    def _poll(self) -> None:
        job = self.job
        if job is None:
            return
        result = job.poll()
        if result is None:
            self._show_progress()
            return
        self._finish()
        kind, value = result
        if kind == "done":
            self._on_done(value)
        elif kind == "failed":
            self._fail(value)

    def _finish(self) -> None:
        self._timer.stop()
        self.job = None
        self.busy = False
        self.action.setEnabled(True)
        dlg, self.progress = self.progress, None
        if dlg is not None:
            dlg.canceled.disconnect()
            dlg.reset()
            dlg.close()
            dlg.deleteLater()

    def _fail(self, message: str) -> None:
        self.window.show_error("Could not personalise", message)
        self.failed.emit(message)

    def _on_done(self, result) -> None:
        out, summary, rows = result
        self.last_summary = summary
        top = ", ".join(f"{r['shape']} {r['rms']:.2f} mm" for r in rows[:3])
        template = self.document.path or self.document.rig.name
        self.window.show_status(f"Wrote {out}: {len(rows)} shapes personalised ({summary['unknowns']:,} unknowns, "
                                f"{summary['seconds']:.1f} s); most changed: {top}. The template ({template}) is "
                                "unchanged.", 15000)
        self.personalized.emit(str(out))
        self._open_when_loaded = Path(out)
        self.window.open_path(out)    # asks first when the current project has unsaved changes

    # --- the heat map -----------------------------------------------------------------------------
    def _load_change(self) -> None:
        """The open project's saved per-shape change, if it has one that fits the rig."""
        self._change = None
        p = self.document.project
        section = p.sections.get(SECTION) if p is not None else None
        change = p.arrays.get(CHANGE) if p is not None else None
        if isinstance(section, dict) and change is not None and isinstance(section.get("shapes"), list):
            names = section["shapes"]
            if (change.ndim == 2 and change.shape == (len(names), p.rig.n_vertices)
                    and all(isinstance(n, str) for n in names)):
                from model.rig import UNIT_IN_METRES
                if section.get("units") not in UNIT_IN_METRES:
                    section = dict(section, units=p.rig.units)
                self._change = (section, np.asarray(change, dtype=np.float32))

    @property
    def has_change(self) -> bool:
        return self._change is not None

    def _on_rig_change(self) -> None:
        self._load_change()
        self.heat_action.setEnabled(self.has_change)
        if self.has_change:
            section, change = self._change
            rows = change_rows(section, change)
            summary = section.get("summary") or {}
            self.panel.set_rows(rows, f"Personalised from {Path(str(section.get('template', '?'))).name}: "
                                      f"{len(rows)} shapes (neutral: {summary.get('neutral', '?')}). Change of each "
                                      "shape, personalised minus template:")
            opened, self._open_when_loaded = self._open_when_loaded, None
            if opened is not None and self.document.path is not None and \
                    self.document.path.resolve() == opened.resolve():
                self.dock.show()
                self.dock.raise_()
                self.heat_shape = rows[0]["shape"] if rows else None
                # after the project's view is restored (the window does that once every controller has the rig)
                QtCore.QTimer.singleShot(0, lambda: self.heat_action.setChecked(self.has_change))
            elif self.heat_shape not in section["shapes"]:
                self.heat_shape = rows[0]["shape"] if rows else None
            if self.heat_action.isChecked():
                self._refresh()
        else:
            self.panel.set_rows([], "This rig was not personalised (File ▸ Personalize to Actor…).")
            self.heat_action.setChecked(False)

    def _on_shapes_change(self) -> None:
        if not self.has_change or not self.heat_action.isChecked():
            return
        self._refresh()

    def show_heat_map(self, on: bool = True) -> None:
        seg = self.window.segmentation
        if on and not self.has_change:
            self.heat_action.setChecked(False)
            self.window.show_status("This rig was not personalised: File ▸ Personalize to Actor… builds one that is.")
            return
        seg.view_override = self.heat_colormap if on else None
        seg.refresh_view()
        self.heat_map_changed.emit(self.heat_shape or "" if on else "")

    def show_shape(self, name: str) -> None:
        """Show ``name``'s change (and turn the heat map on)."""
        if not self.has_change or name not in self._change[0]["shapes"]:
            return
        self.heat_shape = name
        self.panel.select_shape(name)
        if self.heat_action.isChecked():
            self._refresh()
        else:
            self.heat_action.setChecked(True)

    def _refresh(self) -> None:
        self.window.segmentation.refresh_view()
        self.heat_map_changed.emit(self.heat_shape or "")

    def heat_colormap(self) -> ColorMap | None:
        """The colour map of the shown shape's change in mm (0 to its largest change), or None."""
        if not self.has_change or self.heat_shape is None:
            return None
        section, change = self._change
        names = section["shapes"]
        if self.heat_shape not in names:
            return None
        values = change[names.index(self.heat_shape)] * unit_scale(section.get("units", "cm"), "mm")
        hi = float(values.max(initial=0.0))
        return ColorMap(values, title=f"{self.heat_shape}\nchange (mm)", cmap="YlOrRd",
                        clim=(0.0, max(hi, 1e-3)))

    def _on_pose_edit(self, edit) -> None:
        """The heat map follows the shape the user works on in the Shapes panel."""
        rig = self.document.rig
        if self.heat_action.isChecked() and rig is not None and 0 <= edit.shape < rig.n_shapes:
            name = rig.shape_names[edit.shape]
            if name != self.heat_shape:
                self.show_shape(name)

    def _on_focus(self, _old, new) -> None:
        """A shape's slider or number box in the Shapes panel took the focus: show that shape's change."""
        if not self.heat_action.isChecked() or new is None or self.document.rig is None:
            return
        panel, names = self.window.shapes_panel, self.document.rig.shape_names
        w = new
        while w is not None and w is not panel:
            name = getattr(w, "name", None)
            if isinstance(name, str) and name in names and w.parent() is not None:
                if name != self.heat_shape:
                    self.show_shape(name)
                return
            w = w.parentWidget()


class AntagonistsController(QtCore.QObject):
    """Edit ▸ Antagonist Pairs…: the project's pairs, each edit one undo step."""

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window, self.document = window, window.document
        self.dialog: AntagonistsDialog | None = None
        self._found: tuple[int, list] | None = None    # (rig version, the rig's own pairs)
        window.add_separator("edit")
        self.action = window.add_action("edit", "&Antagonist Pairs…", self.show_dialog, None,
                                        "The shape pairs a drag or a take solve never leaves both strongly on "
                                        "(jawLeft/jawRight…): found from the rig, editable")
        self.document.section_changed.connect(lambda name: self._refresh() if name == ANTAGONISTS else None)
        self.document.rig_changed.connect(self._refresh)
        self.document.shapes_changed.connect(self._refresh)

    def found_pairs(self) -> list[tuple[str, str]]:
        """The pairs found from the rig itself (``model.antagonists.rig_antagonists``), once per rig version."""
        from model.antagonists import rig_antagonists
        doc = self.document
        if self._found is None or self._found[0] != doc.rig_version:
            self._found = (doc.rig_version, rig_antagonists(doc.rig))
        return self._found[1]

    def pairs(self) -> list[tuple[str, str]]:
        """The pairs the solves keep apart now."""
        p = self.document.project
        return list(p.antagonists) if p.antagonists is not None else self.found_pairs()

    def show_dialog(self) -> AntagonistsDialog | None:
        if self.document.project is None:
            return None
        if self.dialog is None:
            self.dialog = AntagonistsDialog(self.window)
            self.dialog.add_requested.connect(self.add_pair)
            self.dialog.remove_requested.connect(self.remove_pairs)
            self.dialog.reset_requested.connect(self.reset)
            # Ctrl+Z / Ctrl+Shift+Z undo and redo the pair edits while the dialog has the keyboard
            self.dialog.addActions([self.window.undo_action, self.window.redo_action])
        self._refresh(force=True)
        self.dialog.show()
        self.dialog.raise_()
        return self.dialog

    def _refresh(self, force: bool = False) -> None:
        d = self.dialog
        if d is None or (not force and not d.isVisible()) or self.document.project is None:
            return
        d.set_state(self.pairs(), self.document.rig.shape_names, self.found_pairs(),
                    self.document.project.antagonists is not None)

    def _push(self, new, text: str) -> None:
        old = self.document.project.antagonists
        self.document.undo_stack.push(SetAntagonistsCommand(self.document, old, new, text))

    def add_pair(self, a: str, b: str) -> bool:
        names = self.document.rig.shape_names
        for n in (a, b):
            if n not in names:
                self.window.show_error("Antagonist Pairs", f"The rig has no shape named '{n[:60]}'.")
                return False
        if a == b:
            self.window.show_error("Antagonist Pairs", f"{a} cannot act against itself: choose two shapes.")
            return False
        pairs = self.pairs()
        if frozenset((a, b)) in {frozenset(p) for p in pairs}:
            self.window.show_status(f"{a} and {b} are already kept apart.")
            return False
        self._push(pairs + [(a, b)], f"Add antagonist pair {a}+{b}")
        return True

    def remove_pairs(self, chosen) -> bool:
        gone = {frozenset(p) for p in chosen}
        pairs = self.pairs()
        new = [p for p in pairs if frozenset(p) not in gone]
        if len(new) == len(pairs):
            return False
        text = (f"Remove antagonist pair {chosen[0][0]}+{chosen[0][1]}" if len(chosen) == 1
                else f"Remove {len(pairs) - len(new)} antagonist pairs")
        self._push(new, text)
        return True

    def reset(self) -> bool:
        if self.document.project.antagonists is None:
            return False
        self._push(None, "Use the rig's antagonist pairs")
        return True


def install(window) -> PersonalizeController:
    """Plug personalisation, the change heat map and the antagonist pairs into ``window`` (a MainWindow, through
    its public interface); the window keeps the result as ``window.actor`` (its ``antagonists`` the pairs'
    controller)."""
    controller = PersonalizeController(window)
    controller.antagonists = AntagonistsController(window)
    return controller
