"""The viewport's gesture API for tools (widgets/viewport.py), with real mouse events on the sample rig: a tool
that takes a press gets the drag and the release with the picked surface point and the view-plane motion, the
camera stays; without the tool the same press and release is a click that emits ``picked``."""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore

from tests.gui_helpers import make_window, mouse
from widgets.viewport import ViewportTool


class _Recorder(ViewportTool):
    """Takes every left press and records what the viewport hands it."""

    def __init__(self) -> None:
        self.events: list[tuple[str, object]] = []

    def press(self, g) -> bool:
        self.events.append(("press", g.point))
        return g.button == QtCore.Qt.LeftButton

    def drag(self, g) -> None:
        self.events.append(("drag", g.motion.copy()))

    def release(self, g) -> None:
        self.events.append(("release", g.motion.copy()))


def test_a_tool_gets_the_picked_point_and_the_view_plane_motion_and_the_camera_stays(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    vp, surface = w.viewport, w.document.surface().astype(np.float64)
    v = int(np.argmax(surface[:, 2]))                   # the nose tip: the front-most vertex
    xd, yd, _ = vp.world_to_display(surface[v])[0]
    start = vp.display_to_qt(xd, yd)
    tool = _Recorder()
    vp.push_tool(tool)
    cam = vp.camera_frame()
    step = QtCore.QPointF(30, -20)                      # right and up on screen (logical pixels)
    mouse(vp.canvas, "press", start)
    mouse(vp.canvas, "move", start + step / 2)
    mouse(vp.canvas, "move", start + step)
    mouse(vp.canvas, "release", start + step)
    assert [kind for kind, _ in tool.events] == ["press", "drag", "drag", "release"]
    hit = tool.events[0][1]
    assert hit is not None and np.linalg.norm(surface[hit.vertex] - surface[v]) < 0.5   # cm, beside the nose tip
    np.testing.assert_allclose(vp.world_to_display(hit.position)[0, :2], (xd, yd), atol=1.5)
    np.testing.assert_array_equal(vp.camera_frame().position, cam.position)           # the camera stayed
    half, motion = tool.events[1][1], tool.events[3][1]
    assert np.linalg.norm(motion) > 0
    assert abs(motion @ cam.forward) < 1e-6 * np.linalg.norm(motion)                  # in the view plane
    assert motion @ cam.right > 0 and motion @ cam.up > 0                              # right and up
    np.testing.assert_allclose(half, motion / 2, atol=0.02 * np.linalg.norm(motion))
    # The surface point moved by the motion is drawn where the mouse went (the press pixel is rounded).
    ratio = vp.pixel_ratio()
    press_px = np.array(vp.qt_to_display(start.x(), start.y()))
    release_px = np.array(vp.qt_to_display((start + step).x(), (start + step).y()))
    moved = vp.world_to_display(hit.position + motion)[0, :2]
    np.testing.assert_allclose(moved - vp.world_to_display(hit.position)[0, :2], release_px - press_px,
                               atol=0.5 * ratio)

    # Without the tool the same press and release is a click on the surface.
    vp.remove_tool(tool)
    with qtbot.waitSignal(vp.picked, timeout=2000) as blocker:
        mouse(vp.canvas, "press", start)
        mouse(vp.canvas, "release", start)
    assert blocker.args[0] == hit.vertex
    assert len(tool.events) == 4                        # the removed tool saw nothing
