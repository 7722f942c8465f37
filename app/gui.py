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
    from app.loading import opens_as
    from app.main_window import MainWindow
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    app.setApplicationName("Blendshape Studio")
    app.setOrganizationName("BlendshapeStudio")
    window = MainWindow()
    install_excepthook(window)
    window.show()
    window.prepare_take_solver()
    if not window.autosave.offer_recovery(path):   # a crash left an autosave: restoring it replaces the open
        if not path or opens_as(path) != "rig":
            window.open_sample()                   # a take or a map plays on a rig: the sample until one is opened
        if path:
            window.open_path(path)
    return app.exec()


def install_excepthook(window) -> None:
    """An exception nobody caught (in a slot, a timer, a paint) becomes one sentence in a dialog and a crash
    log; the window keeps running with the rig it had (issue 17). Qt calls sys.excepthook and carries on."""
    from app.crash import describe_unexpected

    def hook(kind, exc, tb):
        if issubclass(kind, KeyboardInterrupt):
            sys.__excepthook__(kind, exc, tb)
            return
        exc.__traceback__ = tb
        window.show_error("Something went wrong", describe_unexpected(exc, "The last action"))
    sys.excepthook = hook
