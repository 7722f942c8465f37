"""Opening rigs and projects off the GUI thread, with progress."""
from __future__ import annotations

from pathlib import Path

from PySide6 import QtCore

from model.errors import RigInputError
from model.project import Project, load_project
from model.readers import load_rig


def open_project_or_rig(path: str | Path, progress=None) -> Project:
    """A Project from a .bsproj, or a new Project around a rig read from a folder/glTF/OBJ."""
    path = Path(path)
    if path.suffix.lower() == ".bsproj":
        return load_project(path)
    return Project(rig=load_rig(path, progress=progress))


class LoadWorker(QtCore.QThread):
    """Loads in a thread; the GUI stays responsive and shows progress."""

    progress = QtCore.Signal(int, int, str)
    loaded = QtCore.Signal(object)   # Project
    failed = QtCore.Signal(str)

    def __init__(self, path: str | Path, parent=None) -> None:
        super().__init__(parent)
        self.path = Path(path)

    def run(self) -> None:
        try:
            project = open_project_or_rig(self.path, progress=lambda d, t, w: self.progress.emit(d, t, w))
        except RigInputError as exc:
            self.failed.emit(str(exc))
        except MemoryError:
            self.failed.emit(f"{self.path}: not enough memory to open it.")
        except Exception as exc:  # an unexpected failure still must not take the open rig down
            self.failed.emit(f"{self.path}: could not be opened ({type(exc).__name__}: {exc}).")
        else:
            self.loaded.emit(project)
