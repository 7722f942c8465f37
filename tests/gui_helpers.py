"""Helpers for GUI tests: a main window on the sample rig with settings kept in a temp folder."""
from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets


def isolate_settings(tmp_path) -> None:
    QtCore.QSettings.setPath(QtCore.QSettings.IniFormat, QtCore.QSettings.UserScope, str(tmp_path / "settings"))


def make_window(qtbot, tmp_path, size=(1200, 800), sample: bool = True):
    """The main window at ``size``, on the bundled sample rig (``sample``) or on nothing yet."""
    from app.main_window import MainWindow
    isolate_settings(tmp_path)
    w = MainWindow()
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.resize(*size)
    w.show()
    qtbot.waitExposed(w)
    if sample:
        w.open_sample()
    QtWidgets.QApplication.processEvents()
    return w


def slider_handle_centre(slider) -> QtCore.QPoint:
    """The centre of a QSlider's handle, in the slider's coordinates."""
    opt = QtWidgets.QStyleOptionSlider()
    slider.initStyleOption(opt)
    return slider.style().subControlRect(QtWidgets.QStyle.CC_Slider, opt, QtWidgets.QStyle.SC_SliderHandle,
                                         slider).center()


def press_shape_slider(qtbot, window, row) -> tuple[QtWidgets.QSlider, QtCore.QPoint]:
    """A real press on the handle of the Shapes panel's ``row``'s slider, scrolled into view first: (the slider, where
    it was pressed); the caller moves and releases it with ``mouse``."""
    window.shapes_panel.scroll.ensureWidgetVisible(row)
    slider = row.slider
    qtbot.waitUntil(lambda: slider.isVisible() and slider.width() > 30, timeout=5000)
    QtWidgets.QApplication.processEvents()
    start = slider_handle_centre(slider)
    mouse(slider, "press", start)
    return slider, start


def sculpting_on_ict(qtbot, tmp_path, rig, drivers, brush: str = "grab", radius: float = 2.0):
    """The main window at its default size (1400x900) on ``rig`` (ICT FaceKit), segmented, authoring the corrective of
    ``drivers`` with ``brush`` at ``radius``, nothing left to draw."""
    from model.project import Project
    w = make_window(qtbot, tmp_path, size=(1400, 900), sample=False)
    w.document.set_project(Project(rig=rig.copy()), None)
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=30000)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=120000)   # its colour map drawn
    w.segmentation.wait()
    ctrl = w.correctives
    ctrl.dock.show()
    assert ctrl.start_authoring(drivers)
    ctrl.set_brush(brush)
    ctrl.panel.radius.setValue(radius)
    qtbot.waitUntil(lambda: not w.redraw_pending, timeout=30000)
    QtCore.QCoreApplication.processEvents()
    return w


def shapes_panel_alone(qtbot, tmp_path, size=(420, 700)):
    """A Shapes panel on its own, shown at ``size``, settings kept in a temp folder (no window, no rig)."""
    from widgets.shapes_panel import ShapesPanel
    isolate_settings(tmp_path)
    panel = ShapesPanel()
    qtbot.addWidget(panel)
    panel.resize(*size)
    panel.show()
    qtbot.waitExposed(panel)
    return panel


def decimation_until_stopped(on_filter, started=None) -> int:
    """Stand-in for ``widgets.lod.proxy_faces``'s work: a decimation filter handed to ``on_filter`` that "runs" until
    it is aborted (20 s at most), ``started`` set once it exists; returns its abort flag (1: stopped)."""
    import time

    import vtk
    f = vtk.vtkDecimatePro()
    on_filter(f)
    if started is not None:
        started.set()
    end = time.monotonic() + 20
    while not f.GetAbortExecute() and time.monotonic() < end:
        time.sleep(0.01)
    return f.GetAbortExecute()


def open_and_wait(qtbot, window, path, timeout=60000):
    """Open a rig or project through the window's background loader and wait until it is done."""
    window.open_path(path)
    qtbot.waitUntil(lambda: not window.is_loading, timeout=timeout)
    QtWidgets.QApplication.processEvents()


def solved_on_ict(qtbot, tmp_path, ict_dir, take_dir, timeout=180000):
    """(window, its mocap controller): the main window on ICT with the real marker take and map loaded and solved."""
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    mc = w.mocap
    assert mc.load_take(take_dir / "take.c3d") and mc.load_map(take_dir / "marker_map.json")
    with qtbot.waitSignal(mc.solved, timeout=timeout):
        mc.solve()
    return w, mc


def calls_on_gui_thread(monkeypatch, module, name: str) -> list[bool]:
    """Wrap ``module.name`` so that each call records whether it ran on the GUI (main) thread; returns that list
    (work moved off the GUI thread: the list is [False] after it ran)."""
    import threading
    calls: list[bool] = []
    original = getattr(module, name)

    def recording(*args, **kwargs):
        calls.append(threading.current_thread() is threading.main_thread())
        return original(*args, **kwargs)
    monkeypatch.setattr(module, name, recording)
    return calls


