"""Remembered settings: recent files, window layout, last folders (QSettings, INI format)."""
from __future__ import annotations

from PySide6 import QtCore

MAX_RECENT = 10


def settings() -> QtCore.QSettings:
    return QtCore.QSettings(QtCore.QSettings.IniFormat, QtCore.QSettings.UserScope,
                            "BlendshapeStudio", "blendshape-studio")


def recent_files() -> list[str]:
    value = settings().value("recentFiles", [])
    if isinstance(value, str):
        value = [value]
    return [v for v in (value or []) if v]


def add_recent_file(path: str) -> list[str]:
    files = [path] + [f for f in recent_files() if f != path]
    files = files[:MAX_RECENT]
    settings().setValue("recentFiles", files)
    return files


def clear_recent_files() -> None:
    settings().setValue("recentFiles", [])
