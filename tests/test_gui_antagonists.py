"""ALGORITHMS.md §13 in the window: dragging one mouth corner on ICT FaceKit at level 3 with real mouse events leaves
no antagonist pair of the rig with both weights above 0.2 (the issue found jawLeft 0.89 with jawRight 1.0)."""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore

from model.antagonists import pair_indices, rig_antagonists, strong_pairs
from tests.gui_helpers import make_window, mouse, open_and_wait


def test_mouth_corner_drag_on_ict_keeps_antagonists_apart(qtbot, tmp_path, ict_dir):
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None
                    and len(w.segmentation.segmentation.levels) > 3, timeout=120000)
    rig, doc, c = w.document.rig, w.document, w.markers
    c.panel.level.setCurrentIndex(3)
    assert c.level == 3
    corner = int(np.argmax(np.linalg.norm(rig.deltas[rig.shape_index("mouthSmile_L"), :9409], axis=1)))
    assert c.add_marker_at(corner), c.last_message
    w.markers.mode_action.trigger()
    P0 = c.marker_positions()
    d = w.viewport.world_to_display(np.vstack([P0[0], P0[0] + [1.0, 0.0, 0.0]]))
    q, q_cm = (w.viewport.display_to_qt(x, y) for x, y, _ in d)
    px_per_cm = np.hypot(q_cm.x() - q.x(), q_cm.y() - q.y())
    start = QtCore.QPoint(round(q.x()), round(q.y()))
    # the character's left corner is on the screen's right: out (right) 1.5 cm and up 1 cm
    drag = QtCore.QPoint(round(1.5 * px_per_cm), -round(1.0 * px_per_cm))
    widget = w.viewport.canvas
    mouse(widget, "press", start)
    qtbot.waitUntil(lambda: c.drag is not None, timeout=10000)   # at once, or held until marker mode's set-up is done
    for i in range(1, 7):
        mouse(widget, "move", start + drag * i / 6)
    qtbot.waitUntil(lambda: not w.redraw_pending)
    mouse(widget, "release", start + drag)
    assert doc.is_regional and doc.region_level == 3
    moved = np.linalg.norm(c.marker_positions()[0] - P0[0])
    assert moved > 0.3, moved                                              # the corner followed the mouse (cm)
    pairs = pair_indices(rig, rig_antagonists(rig))
    W = doc.region_weights
    on = strong_pairs(W, pairs)
    assert on == [], [(rig.shape_names[i], rig.shape_names[j]) for i, j, _ in on]
