"""Autosave and crash recovery with the real application (issue 17): a window is edited with real input
(a weight typed into its box, a corrective muted with the keyboard), autosaves, and is killed with
SIGKILL; the next start offers the autosave with its time, and restoring it brings the edits back."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtTest, QtWidgets

from model.correctives import Corrective, add_corrective
from model.project import Project, load_project, save_project
from model.recovery import find_recoveries, lock_path
from tests.gui_helpers import isolate_settings, make_window

pytestmark = pytest.mark.gui
REPO = Path(__file__).resolve().parents[1]
CORRECTIVE = "browInnerUp_L+browInnerUp_R"

DRIVER = r"""
import sys
from PySide6 import QtCore, QtTest, QtWidgets
QtCore.QSettings.setPath(QtCore.QSettings.IniFormat, QtCore.QSettings.UserScope, sys.argv[2])
from app import settings as app_settings
s = app_settings.settings()
s.setValue("autosave/seconds", 3600)
s.setValue("autosave/idleSeconds", 0.5)
s.sync()
from app.main_window import MainWindow
app = QtWidgets.QApplication(sys.argv[:1])
w = MainWindow()
w.confirm_discard = False
w.resize(1200, 800)
w.show()


def edit():
    if w.is_loading or w.document.path is None:
        QtCore.QTimer.singleShot(50, edit)
        return
    box = w.shapes_panel.row("jawOpen").box
    box.setFocus()
    QtTest.QTest.keyClick(box, QtCore.Qt.Key_A, QtCore.Qt.ControlModifier)
    QtTest.QTest.keyClicks(box, "0.65")
    QtTest.QTest.keyClick(box, QtCore.Qt.Key_Return)
    table = w.correctives.panel.table
    table.setFocus()
    table.setCurrentItem(table.topLevelItem(0))
    QtTest.QTest.keyClick(table.viewport(), QtCore.Qt.Key_Space)
    QtCore.QTimer.singleShot(50, report)


def report():
    a = w.autosave
    if a.runner.busy or a._dirty or a.idle.isActive() or not a.written:
        QtCore.QTimer.singleShot(50, report)
        return
    print("autosaved", w.document.weights[w.document.rig.shape_index("jawOpen")],
          [c.muted for c in w.document.rig.correctives], flush=True)


w.open_path(sys.argv[1])
QtCore.QTimer.singleShot(50, edit)
sys.exit(app.exec())
"""


@pytest.fixture()
def project_with_corrective(tmp_path, sample_rig):
    rig = sample_rig.copy()
    delta = np.zeros_like(rig.neutral)
    delta[:50, 1] = 0.05
    add_corrective(rig, Corrective(drivers=["browInnerUp_L", "browInnerUp_R"], delta=delta))
    path = tmp_path / "face.bsproj"
    save_project(Project(rig=rig), path)
    return path


def test_edits_survive_kill_minus_9_and_are_restored(qtbot, tmp_path, project_with_corrective):
    path = project_with_corrective
    env = dict(os.environ, PYTHONPATH=str(REPO), XDG_DATA_HOME=os.environ["XDG_DATA_HOME"])
    proc = subprocess.Popen([sys.executable, "-c", DRIVER, str(path), str(tmp_path / "settings-child")],
                            cwd=REPO, env=env, stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("autosaved 0.65 [True]"), line
        assert lock_path(path).exists()
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    assert load_project(path).weights.max() == 0.0           # the project file never got the edits

    # the next start
    isolate_settings(tmp_path)
    from app.main_window import MainWindow
    w = MainWindow()
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    [rec] = find_recoveries(path)
    assert "face.bsproj, autosaved" in rec.describe()

    def click_restore():
        box = w.autosave.recovery_box
        if box is None:
            QtCore.QTimer.singleShot(50, click_restore)
            return
        assert rec.saved_at.strftime("%H:%M:%S") in box.text()
        restore = next(b for b in box.buttons() if b.text() == "Restore")
        QtTest.QTest.mouseClick(restore, QtCore.Qt.LeftButton)
    QtCore.QTimer.singleShot(50, click_restore)
    assert w.autosave.offer_recovery(path)
    doc = w.document
    assert doc.path == path and doc.is_modified
    assert doc.weights[doc.rig.shape_index("jawOpen")] == pytest.approx(0.65)
    assert [c.muted for c in doc.rig.correctives] == [True]
    assert w.shapes_panel.row("jawOpen").box.value() == pytest.approx(0.65)
    # saving makes the autosave unnecessary: it is removed
    assert w.save_to(path)
    assert find_recoveries(path) == []
    assert load_project(path).rig.correctives[0].muted


def test_a_clean_quit_leaves_no_autosave(qtbot, tmp_path, project_with_corrective):
    isolate_settings(tmp_path)
    from app import settings as app_settings
    app_settings.settings().setValue("autosave/idleSeconds", 0.2)
    w = make_window(qtbot, tmp_path)
    w.open_path(project_with_corrective)
    qtbot.waitUntil(lambda: not w.is_loading and w.document.path == project_with_corrective, timeout=60000)
    w.autosave.idle.setInterval(200)
    box = w.shapes_panel.row("jawOpen").box
    box.setFocus()
    QtTest.QTest.keyClick(box, QtCore.Qt.Key_A, QtCore.Qt.ControlModifier)
    QtTest.QTest.keyClicks(box, "0.4")
    with qtbot.waitSignal(w.autosave.saved, timeout=30000):
        QtTest.QTest.keyClick(box, QtCore.Qt.Key_Return)
    w.autosave.runner.wait()
    assert len(find_recoveries(project_with_corrective)) == 1
    w.close()
    assert find_recoveries(project_with_corrective) == []
    assert not lock_path(project_with_corrective).exists()
