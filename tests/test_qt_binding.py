"""The Qt binding the application runs on keeps Python's objects alive: PySide6 6.12.0's ``Signal.emit()`` returns
``True`` without taking a reference to it, so every emit from Python drops one of ``True``'s references. The
application emits a few signals a frame; after ~11,000 emits (about 90 s of keyed playback on ICT FaceKit) ``True``'s
count reaches zero and Python aborts with "Fatal Python error: bool_dealloc", taking the session with it.
pyproject.toml keeps PySide6 below 6.12; this test tells whether a binding is safe to allow."""
from __future__ import annotations

import sys

from PySide6 import QtCore


class _Emitter(QtCore.QObject):
    plain = QtCore.Signal()
    number = QtCore.Signal(int)


def test_emitting_signals_from_python_keeps_true_and_false_alive(qtbot):
    emitter = _Emitter()
    received = []
    emitter.number.connect(received.append)
    emitter.plain.connect(lambda: None)
    before = (sys.getrefcount(True), sys.getrefcount(False), sys.getrefcount(None))
    for i in range(250):      # few enough that a leaking binding fails here instead of aborting the run
        emitter.plain.emit()
        emitter.number.emit(i)
    after = (sys.getrefcount(True), sys.getrefcount(False), sys.getrefcount(None))
    assert len(received) == 250
    # 500 emits: a binding that drops a reference per emit loses hundreds; a sound one a handful at most
    assert all(abs(a - b) < 20 for a, b in zip(after, before)), f"references lost: {before} -> {after}"
