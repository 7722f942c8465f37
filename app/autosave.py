"""Autosave, crash recovery and the "already open" warning in the window (issue 17); the files themselves
are model.recovery's.

- Every ``interval`` seconds (Preferences key ``autosave/seconds``, default 120) and after ``idle`` seconds
  without an edit (default 10), an edited document is written to its recovery file in the background
  (a snapshot copied on the GUI thread, written on a worker: ICT takes about a second to deflate).
- A save that makes the document clean, opening another document, and a normal quit remove it.
- At start ``offer_recovery`` finds autosaves that a crash or a kill left and asks whether to restore one,
  showing when it was written; a restored document opens as modified, under its project's path.
- Opening a project takes its lock; another live window holding it is named in a warning.
"""
from __future__ import annotations

from pathlib import Path

from PySide6 import QtCore, QtWidgets

from app import settings as app_settings
from app.background import BackgroundRunner
from model.recovery import (Recovery, describe_owner, find_recoveries, load_recovery, recovery_snapshot, release_lock,
                            remove_recovery, take_lock, write_recovery)

DEFAULT_INTERVAL_S = 120
DEFAULT_IDLE_S = 10


class AutosaveController(QtCore.QObject):
    saved = QtCore.Signal(str)   # the recovery file written (tests wait for it)

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window = window
        self.document = window.document
        s = app_settings.settings()
        self.interval_s = float(s.value("autosave/seconds", DEFAULT_INTERVAL_S))
        self.idle_s = float(s.value("autosave/idleSeconds", DEFAULT_IDLE_S))
        self.runner = BackgroundRunner(self)
        self._dirty = False            # edited since the last autosave
        self.written = 0               # autosaves written in this session
        self._shut_down = False
        self._owner: tuple | None = None   # (project path, rig source) the recovery file belongs to
        self._locked: Path | None = None
        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(int(self.interval_s * 1000))
        self.timer.timeout.connect(self.autosave_now)
        self.timer.start()
        self.idle = QtCore.QTimer(self)
        self.idle.setSingleShot(True)
        self.idle.setInterval(int(self.idle_s * 1000))
        self.idle.timeout.connect(self.autosave_now)
        stack = self.document.undo_stack
        stack.indexChanged.connect(self._on_edit)
        stack.cleanChanged.connect(self._on_clean_change)
        self.document.rig_changed.connect(self._on_new_document)
        self.document.path_changed.connect(self._on_path_change)

    # --- autosave ----------------------------------------------------------------------------------
    def _on_edit(self, _index: int) -> None:
        if self.document.is_modified:
            self._dirty = True
            self.idle.start()

    def autosave_now(self) -> None:
        """Write the recovery file if the document has edits not yet autosaved (in the background)."""
        doc = self.document
        if doc.project is None or not self._dirty or not doc.is_modified or self.runner.busy:
            return
        self._dirty = False
        snapshot = recovery_snapshot(doc.project)   # the rig's large arrays shared, not copied
        snapshot.region_weights, snapshot.region_blend, snapshot.region_level = \
            doc.region_weights, doc.region_blend, doc.region_level
        path = doc.path if doc.path is not None and doc.path.suffix.lower() == ".bsproj" else None
        self._owner = (path, snapshot.rig.source)
        self.runner.submit(lambda: write_recovery(snapshot, path), self._on_written, self._on_failed)

    def _on_written(self, path) -> None:
        self.written += 1
        self.saved.emit(str(path))

    def _on_failed(self, message: str) -> None:
        self._dirty = True
        self.window.show_status(f"Autosave failed: {message}", 10000)

    def _remove(self) -> None:
        if self.runner.busy:      # a recovery file being written: let it finish first (it delivers by events)
            self.runner.wait()
        if self._owner is not None:
            remove_recovery(*self._owner)
            self._owner = None

    def _on_clean_change(self, clean: bool) -> None:
        if clean:                      # saved (or every edit undone): the project file holds it all
            self._dirty = False
            self._remove()

    def _on_new_document(self) -> None:
        self._dirty = False
        self._remove()

    def _on_path_change(self) -> None:
        path = self.document.path
        if self._locked is not None and self._locked != path:
            release_lock(self._locked)
            self._locked = None
        if path is not None and path.suffix.lower() == ".bsproj" and self._locked != path:
            other = take_lock(path)
            self._locked = path
            if other is not None:
                self.window.show_error("Already open", describe_owner(other, path))

    def shutdown(self, clean_quit: bool = True) -> None:
        """On a normal quit: stop the timers, remove the recovery file and release the lock."""
        if self._shut_down:
            return
        self._shut_down = True
        self.timer.stop()
        self.idle.stop()
        stack = self.document.undo_stack
        stack.indexChanged.disconnect(self._on_edit)
        stack.cleanChanged.disconnect(self._on_clean_change)
        if clean_quit:
            self._remove()
        self.runner.shutdown()
        if self._locked is not None:
            release_lock(self._locked)
            self._locked = None

    # --- recovery at start ---------------------------------------------------------------------------
    def pending(self, path: str | Path | None = None) -> list[Recovery]:
        p = Path(path) if path and str(path).lower().endswith(".bsproj") else None
        return find_recoveries(p)

    def restore(self, rec: Recovery) -> None:
        """Open an autosave as the document: under its project's path, modified, the file kept until saved."""
        project = load_recovery(rec)
        path = Path(rec.project_path) if rec.project_path else None
        self.document.set_project(project, path)
        self.document.undo_stack.resetClean()     # unsaved edits: the project file does not hold them yet
        self._owner = (path, project.rig.source)
        self.window.show_status(f"Restored {rec.describe()}")

    def offer_recovery(self, path: str | Path | None = None) -> bool:
        """Ask whether to restore the newest autosave left by a crash; True if one was restored."""
        found = self.pending(path)
        if not found:
            return False
        rec = found[0]
        box = QtWidgets.QMessageBox(QtWidgets.QMessageBox.Question, "Restore autosave",
                                    f"Blendshape Studio did not close normally. Restore {rec.describe()}?",
                                    QtWidgets.QMessageBox.NoButton, self.window)
        restore = box.addButton("Restore", QtWidgets.QMessageBox.AcceptRole)
        box.addButton("Discard", QtWidgets.QMessageBox.DestructiveRole)
        box.setDefaultButton(restore)
        self.recovery_box = box
        box.exec()
        self.recovery_box = None
        if box.clickedButton() is restore:
            self.restore(rec)
            return True
        rec.path.unlink(missing_ok=True)
        return False
