"""Issue 20: keyed playback evaluates the next frame's surface and normals on a worker thread while the current
frame is drawn (app/keyframe_controller.py ``_play_frame``). What is drawn must be the frame the clock shows, its
surface and normals exactly those evaluated on the spot; and the work must really be done ahead (else it saves
nothing)."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

from app.document import PoseState
from tests.gui_helpers import make_window

pytestmark = pytest.mark.gui


def _keyed(qtbot, tmp_path, regional: bool = False):
    """The sample rig keyed at 0, 1 and 2 s: the jaw opening and closing, or (``regional``) three random per-region
    poses of segmentation level 1, as marker drags at that level leave them: a marker-keyed animation."""
    w = make_window(qtbot, tmp_path)
    kf, rig = w.keyframes, w.document.rig
    kf.set_settings(fps=60.0)
    if regional:
        w.segmentation.wait()
        blend = w.segmentation.segmentation.levels[1].blend
        rng = np.random.default_rng(7)
        for t in (0.0, 1.0, 2.0):
            W = rng.uniform(0, 1, (blend.shape[1], rig.n_shapes))
            w.document.set_pose_state(PoseState(np.zeros(rig.n_shapes), W, blend, 1))
            kf.set_key(t)
        assert kf.blend is not None and kf.level == 1
    else:
        for t, jaw in ((0.0, 0.0), (1.0, 1.0), (2.0, 0.0)):
            pose = np.zeros(rig.n_shapes)
            pose[rig.shape_index("jawOpen")] = jaw
            w.set_pose(pose, "jaw")
            kf.set_key(t)
    kf.scrub(0.0)
    return w, kf


def _drawn_is_fresh(w, kf) -> None:
    """The viewport shows the pose at the controller's time: points and normals as evaluated now."""
    fresh = w.document.evaluate_state(kf.pose_at(kf.time))
    np.testing.assert_array_equal(w.viewport.points(), fresh)
    normals = w.viewport.normals_function()(fresh)
    np.testing.assert_array_equal(w.viewport._arrays.normals, normals)


@pytest.mark.parametrize("regional", [False, True], ids=["global", "marker-keyed"])
def test_playback_draws_frames_evaluated_ahead_and_each_is_the_clocks_frame(qtbot, tmp_path, regional):
    w, kf = _keyed(qtbot, tmp_path, regional)
    given, frames = [], []
    set_pose_state = w.document.set_pose_state
    w.document.set_pose_state = lambda state, surface=None: (given.append(surface is not None),
                                                             set_pose_state(state, surface))

    def check(frame):
        frames.append(frame)
        _drawn_is_fresh(w, kf)
        assert kf.time == pytest.approx(frame / 60.0)
    kf.playback.ticked.connect(check)      # after the frame was drawn (the window's redraw is connected first)
    kf.playback.loop = False
    kf.set_playing(True)
    qtbot.waitUntil(lambda: not kf.playing, timeout=10000)
    kf.playback.ticked.disconnect(check)
    assert len(frames) > 30 and frames[-1] == 120
    # after the first frame, the frames that follow the one before were evaluated ahead
    follows = [b == a + 1 for a, b in zip(frames, frames[1:])]
    assert sum(given[1:]) >= sum(follows) > 0


@contextlib.contextmanager
def _playing_from(w, kf, frame: int):
    """As while playing (without the timer): ``frame`` drawn, the next one being evaluated ahead."""
    kf.playback.set_length(121, 60.0)
    kf.playback._playing = True
    try:
        kf.playback.set_frame(frame)
        w.redraw_now()
        assert kf._ahead is not None and kf._ahead[0] == frame + 1
        yield
    finally:
        kf.playback._playing = False


def _show(w, kf, frame: int) -> None:
    kf.playback.set_frame(frame)
    w.redraw_now()
    assert kf.time == pytest.approx(frame / 60.0)
    _drawn_is_fresh(w, kf)


@pytest.mark.parametrize("regional", [False, True], ids=["global", "marker-keyed"])
def test_a_frame_other_than_the_one_evaluated_ahead_is_evaluated_on_the_spot(qtbot, tmp_path, regional):
    """The clock skipped a frame: the one evaluated ahead (frame + 1) is not drawn for frame + 2."""
    w, kf = _keyed(qtbot, tmp_path, regional)
    with _playing_from(w, kf, 30):
        _show(w, kf, 32)                   # 31 was due but its time passed
        _show(w, kf, 33)                   # the one evaluated ahead this time


def test_an_edit_between_frames_is_drawn_not_the_frame_evaluated_before_it(qtbot, tmp_path):
    """A key changed while the next frame was being evaluated: the frame drawn has the new key's pose."""
    w, kf = _keyed(qtbot, tmp_path)
    with _playing_from(w, kf, 59):
        pose = np.zeros(w.document.rig.n_shapes)
        pose[w.document.rig.shape_index("mouthSmile_L")] = 1.0
        w.set_pose(pose, "smile")
        kf.set_key(1.0)                    # replaces the key at frame 60's time
        _show(w, kf, 60)
        assert w.document.weights[w.document.rig.shape_index("mouthSmile_L")] == pytest.approx(1.0)


def test_a_shape_edited_between_frames_is_drawn_not_the_frame_evaluated_before_it(qtbot, tmp_path):
    """A shape muted while the next frame was being evaluated (the same weights, another rig): evaluated anew."""
    w, kf = _keyed(qtbot, tmp_path)
    with _playing_from(w, kf, 59):
        w.document.project.rig.muted.append("jawOpen")
        w.document.shape_settings_edited()
        _show(w, kf, 60)
        np.testing.assert_array_equal(w.viewport.points(), w.document.evaluate_state(kf.pose_at(0.0)))  # no jaw
