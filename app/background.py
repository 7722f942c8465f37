"""Run heavy work off the GUI thread and deliver the result back on it."""
from __future__ import annotations

import traceback
from typing import Any, Callable

from PySide6 import QtCore

from model.errors import RigInputError


class _Signals(QtCore.QObject):
    done = QtCore.Signal(object)
    failed = QtCore.Signal(str)


class _Task(QtCore.QRunnable):
    def __init__(self, fn: Callable[[], Any]) -> None:
        super().__init__()
        self.fn = fn
        self.signals = _Signals()

    def run(self) -> None:
        try:
            result = self.fn()
        except RigInputError as exc:
            self.signals.failed.emit(str(exc))
        except Exception as exc:  # reported to the user, never crashes the app
            traceback.print_exc()
            self.signals.failed.emit(f"{type(exc).__name__}: {exc}")
        else:
            self.signals.done.emit(result)


class BackgroundRunner(QtCore.QObject):
    """Runs one job at a time; a request while busy replaces any queued one (latest settings win)."""

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.pool = QtCore.QThreadPool(self)
        self.pool.setMaxThreadCount(1)
        self._queued: tuple | None = None
        self._busy = False
        self._closed = False

    @property
    def busy(self) -> bool:
        return self._busy or self._queued is not None

    def submit(self, fn: Callable[[], Any], on_done: Callable[[Any], None], on_failed: Callable[[str], None]) -> None:
        if self._closed:
            return
        if self._busy:
            self._queued = (fn, on_done, on_failed)
            return
        self._start(fn, on_done, on_failed)

    def _start(self, fn, on_done, on_failed) -> None:
        self._busy = True
        task = _Task(fn)
        task.signals.done.connect(lambda r: self._finish(on_done, r))
        task.signals.failed.connect(lambda m: self._finish(on_failed, m))
        self._signals = task.signals  # keep the QObject alive until delivery
        self.pool.start(task)

    def _finish(self, callback, value) -> None:
        self._busy = False
        if self._closed:  # the owner is going away: deliver nothing
            return
        queued, self._queued = self._queued, None
        if queued is not None:   # newer settings arrived meanwhile: this result is stale
            self._start(*queued)
            return
        callback(value)

    def wait(self, msecs: int = 60000) -> None:
        self.pool.waitForDone(msecs)
        QtCore.QCoreApplication.processEvents()

    def shutdown(self) -> None:
        """Drop any queued job, wait for the running one and deliver nothing more (the owner is closing)."""
        self._closed = True
        self._queued = None
        self.pool.waitForDone()
