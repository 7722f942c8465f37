"""Local files and folders dropped on a window (from a file manager): the one way the main window and the Batch
Solve dialog take them."""
from __future__ import annotations

from PySide6 import QtGui


class FileDropTarget:
    """Mixin for a QWidget (listed before the Qt class): a drag of local files and folders is accepted, and their
    paths dropped go to ``files_dropped(paths)``, which the widget defines. Call ``setAcceptDrops(True)``."""

    def files_dropped(self, paths: list[str]) -> None:
        raise NotImplementedError

    def dragEnterEvent(self, event: QtGui.QDragEnterEvent) -> None:  # Qt override
        urls = event.mimeData().urls() if event.mimeData().hasUrls() else []
        if urls and all(u.isLocalFile() for u in urls):
            event.acceptProposedAction()

    def dragMoveEvent(self, event) -> None:  # Qt override
        self.dragEnterEvent(event)

    def dropEvent(self, event: QtGui.QDropEvent) -> None:  # Qt override
        paths = [u.toLocalFile() for u in event.mimeData().urls() if u.isLocalFile()]
        if paths:
            event.acceptProposedAction()
            self.files_dropped(paths)
