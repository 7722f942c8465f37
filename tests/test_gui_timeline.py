"""The timeline panel redraws only what changed during playback (issue 20: keyed playback at 60 fps), and what
is on screen is then what a full repaint shows."""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from widgets.timeline import TimelinePanel


def _on_screen(widget) -> np.ndarray:
    """The widget's pixels as the screen shows them (not a fresh paint, as ``QWidget.grab`` would be)."""
    img = widget.screen().grabWindow(widget.winId()).toImage().convertToFormat(QtGui.QImage.Format_RGB888)
    return np.frombuffer(img.constBits(), np.uint8).reshape(img.height(), img.bytesPerLine())[:, :img.width() * 3] \
        .reshape(img.height(), img.width(), 3).copy()


class _Paints(QtCore.QObject):
    def __init__(self):
        super().__init__()
        self.widgets: list = []

    def eventFilter(self, obj, event):
        if event.type() == QtCore.QEvent.Paint:
            self.widgets.append((obj, event.region().boundingRect()))
        return False


def test_playhead_moves_with_only_its_columns_repainted(qtbot):
    panel = TimelinePanel()
    qtbot.addWidget(panel)
    panel.resize(1600, 44)
    panel.show()
    qtbot.waitExposed(panel)
    keys = [0.0, 1.0, 2.0]
    panel.set_state(0.25, 2.0, 60.0, keys, "smooth")
    qtbot.wait(50)
    ruler = panel.ruler
    assert ruler.width() > 300
    paints = _Paints()
    QtWidgets.QApplication.instance().installEventFilter(paints)
    try:
        panel.set_state(1.5, 2.0, 60.0, keys, "smooth")          # a playback frame: only the time moves
        qtbot.wait(50)
    finally:
        QtWidgets.QApplication.instance().removeEventFilter(paints)
    painted = {type(obj).__name__ for obj, _ in paints.widgets}
    assert not painted & {"QDoubleSpinBox", "QLineEdit", "QComboBox"}, painted   # unchanged values: not redrawn
    # the ruler and the time label are opaque: nothing beneath them (the panel, a dock, the window) is painted
    assert panel not in {obj for obj, _ in paints.widgets}, painted
    label = panel.time_label
    label_shown = _on_screen(label)
    label.repaint()
    qtbot.wait(50)
    np.testing.assert_array_equal(label_shown, _on_screen(label))   # its new text as a full repaint draws it
    ruler_rects = [r for obj, r in paints.widgets if obj is ruler]
    assert ruler_rects and all(r.width() < ruler.width() for r in ruler_rects)   # not the whole ruler
    shown = _on_screen(ruler)
    ruler.repaint()                                             # what a full repaint draws
    qtbot.wait(50)
    np.testing.assert_array_equal(shown, _on_screen(ruler))
    red = (shown[:, :, 0] > 200) & (shown[:, :, 1] < 120)      # the playhead's red line
    columns = np.flatnonzero(red.sum(axis=0) > ruler.height() // 2)
    assert columns.size and abs(columns.mean() - ruler.x_of(1.5)) < 2
    assert abs(columns.mean() - ruler.x_of(0.25)) > 50          # gone from where it was
    # a changed setting still shows, and repaints the whole ruler (its ticks move)
    panel.set_state(1.5, 4.0, 30.0, keys, "linear")
    assert panel.fps.value() == 30.0 and panel.duration.value() == 4.0 and panel.interp.currentData() == "linear"
    assert ruler.duration == 4.0 and ruler.fps == 30.0


def test_ruler_draws_itself_anew_for_a_new_size_and_new_settings(qtbot):
    """The ruler draws its ticks, times and keys once and copies them for each playback frame; after a resize or
    new settings it must show what a new ruler of that size and those settings shows."""
    def new_panel() -> TimelinePanel:
        panel = TimelinePanel()
        qtbot.addWidget(panel)
        panel.show()
        qtbot.waitExposed(panel)
        return panel

    def shown(panel: TimelinePanel, width: int, duration: float) -> np.ndarray:
        panel.resize(width, 44)
        panel.set_state(0.5, duration, 24.0, [1.0], "smooth")
        qtbot.waitUntil(lambda: panel.width() == width)
        panel.layout().activate()   # the ruler takes its share of the new width now, not on a later turn
        qtbot.wait(50)
        return _on_screen(panel.ruler)

    def fresh(width: int, duration: float) -> np.ndarray:
        panel = new_panel()
        image = shown(panel, width, duration)
        panel.hide()                # the screen's pixels are grabbed: it must not cover the panel under test
        qtbot.wait(50)
        return image

    panel = new_panel()
    wide = shown(panel, 1600, 2.0)
    assert panel.ruler.width() > 600
    narrow = shown(panel, 1250, 2.0)                           # narrower: every tick moves left
    assert narrow.shape[1] < wide.shape[1] - 300
    np.testing.assert_array_equal(narrow, fresh(1250, 2.0))
    longer = shown(panel, 1250, 4.0)                           # twice as long: 1 s is half as far along
    assert not np.array_equal(longer, narrow)
    np.testing.assert_array_equal(longer, fresh(1250, 4.0))


def test_the_last_time_on_the_ruler_is_shown_whole(qtbot):
    """Each second's time is written right of its tick; the last one ran past the ruler's end ("2s" showed as
    "2"): it is written left of its tick. Nothing is drawn right of the last tick, and its label is there."""
    panel = TimelinePanel()
    qtbot.addWidget(panel)
    panel.resize(1600, 44)
    panel.show()
    qtbot.waitExposed(panel)
    panel.set_state(0.5, 2.0, 24.0, [], "smooth")
    qtbot.wait(50)
    ruler = panel.ruler
    assert ruler.width() > 600
    image = ruler.grab().toImage().convertToFormat(QtGui.QImage.Format_RGB888)
    pixels = np.frombuffer(image.constBits(), np.uint8).reshape(image.height(), image.bytesPerLine())[
        :, :image.width() * 3].reshape(image.height(), image.width(), 3).astype(int)
    text_rows = pixels[:14]                                   # the times, above the ticks
    background = text_rows[0, 0]
    drawn = np.abs(text_rows - background).sum(axis=2) > 60
    end = int(ruler.x_of(2.0))
    width = ruler.fontMetrics().horizontalAdvance("2s")
    assert not drawn[:, end + 2:].any()                       # nothing right of the last tick but its line
    assert drawn[:, end - 2 - width:end - 1].sum() > 10       # "2s", left of it


def test_closing_the_graph_editor_gives_its_height_back_to_the_viewport(qtbot, tmp_path):
    """The Graph Editor (and the Mocap Views, which share its place) sits above the timeline: closed, the height
    it had went to the timeline, a quarter of the window of empty panel with one row of controls in its middle, and
    the face stayed small."""
    from tests.gui_helpers import make_window
    w = make_window(qtbot, tmp_path, size=(1400, 900))
    timeline = w.keyframes.dock
    viewport_before = w.viewport.height()
    graph_action = next(a for a in w.findChildren(QtGui.QAction) if a.text() == "&Graph Editor")
    graph_action.trigger()                                       # Animation ▸ Graph Editor (Ctrl+G)
    qtbot.waitUntil(lambda: w.keyframes.graph_dock.isVisible())
    assert w.viewport.height() < viewport_before - 100
    w.keyframes.graph_dock.toggleViewAction().trigger()          # View ▸ Panels ▸ Graph Editor: closed
    qtbot.waitUntil(lambda: not w.keyframes.graph_dock.isVisible())
    QtWidgets.QApplication.processEvents()
    assert timeline.height() < 2 * w.keyframes.panel.sizeHint().height() + 30
    assert w.viewport.height() >= viewport_before - 5


def test_another_rig_opens_at_the_start_of_its_timeline(qtbot, tmp_path):
    """The time of the last rig's animation stayed when another rig was opened ("1.000 s · frame 24" on a timeline
    without any key); it starts at 0 s, and a saved project where its playhead was, as a scene opens in Maya."""
    from tests.gui_helpers import make_window, open_and_wait
    w = make_window(qtbot, tmp_path)
    kf = w.keyframes
    kf.set_key(0.0)
    ruler = kf.panel.ruler
    qtbot.mouseClick(ruler, QtCore.Qt.LeftButton, pos=QtCore.QPoint(int(ruler.x_of(1.0)), ruler.height() // 2))
    assert kf.time == 1.0
    project = tmp_path / "keys.bsproj"
    assert w.save_to(project)
    w.open_sample()
    QtWidgets.QApplication.processEvents()
    assert kf.time == 0.0 and kf.panel.time_label.text().startswith("0.000 s")
    open_and_wait(qtbot, w, project)                 # a saved project: where its playhead was
    assert kf.time == 1.0 and kf.panel.time_label.text().startswith("1.000 s")
