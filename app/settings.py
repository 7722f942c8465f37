"""Remembered settings: recent files, window layout, last folders, tool options (QSettings, INI format)."""
from __future__ import annotations

import json
from pathlib import Path

from PySide6 import QtCore, QtWidgets

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


def start_folder(key: str) -> str:
    """Where an open-file dialog for ``key``'s kind of file starts: the folder such a file last came from (this
    session or an earlier one), else the last folder a rig or project was opened from, else the home folder -- not
    the folder the program was started in, where a dialog given no folder opens."""
    s = settings()
    for folder in (s.value(key, ""), s.value("lastFolder", "")):
        if folder and QtCore.QDir(str(folder)).exists():
            return str(folder)
    return QtCore.QDir.homePath()


def open_file(parent, key: str, title: str, file_filter: str) -> str:
    """Ask for one file to open, starting in ``start_folder(key)``; remembers its folder. "" when cancelled."""
    path, _ = QtWidgets.QFileDialog.getOpenFileName(parent, title, start_folder(key), file_filter)
    if path:
        settings().setValue(key, QtCore.QFileInfo(path).absolutePath())
    return path


MAX_TAKE_RATES = 200   # files whose frame rate is remembered (the last given)


def _take_rates() -> dict:
    try:
        value = json.loads(str(settings().value("mocap/takeRates", "{}")))
    except ValueError:
        return {}
    return value if isinstance(value, dict) else {}


def take_rate(path) -> float | None:
    """The frame rate last given in the Mocap panel for the take file ``path`` (one whose file gives none), or None:
    none given, or one that is no frame rate (``model.take_data.given_rate``)."""
    from model.errors import RigInputError
    from model.take_data import given_rate
    rate = _take_rates().get(str(Path(path).resolve()))
    try:
        return given_rate(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) else None
    except RigInputError:
        return None


def remember_take_rate(path, rate: float) -> None:
    """Remember ``rate`` for the take file ``path`` (the last ``MAX_TAKE_RATES`` files)."""
    key = str(Path(path).resolve())
    rates = {k: v for k, v in _take_rates().items() if k != key}
    rates[key] = float(rate)
    settings().setValue("mocap/takeRates", json.dumps(dict(list(rates.items())[-MAX_TAKE_RATES:])))


def _combo_value(combo: QtWidgets.QComboBox):
    data = combo.currentData()
    return combo.currentText() if data is None else data


def remember(widget: QtWidgets.QWidget, key: str) -> None:
    """Bring back the value ``widget`` had in the last session (saved under ``key``) and save every change.

    For a QComboBox (its item data, else its text), a QSpinBox or QDoubleSpinBox (its value, clamped to its
    range), a QCheckBox or another checkable button (whether it is checked) and a QLineEdit (its text). A saved
    value that no longer fits (an item gone) is ignored. The widget's signals are blocked while it is restored,
    so start-up triggers no work; a widget that is not one of those raises.
    """
    saved = settings().value(key)
    widget.blockSignals(True)
    try:
        if isinstance(widget, QtWidgets.QComboBox):
            if saved is not None:
                i = widget.findData(saved)
                i = widget.findText(str(saved)) if i < 0 else i
                if i >= 0:
                    widget.setCurrentIndex(i)
            widget.currentIndexChanged.connect(lambda _=0: settings().setValue(key, _combo_value(widget)))
        elif isinstance(widget, (QtWidgets.QSpinBox, QtWidgets.QDoubleSpinBox)):
            if saved is not None:
                try:
                    value = float(saved)
                except (TypeError, ValueError):
                    value = None
                if value is not None:
                    widget.setValue(int(round(value)) if isinstance(widget, QtWidgets.QSpinBox) else value)
            widget.valueChanged.connect(lambda v: settings().setValue(key, v))
        elif isinstance(widget, QtWidgets.QAbstractButton) and widget.isCheckable():
            if saved is not None:
                widget.setChecked(str(saved).lower() in ("true", "1"))
            widget.toggled.connect(lambda on: settings().setValue(key, bool(on)))
        elif isinstance(widget, QtWidgets.QLineEdit):
            if isinstance(saved, str):
                widget.setText(saved)
            widget.textChanged.connect(lambda text: settings().setValue(key, text))
        else:
            raise TypeError(f"Cannot remember a {type(widget).__name__}.")
    finally:
        widget.blockSignals(False)
