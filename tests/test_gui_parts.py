"""View ▸ Parts and View ▸ Material Colours on ICT FaceKit (app.parts_controller): a hidden part is neither drawn
nor clicked (the click goes through to what is behind it), the material colours replace the skin tone, and both
choices come back in the next session."""
from __future__ import annotations

import numpy as np
import pytest

from model.parts import rig_parts
from tests.gui_helpers import make_window, mouse, open_and_wait


@pytest.fixture
def ict_window(qtbot, tmp_path, ict_dir):
    w = make_window(qtbot, tmp_path, size=(1000, 700))
    open_and_wait(qtbot, w, ict_dir)
    return w


def _vertices_of(rig, name):
    parts = rig_parts(rig)
    return np.unique(rig.face_indices[np.repeat(parts.face_part == parts.names.index(name), rig.face_counts)])


def _click(qtbot, vp, point):
    """Click the canvas where world ``point`` is drawn; the vertex the viewport reports picked."""
    x, y, _ = vp.world_to_display(point)[0]
    at = vp.display_to_qt(x, y).toPoint()
    with qtbot.waitSignal(vp.picked, timeout=3000) as blocker:
        mouse(vp.canvas, "press", at)
        mouse(vp.canvas, "release", at)
    return blocker.args[0]


def test_a_hidden_part_is_neither_drawn_nor_clicked(qtbot, ict_window):
    w, vp = ict_window, ict_window.viewport
    rig = w.document.rig
    parts = rig_parts(rig)
    helpers = ["M_LacrimalFluid", "M_EyeBlend", "M_EyeOcclusion"]
    assert w.parts.hidden == helpers                      # the helper shells start hidden
    assert vp.shown_faces.size == rig.n_faces - sum(len(parts.faces(n)) for n in helpers)
    action = w.parts.part_actions["M_EyeLashes"]
    assert action.isChecked()
    lashes = _vertices_of(rig, "M_EyeLashes")
    # a lash vertex in front of everything else (the most forward ones), clicked: a lash vertex is picked
    front = lashes[np.argsort(-rig.neutral[lashes, 2])[:40]]
    target = next((v for v in front if _click(qtbot, vp, rig.neutral[v]) in set(lashes)), None)
    assert target is not None, "no lash vertex could be clicked"
    # a lash face comes after the hidden shells' faces: its number is still the rig's
    hit = vp.pick(*vp.world_to_display(rig.neutral[target])[0, :2].round().astype(int))
    starts = np.concatenate(([0], np.cumsum(rig.face_counts)[:-1]))
    assert hit.face in set(parts.faces("M_EyeLashes"))
    assert hit.vertex in rig.face_indices[starts[hit.face]:starts[hit.face] + rig.face_counts[hit.face]]
    before = vp.picture((640, 480))
    action.trigger()                                      # View ▸ Parts ▸ M_EyeLashes off
    assert not action.isChecked() and "M_EyeLashes" in w.parts.hidden
    assert not np.isin(parts.faces("M_EyeLashes"), vp.shown_faces).any()
    picked = _click(qtbot, vp, rig.neutral[target])
    assert picked not in set(lashes)                      # the click went through to the lid behind
    # the face picked is numbered as the rig numbers its faces (the parts drawn are a subset of them)
    hit = vp.pick(*vp.world_to_display(rig.neutral[target])[0, :2].round().astype(int))
    assert hit.vertex in rig.face_indices[starts[hit.face]:starts[hit.face] + rig.face_counts[hit.face]]
    after = vp.picture((640, 480))
    assert (np.abs(before.astype(int) - after.astype(int)).sum(axis=2) > 30).sum() > 100
    # the vertices stay and still move with the pose: the surface keeps every vertex
    assert vp.points().shape == rig.neutral.shape
    w.parts.show_all_action.trigger()
    assert w.parts.hidden == [] and vp.shown_faces is None
    for a in w.parts.part_actions.values():                # untick every part: the last one stays shown
        a.trigger()
    assert len(w.parts.hidden) == len(parts.names) - 1
    assert [n for n, a in w.parts.part_actions.items() if a.isChecked()] == [parts.names[-1]]
    assert np.array_equal(vp.shown_faces, parts.faces(parts.names[-1]))


