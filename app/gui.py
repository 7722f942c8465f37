"""GUI entry point: ``blendshape-studio [PATH]``."""
from __future__ import annotations

import os
import sys


def run_gui(path: str | None = None) -> int:
    # The 3D views are native X11 windows that VTK renders into (widgets/native_plotter.py): in a Wayland
    # session, run Qt through XWayland unless the user chose a platform.
    if os.environ.get("WAYLAND_DISPLAY") and os.environ.get("DISPLAY"):
        os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
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
