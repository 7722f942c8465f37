import numpy as np
from PySide6 import QtWidgets, QtGui, QtCore
from tests.gui_helpers import isolate_settings, open_and_wait
def test_shot(qtbot, tmp_path, ict_dir):
    from app.main_window import MainWindow
    isolate_settings(tmp_path)
    w = MainWindow(); w.confirm_discard = False
    qtbot.addWidget(w); w.show(); qtbot.waitExposed(w)
    open_and_wait(qtbot, w, ict_dir)
    qtbot.wait(500)
    print("window", w.geometry(), "viewport", w.viewport.geometry(), w.isMaximized())
    img = w.grab().toImage()
    rgb = np.ascontiguousarray(w.viewport.grab_image())
    h, wd = rgb.shape[:2]
    vimg = QtGui.QImage(rgb.data, wd, h, 3*wd, QtGui.QImage.Format_RGB888)
    p = QtGui.QPainter(img)
    top_left = w.viewport.mapTo(w, QtCore.QPoint(0, 0))
    p.drawImage(QtCore.QRect(top_left, w.viewport.size()), vimg)
    p.end()
    img.save("/tmp/shots/default_ict.png")
