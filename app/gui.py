"""GUI entry point: ``blendshape-studio [PATH]``."""
from __future__ import annotations

import sys


def run_gui(path: str | None = None) -> int:
    from PySide6 import QtWidgets
    from app.main_window import MainWindow
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    app.setApplicationName("Blendshape Studio")
    app.setOrganizationName("BlendshapeStudio")
    window = MainWindow()
    window.show()
    if path:
        window.open_path(path)
    else:
        window.open_sample()
    return app.exec()
