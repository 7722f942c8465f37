"""Run heavy work off the GUI thread and deliver the result back on it."""
from __future__ import annotations

import threading
import traceback
from typing import Any, Callable

from PySide6 import QtCore, QtWidgets

from model.errors import RigInputError


_modal_depth = 0   # ``run_modal`` calls under way
_held: list[Callable[[], None]] = []   # deliveries waiting for the last ``run_modal`` to end, in arrival order


def after_modal(deliver: Callable[[], None]) -> None:
    """Run ``deliver`` now, or once no ``run_modal`` is under way. A background job's result reaches the GUI thread
    as a queued signal, which ``run_modal``'s event loop delivers like any other: its callback (a shape added,
    a segmentation shown) would then change the document in the middle of an undo command's edit or a save.
    Held deliveries run in the order they came, on the event loop's first turn after the last modal ends."""
    if _modal_depth:
        _held.append(deliver)
    else:
        deliver()


def _release_held() -> None:
    while _held and not _modal_depth:   # a delivery may start a modal: the rest wait for that one too
        _held.pop(0)()


class _Finished(QtCore.QObject):
    done = QtCore.Signal()


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
            from model.atomic import disk_error
            full = disk_error(None, exc)     # a full disk under a write the model did not name: still one sentence
            if full is None:
                traceback.print_exc()
            self.signals.failed.emit(str(full) if full is not None else f"{type(exc).__name__}: {exc}")
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
        after_modal(lambda: None if self._closed else callback(value))

    def wait(self, msecs: int = 60000) -> None:
        self.pool.waitForDone(msecs)
        QtCore.QCoreApplication.processEvents()

    def shutdown(self) -> None:
        """Drop any queued job, wait for the running one and deliver nothing more (the owner is closing)."""
        self._closed = True
        self._queued = None
        self.pool.waitForDone()


class JobQueue(QtCore.QObject):
    """Runs every submitted job in turn off the GUI thread (none replaces another, unlike BackgroundRunner: each
    export or save must happen). ``changed(n, text)``: n jobs waiting or running, ``text`` the latest one's."""

    changed = QtCore.Signal(int, str)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.pool = QtCore.QThreadPool(self)
        self.pool.setMaxThreadCount(1)
        self._live: set = set()   # the tasks' signal objects, alive until delivery
        self._closed = False

    @property
    def pending(self) -> int:
        return len(self._live)

    def submit(self, text: str, fn: Callable[[], Any], on_done: Callable[[Any], None],
               on_failed: Callable[[str], None]) -> None:
        if self._closed:
            return
        task = _Task(fn)
        signals = task.signals
        self._live.add(signals)
        signals.done.connect(lambda r: self._finish(signals, text, on_done, r))
        signals.failed.connect(lambda m: self._finish(signals, text, on_failed, m))
        self.changed.emit(len(self._live), text)
        self.pool.start(task)

    def _finish(self, signals, text: str, callback, value) -> None:
        self._live.discard(signals)
        if self._closed:
            return
        self.changed.emit(len(self._live), text)
        after_modal(lambda: None if self._closed else callback(value))

    def wait(self, msecs: int = 120000) -> None:
        """Wait for every job and deliver its result (tests, benchmarks)."""
        deadline = QtCore.QDeadlineTimer(msecs)
        while self._live and not deadline.hasExpired():
            self.pool.waitForDone(50)
            QtCore.QCoreApplication.processEvents()

    def shutdown(self) -> None:
        """Let the running and queued jobs finish (a file being written is completed) and deliver nothing more."""
        self._closed = True
        self.pool.waitForDone()


def _give_focus_back(parent: QtWidgets.QWidget | None, focus: QtWidgets.QWidget | None) -> None:
    """After ``run_modal``'s busy dialog, which took the keyboard when it showed: the window active again and the
    focus where it was (or on the window, where the edit removed that widget), so that the key pressed next goes
    where it went before the edit (Ctrl+D, then Alt+Up moves the copy). Without a window manager to do it, closing
    the dialog left no window active."""
    import shiboken6
    window = parent.window() if parent is not None else None
    if window is None or not window.isVisible():
        return
    if QtWidgets.QApplication.activeWindow() is None:
        window.activateWindow()
    if focus is not None and shiboken6.isValid(focus) and focus.isVisible() and focus.window() is window:
        focus.setFocus(QtCore.Qt.OtherFocusReason)


def run_modal(parent: QtWidgets.QWidget, title: str, label: str, fn: Callable[[], Any], *, show_after_ms: int = 200):
    """``fn()`` on a worker thread while the window stays drawn but takes no input, as a modal save does; a busy
    progress dialog shows after ``show_after_ms``. Returns what ``fn`` returned, or raises what it raised.

    The window's events (paints, timers) go on meanwhile; mouse and key input waits until ``fn`` is done
    (``QEventLoop.ExcludeUserInputEvents``), and so do the results of background jobs (``after_modal``), so nothing
    can change what ``fn`` reads or writes."""
    global _modal_depth
    out: dict[str, Any] = {}
    loop = QtCore.QEventLoop()
    finished = _Finished()
    finished.done.connect(loop.quit)   # emitted on the worker thread: queued to this one, where the loop runs

    def work() -> None:
        try:
            out["value"] = fn()
        except BaseException as exc:  # handed to the caller on the GUI thread
            out["error"] = exc
        finally:
            finished.done.emit()

    thread = threading.Thread(target=work, name=title, daemon=True)
    focus = QtWidgets.QApplication.focusWidget()
    dialog = QtWidgets.QProgressDialog(label, None, 0, 0, parent)   # 0..0: a busy indicator, no Cancel
    dialog.setWindowTitle(title)
    dialog.setWindowModality(QtCore.Qt.WindowModal)
    dialog.setMinimumDuration(show_after_ms)
    dialog.setValue(0)    # starts its show-after timer: a bar never set shows only after Qt's default 4 s
    _modal_depth += 1
    try:
        thread.start()
        if thread.is_alive():   # a quit posted before exec() starts is delivered by it: the loop ends at once
            loop.exec(QtCore.QEventLoop.ExcludeUserInputEvents)
        thread.join()
    finally:
        _modal_depth -= 1
        if not _modal_depth and _held:
            QtCore.QTimer.singleShot(0, _release_held)   # after this call's caller has finished its edit
    shown = dialog.isVisible()
    dialog.reset()      # stops its show-after timer too
    dialog.close()
    dialog.deleteLater()
    if shown:
        _give_focus_back(parent, focus)
    if "error" in out:
        raise out["error"]
    return out.get("value")