def test_material_colours_replace_the_skin_tone_and_both_choices_are_remembered(qtbot, tmp_path, ict_window, ict_dir):
    w, vp = ict_window, ict_window.viewport
    rig = w.document.rig
    face = _vertices_of(rig, "M_Face")
    nose = face[np.argmax(rig.neutral[face, 2])]          # the tip of the nose, in front of everything

    def colour_at_nose():
        w.redraw_now()
        x, y, _ = vp.world_to_display(rig.neutral[nose])[0]
        img = vp.picture()
        h = img.shape[0]
        r, c = int(round(h - 1 - y)), int(round(x))
        return img[r - 2:r + 3, c - 2:c + 3].reshape(-1, 3).mean(axis=0)

    skin = colour_at_nose()
    assert skin[0] - skin[2] > 30                         # the application's skin tone
    assert not w.parts.colors_action.isChecked()
    w.parts.colors_action.trigger()
    grey = colour_at_nose()
    assert np.ptp(grey) < 8 and abs(grey.mean() - skin.mean()) < 80, (skin, grey)   # the MTL's grey (Kd 0.6)
    w.parts.part_actions["M_EyeLashes"].trigger()
    w.parts.part_actions["M_EyeBlend"].trigger()          # a helper shell shown again
    # the next session: the same choices on the same rig
    w.close()
    w2 = make_window(qtbot, tmp_path, size=(1000, 700))
    open_and_wait(qtbot, w2, ict_dir)
    assert w2.parts.colors_action.isChecked()
    assert w2.parts.hidden == ["M_LacrimalFluid", "M_EyeOcclusion", "M_EyeLashes"]
    assert not w2.parts.part_actions["M_EyeLashes"].isChecked() and w2.parts.part_actions["M_EyeBlend"].isChecked()


def test_a_rig_without_materials_says_so_in_the_menu(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)                      # the sample rig: one surface, no materials
    actions = w.parts.menu.actions()
    assert len(actions) == 1 and not actions[0].isEnabled() and "no materials" in actions[0].text()
    assert not w.parts.colors_action.isEnabled() and w.viewport.shown_faces is None


def test_the_hidden_back_faces_are_found_with_the_load_not_on_the_gui_thread(qtbot, tmp_path, ict_dir, monkeypatch):
    """The default view's faces whose backs no one sees (the viewport culls them) are found by the loader's thread
    with the rig (``model.rig_prep``: 0.17 s at 106k vertices, ~0.7 s at 422k, which froze the window): opening
    ICT searches no faces on the GUI thread, and the backs drawn are those a search of the drawn surface finds.
    Showing a part the default view leaves out changes the faces drawn: they are searched again, there."""
    import threading

    import solvers.mesh
    from solvers.mesh import hidden_back_faces
    from widgets.scene import _back_sides
    on_gui = []
    gui = threading.current_thread()

    def counted(*args):
        if threading.current_thread() is gui:
            on_gui.append(len(args[1]))
        return hidden_back_faces(*args)

    monkeypatch.setattr(solvers.mesh, "hidden_back_faces", counted)
    import model.rig_prep
    monkeypatch.setattr(model.rig_prep, "hidden_back_faces", counted)
    w = make_window(qtbot, tmp_path, size=(1000, 700))      # its sample face is set without the loader
    on_gui.clear()
    open_and_wait(qtbot, w, ict_dir)
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=60000)
    vp = w.viewport
    assert on_gui == [] and w.parts.hidden                 # the helper shells start hidden: the default view
    counts, indices = vp.mesh._faces
    fresh = np.flatnonzero(~hidden_back_faces(vp.points(), counts, indices))
    backs = _back_sides(vp.mesh)[1]
    assert backs is not None and np.array_equal(backs, fresh)
    assert 0 < backs.size < len(counts) / 2                # the open sheets keep their backs, the closed parts not
    w.parts.part_actions[w.parts.hidden[0]].trigger()      # a helper shell shown: other faces drawn
    assert len(on_gui) == 1 and on_gui[0] == len(vp.mesh._faces[0])
