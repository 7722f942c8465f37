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


def test_culled_surface_draws_and_picks_the_back_of_two_sided_parts(qtbot, tmp_path):
    """Issue 20: the viewport culls the faces turned away on closed parts only; the sample face is an open mask,
    whose back is drawn by a second actor of its faces reversed: seen from behind, the mask is there. A click
    on the back of a two-sided part picks the rig's own face (the reversed copy's number mapped back)."""
    w = make_window(qtbot, tmp_path)
    vp = w.viewport
    actors = vp.plotter.renderer.actors
    assert actors["surface"].GetProperty().GetBackfaceCulling()
    assert "surface_backs" in actors and actors["surface_backs"].GetVisibility()

    def covered(img):
        return (np.abs(img.astype(int) - img[2, img.shape[1] // 2].astype(int)).max(axis=2) > 30).mean()

    front = covered(vp.picture())
    vp.plotter.camera.Azimuth(180)                    # look at the back of the face
    vp.plotter.reset_camera_clipping_range()
    assert covered(vp.picture()) > 0.5 * front > 0.05
    # a closed box (culled, no back copies) before an open square (two-sided): the square is face 6 of the
    # surface and face 0 of the backs' actor
    box = np.array([[x, y, z] for x in (3.0, 4.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    box_faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    points = np.concatenate([box, square])
    counts = np.full(7, 4)
    indices = np.concatenate([np.ravel(box_faces), 8 + np.arange(4)])
    vp.set_surface(points, counts, indices, focus=square)
    vp.plotter.camera.Azimuth(180)                    # from behind the square (-Z), the box off to the side
    vp.plotter.reset_camera_clipping_range()
    vp.render()
    x, y, _ = vp.world_to_display(np.array([0.5, 0.5, 0.0]))[0]
    hit = vp.pick(int(round(x)), int(round(y)))
    assert hit is not None and hit.face == 6 and hit.vertex in range(8, 12)
    np.testing.assert_allclose(hit.position, [0.5, 0.5, 0.0], atol=0.05)
    # the picker meets the square and its reversed copy at one depth; whichever it reports is face 6
    from widgets.scene import surface_face
    backs = vp.plotter.renderer.actors["surface_backs"].GetMapper().GetInput()
    assert backs.GetNumberOfCells() == 1 and surface_face(vp.mesh, backs, 0) == 6
    assert surface_face(vp.mesh, vp.mesh, 0) == 0


def test_blending_is_off_only_when_nothing_drawn_needs_it_and_the_picture_is_unchanged(qtbot, tmp_path, monkeypatch):
    """Issue 20: OpenGL blending (VTK turns it on for the whole frame) costs ~3 ms CPU a render on llvmpipe; the
    viewport turns it off when nothing drawn is translucent or text. The shaded face is then the same picture,
    bit for bit; with a colour map its bar's text needs blending, and it is on (without it, the glyphs' boxes
    would show: the picture would differ)."""
    import widgets.scene as scene
    from widgets.scene import GL_BLEND, ColorMap
    w = make_window(qtbot, tmp_path)
    vp = w.viewport
    ren = vp.plotter.renderer
    state = vp.plotter.ren_win.GetState()

    def picture(blending=None):
        if blending is not None:
            monkeypatch.setattr(scene, "needs_blending", lambda _ren: blending)
        try:
            return vp.picture(), state.GetEnumState(GL_BLEND)
        finally:
            monkeypatch.undo()

    shaded, blend_on = picture()
    assert not scene.needs_blending(ren) and not blend_on
    forced, forced_on = picture(blending=True)
    assert forced_on and np.array_equal(shaded, forced)

    vp.set_colormap(ColorMap(np.linspace(0.0, 1.0, len(vp.mesh.points)), title="a colour bar (mm)"))
    mapped, blend_on = picture()
    assert scene.needs_blending(ren) and blend_on
    assert np.array_equal(mapped, picture(blending=True)[0])
    assert not np.array_equal(mapped, picture(blending=False)[0])   # the bar's text does need it


def test_frame_all_frames_the_whole_model_as_posed(qtbot, tmp_path):
    """A (Frame All) frames every vertex of the surface as it is posed now, from where the camera looks: the
    sparse glTF cube (Khronos sample) opens framed on the half its shape moves, and with the shape at 1 it
    stretches out of the view; pressing A brings every vertex inside the view. It framed the rest pose of the
    moved half before and left the camera where it was."""
    from tests.conftest import DATA, require_data
    from tests.gui_helpers import open_and_wait
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, require_data(DATA / "thirdparty" / "gltf" / "singleBlendshapeCube_sparse.glb"))
    vp = w.viewport
    w.set_pose(np.ones(w.document.rig.n_shapes), "pose")
    qtbot.waitUntil(lambda: not w.redraw_pending)

    def inside() -> bool:
        xy = vp.world_to_display(vp.points())[:, :2]
        width, height = vp.plotter.window_size
        return bool(((xy >= 0) & (xy <= [width, height])).all())

    assert not inside(), "the posed cube fits the view already: the test lost its point"
    from tests.test_gui_rigger_habits import _key
    _key(qtbot, vp.canvas, QtCore.Qt.Key_A)
    qtbot.waitUntil(lambda: not w.redraw_pending)
    assert inside()
