"""File ▸ Batch Solve…: the open rig and chosen takes solved with ``solve``'s options on a Dask cluster in the
background (``model.batch.run_batch`` on the controller's BackgroundRunner thread, so the window stays usable),
with progress in the dialog and a table of results from which a take opens in the Mocap panel.
"""
from __future__ import annotations

import argparse
import threading
from pathlib import Path

from PySide6 import QtCore

from app import settings as app_settings
from app.background import BackgroundRunner
from model.errors import RigInputError
from widgets.batch_dialog import BatchDialog


class _OptionParser(argparse.ArgumentParser):
    """``solve``'s options parsed for the dialog: a bad option is a RigInputError, not an exit."""

    def error(self, message: str):
        raise RigInputError(f"Solve options: {message}.")


class _Relay(QtCore.QObject):
    progress = QtCore.Signal(object)    # model.batch.BatchProgress, from the runner's thread


class BatchController(QtCore.QObject):
    """Owns the Batch Solve dialog and its run; ``finished(rows)`` after a run (``failed(message)`` if none)."""

    finished = QtCore.Signal(list)
    failed = QtCore.Signal(str)

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window = window
        self.dialog: BatchDialog | None = None
        self.rows: list[dict] = []
        self.running = False
        self._units = ""              # the length unit of the rig the running batch solves
        self._notes = ""              # what the running batch left out of what was given, said with its end
        self.map_path: str | None = None
        self.runner = BackgroundRunner(self)
        self._cancel = threading.Event()
        self._relay = _Relay(self)
        self._relay.progress.connect(self._on_progress)

    def show_dialog(self) -> BatchDialog | None:
        if self.window.document.rig is None:
            self.window.show_error("Batch Solve", "Open a rig first: the batch solves the takes onto the open rig.")
            return None
        if self.dialog is None:
            d = self.dialog = BatchDialog(self.window)
            d.run_requested.connect(self.run)
            d.cancel_requested.connect(self.cancel)
            d.open_requested.connect(self.open_take)
            d.results_requested.connect(self.open_results)
            d.dropped.connect(self.drop)
            for widget, key in ((d.output_edit, "output"), (d.map_edit, "markerMap"), (d.mode_combo, "mode"),
                                (d.residual_combo, "residual"), (d.calibration_spin, "calibrationFrames"),
                                (d.fixed_head_check, "fixedHead"), (d.extra_edit, "moreOptions"),
                                (d.cache_check, "cache"), (d.workers_spin, "workers"),
                                (d.scheduler_edit, "scheduler")):
                app_settings.remember(widget, f"batch/{key}")     # the last batch's form, in the next session
        self.dialog.show()
        self.dialog.raise_()
        self.dialog.activateWindow()
        return self.dialog

    def _options(self):
        from app.cli_solve import add_solve_options
        parser = _OptionParser(prog="Batch Solve", add_help=False)
        add_solve_options(parser)
        return parser.parse_args(self.dialog.solve_options())

    def run(self) -> bool:
        """Start the batch the dialog describes; False (and the reason in the dialog) if it cannot start."""
        from app.cli_batch import prepare_job, progress_text
        from model.batch import find_takes, run_batch
        d = self.dialog
        if self.running or d is None:
            return False
        try:
            args = self._options()
            if not d.takes():
                raise RigInputError("Add the takes to solve first.")
            if not d.output():
                raise RigInputError("Choose the output folder first.")
            notes: list[str] = []       # a batch's own output added as a take: left out, and said so
            takes = find_takes(d.takes(), exclude=d.output(), notes=notes)
            args.cache = d.cache_check.isChecked()
            self._check_not_inputs(d.output(), takes, args)
        except RigInputError as exc:
            return self._refuse(str(exc))
        rig = self.window.document.rig.snapshot()   # the user may go on editing the open rig
        if args.rig_units:
            rig.units = args.rig_units
        self._units = rig.units
        out, force, scheduler = Path(d.output()), d.force_check.isChecked(), d.scheduler() or None
        workers = None if scheduler else d.workers_spin.value()
        self.map_path = args.map
        self._cancel = cancel = threading.Event()
        relay = self._relay

        def job():
            return run_batch(prepare_job(rig, args), takes, out, force=force, workers=workers, scheduler=scheduler,
                             progress=relay.progress.emit, cancel=cancel.is_set)

        self._progress_text = progress_text
        self.running = True
        d.set_running(True)
        self._notes = " ".join(notes)
        d.set_status(f"Starting: {len(takes)} take(s) onto {rig.name}… {self._notes}".rstrip())
        self.window.show_status(f"Batch solve of {len(takes)} take(s) started.")
        self.runner.submit(job, self._on_done, self._on_failed)
        return True

    def _check_not_inputs(self, out: str, takes: list[Path], args) -> None:
        """Refuse (RigInputError, one sentence) a batch into ``out`` that would write over, or among, what it reads
        or the window has open (``model.beside_inputs``): a file of a take's set that is a take given (an earlier
        batch's ``weights.csv``), the marker map or the Mocap panel's take; a summary among a folder of takes given
        (read as one more take); a file the rig's OBJ folder reads. Nothing is written then."""
        from model.batch import batch_files, take_names
        from model.beside_inputs import check_not_input, check_not_inputs
        fix = "choose another output folder"
        given = [(item, Path(item).is_dir()) for item in self.dialog.takes()]
        for path in batch_files(out, take_names(takes), args.cache):
            check_not_inputs(path, self.window.export_inputs(), fix)
            for item, folder in given:
                check_not_input(path, item, "a folder of takes to solve" if folder else "a take to solve",
                                "this batch reads", fix, reads="takes", where="{name}")
            if args.map:
                check_not_input(path, args.map, "the marker map", "this batch reads", fix, reads="scans")

    def _refuse(self, sentence: str) -> bool:
        """Say why the dialog's request cannot be done, in the dialog and the status bar; False."""
        self.dialog.set_status(sentence)
        self.window.show_status(sentence)
        return False

    def cancel(self) -> None:
        if self.running:
            self._cancel.set()
            if self.dialog is not None:
                self.dialog.set_status("Cancelling: the takes being solved finish first…")

    def _on_progress(self, p) -> None:
        if self.dialog is None:
            return
        text = self._progress_text(p)
        if p.dashboard:
            text += f' — <a href="{p.dashboard}">Dask dashboard</a>'
        self.dialog.set_progress(p.done, p.total, text)

    def _on_done(self, rows: list) -> None:
        from app.crash import log_unexpected_rows
        from model.batch import counts_text
        self.running = False
        log_unexpected_rows(rows, "solving the take")
        text = f"Batch: {counts_text(rows)}; summary in {Path(self.dialog.output()) / 'batch.json'}."
        text = f"{text} {self._notes}".rstrip()
        self.dialog.set_running(False)
        self._show_rows(Path(self.dialog.output()), rows, self._units)   # the RMSE is in the solved rig's units
        self.dialog.set_progress(len(rows), len(rows), text)
        self.window.show_status(text, 0)
        self.finished.emit(rows)

    def _on_failed(self, message: str) -> None:
        self.running = False
        if self.dialog is not None:
            self.dialog.set_running(False)
            self.dialog.set_progress(0, 1, f"Could not run the batch: {message}")
        self.window.show_error("Batch Solve", message)
        self.failed.emit(message)

    def _show_rows(self, batch_dir: Path, rows: list[dict], units: str) -> None:
        from model.batch import preview_path
        self.rows = rows
        self.dialog.set_rows(rows, units=units, previews=[preview_path(batch_dir, r["take"]) for r in rows])

    def open_results(self, path: str) -> bool:
        """Show the results of an earlier batch (its ``batch.json``, or the folder holding it: a run of this
        dialog or of the ``batch`` command, here or on a cluster) in the dialog's table, with the previews in its
        folder; a take then opens from it with the marker map that batch used. False (the reason in the dialog)
        for a file that is not a batch summary, or while a batch runs."""
        from model.batch import counts_text, read_summary
        d = self.dialog
        if d is None:
            return False
        if self.running:
            d.set_status("A batch is running: open earlier results when it has finished.")
            return False
        try:
            folder, summary = read_summary(path)
        except RigInputError as exc:
            return self._refuse(str(exc))
        rows = summary["takes"]
        marker_map = summary.get("marker_map")
        self.map_path = marker_map if isinstance(marker_map, str) and Path(marker_map).is_file() else None
        units = summary.get("rig_units") if isinstance(summary.get("rig_units"), str) else ""
        self._show_rows(folder, rows, units)
        rig = summary.get("rig")
        d.set_progress(len(rows), len(rows), f"Results of {folder}" + (f" (rig {rig})" if isinstance(rig, str) else "")
                       + f": {counts_text(rows)}.")
        return True

    def drop(self, paths: list[str]) -> bool:
        """Files dropped on the dialog: takes and folders of takes join the list, a marker map fills its field, a
        batch's results show (``model.batch.sort_dropped``). Anything else is one sentence, and nothing changes."""
        from model.batch import sort_dropped
        d = self.dialog
        try:
            items = sort_dropped(paths)
        except RigInputError as exc:
            return self._refuse(str(exc))
        d.add_takes([str(p) for p in items.takes])
        if items.marker_map is not None:
            d.map_edit.setText(str(items.marker_map))
        if items.results is not None:
            return self.open_results(str(items.results))
        return True

    def open_take(self, row: int) -> bool:
        """Open take ``row`` of the results (and the batch's marker map) in the Mocap panel."""
        if not 0 <= row < len(self.rows):
            return False
        if not self.rows[row]["path"]:
            self.window.show_status(f"The batch's summary names no take file for {self.rows[row]['take']}.")
            return False
        mocap = self.window.mocap
        if not mocap.load_take(self.rows[row]["path"]):
            return False
        if self.map_path and not mocap.load_map(self.map_path):
            return False
        mocap.show_panel(f"Opened {self.rows[row]['take']} in the Mocap panel: Solve to see it frame by frame.")
        return True

    def shutdown(self) -> None:
        """Stop the run (the takes being solved finish) and wait for it: the window is closing."""
        self._cancel.set()
        self.runner.shutdown()


def install(window) -> BatchController:
    """File ▸ Batch Solve… in ``window`` (through its public interface); the window keeps it as ``window.batch``."""
    controller = BatchController(window)
    controller.action = window.add_action(
        "file", "&Batch Solve…", lambda _=False: controller.show_dialog(), None,
        "Solve many takes onto the open rig with the same options, on a Dask cluster, in the background")
    window.add_separator("file")
    return controller