def click_shape_name(qtbot, window, name, modifier=QtCore.Qt.NoModifier) -> None:
    """Click shape ``name``'s label in the Shapes list (scrolled into view), as a user selects it; the list then
    has the keyboard focus."""
    from PySide6.QtTest import QTest
    panel = window.shapes_panel
    row = panel.row(name)
    panel.scroll.ensureWidgetVisible(row)
    QtWidgets.QApplication.processEvents()
    QTest.mouseClick(row.label, QtCore.Qt.LeftButton, modifier, row.label.rect().center())
    qtbot.waitUntil(lambda: QtWidgets.QApplication.focusWidget() is panel._rows_host, timeout=5000)


def key_on_shape_name(qtbot, window, name, key, text: str | None = None) -> None:
    """Select shape ``name`` in the Shapes list and press ``key`` (F2, Delete, ...); with ``text``, type it into the
    in-place editor the key opened (F2: a rename) and press Return."""
    from PySide6.QtTest import QTest
    click_shape_name(qtbot, window, name)
    QTest.keyClick(QtWidgets.QApplication.focusWidget(), key)
    if text is not None:
        editor = QtWidgets.QApplication.focusWidget()
        editor.selectAll()
        QTest.keyClicks(editor, text)
        QTest.keyClick(editor, QtCore.Qt.Key_Return)
    QtWidgets.QApplication.processEvents()


def mouse(widget, kind, pos, buttons=QtCore.Qt.LeftButton, button=QtCore.Qt.LeftButton):
    """Send a real mouse event (press/move/release) at widget-local ``pos`` with buttons held."""
    types = {"press": QtCore.QEvent.MouseButtonPress, "move": QtCore.QEvent.MouseMove,
             "release": QtCore.QEvent.MouseButtonRelease}
    local = QtCore.QPointF(pos)
    glob = QtCore.QPointF(widget.mapToGlobal(pos))
    held = QtCore.Qt.NoButton if kind == "release" else buttons
    ev = QtGui.QMouseEvent(types[kind], local, glob, button if kind != "move" else QtCore.Qt.NoButton,
                           held, QtCore.Qt.NoModifier)
    QtWidgets.QApplication.sendEvent(widget, ev)
    QtWidgets.QApplication.processEvents()


def drop_files(widget, paths) -> bool:
    """Drag ``paths`` over ``widget`` and drop them (real mime data with file URLs); returns whether the widget
    took the drop."""
    mime = QtCore.QMimeData()
    mime.setUrls([QtCore.QUrl.fromLocalFile(str(p)) for p in paths])
    pos = QtCore.QPoint(widget.width() // 2, widget.height() // 2)
    enter = QtGui.QDragEnterEvent(pos, QtCore.Qt.CopyAction, mime, QtCore.Qt.LeftButton, QtCore.Qt.NoModifier)
    QtWidgets.QApplication.sendEvent(widget, enter)
    if not enter.isAccepted():
        return False
    drop = QtGui.QDropEvent(QtCore.QPointF(pos), QtCore.Qt.CopyAction, mime, QtCore.Qt.LeftButton,
                            QtCore.Qt.NoModifier)
    QtWidgets.QApplication.sendEvent(widget, drop)
    QtWidgets.QApplication.processEvents()
    return drop.isAccepted()


def combo_text_shown_whole(combo: QtWidgets.QComboBox) -> bool:
    """Whether a drop-down list's current choice fits its text field (not cut at the right)."""
    opt = QtWidgets.QStyleOptionComboBox()
    combo.initStyleOption(opt)
    field = combo.style().subControlRect(QtWidgets.QStyle.CC_ComboBox, opt, QtWidgets.QStyle.SC_ComboBoxEditField,
                                         combo)
    return combo.fontMetrics().horizontalAdvance(combo.currentText()) <= field.width()


def wait_until_still(qtbot, w, quiet: float = 0.5) -> None:
    """Wait until the window is still: its segmentation shown (its colour map's render comes when it is done, later
    on a slow machine) and no render started for ``quiet`` seconds, so that the next change is the first after a
    still moment (a fixed wait could end just after a late render)."""
    import time

    import vtk
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None and not w.redraw_pending, timeout=120000)
    last = [time.monotonic()]
    window = w.viewport.plotter.ren_win
    tag = window.AddObserver(vtk.vtkCommand.StartEvent, lambda *_: last.__setitem__(0, time.monotonic()))
    try:
        qtbot.waitUntil(lambda: time.monotonic() - last[0] >= quiet and not w.redraw_pending, timeout=30000)
    finally:
        window.RemoveObserver(tag)
