"""The Segmentation panel's map and separate-mesh choices reach the settings (real key presses on the combo
boxes, the panel's public settings_committed signal), and the settings they give are valid."""
from __future__ import annotations

from PySide6 import QtCore

from model.segmentation import SegmentationSettings
from widgets.segmentation_panel import MAP_CHOICES, SegmentationPanel


def test_map_and_separate_mesh_choices_commit_settings(qtbot):
    panel = SegmentationPanel()
    qtbot.addWidget(panel)
    panel.show()
    defaults = SegmentationSettings().to_dict()
    panel.set_settings(defaults)
    assert panel.map_kind.currentData() == (defaults["map_kind"], defaults["normalise"])
    assert panel.separate.currentData() == "follow"
    raw = [i for i, (k, n, _) in enumerate(MAP_CHOICES) if k == "laplacian" and not n][0]
    emitted: list[dict] = []
    panel.settings_committed.connect(emitted.append)
    panel.map_kind.setFocus()
    for _ in range(raw):
        qtbot.keyClick(panel.map_kind, QtCore.Qt.Key_Down)
    assert len(emitted) == raw  # every key press commits one undoable change
    assert emitted[-1]["map_kind"] == "laplacian" and emitted[-1]["normalise"] is False
    assert emitted[0]["map_kind"] == MAP_CHOICES[1][0] and emitted[0]["normalise"] is MAP_CHOICES[1][1]
    panel.set_settings(emitted[-1])  # the app echoes the committed settings back
    with qtbot.waitSignal(panel.settings_committed, timeout=2000) as got:
        panel.separate.setFocus()
        qtbot.keyClick(panel.separate, QtCore.Qt.Key_Down)
    assert got.args[0]["separate_meshes"] == "background"
    s = SegmentationSettings.from_dict(got.args[0])
    assert s.separate_meshes == "background" and s.map_kind == "laplacian" and s.normalise is False
    # settings coming back (undo, a project) select the matching entries
    panel.set_settings(defaults)
    assert panel.map_kind.currentData() == ("laplacian+displacement", True)
    assert panel.separate.currentData() == "follow"
