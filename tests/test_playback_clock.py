"""app.mocap_playback.TakePlayback schedules its timer by the clock (issue 20): each tick arms one shot for the
moment the next frame is due (at once when it is due already), so a 60 fps take draws every frame when drawing
takes less than a frame, draws a frame late when it fell at most ``late_frames`` (1) behind the clock, and skips to the
clock's frame when it fell further behind."""
from __future__ import annotations

import time

import pytest

import app.mocap_playback as playback
from app.mocap_playback import TakePlayback


@pytest.fixture
def clock(monkeypatch):
    now = [1000.0]
    monkeypatch.setattr(playback.time, "perf_counter", lambda: now[0])
    return now


def _playing_from_frame_0(n_frames: int = 120, rate: float = 60.0) -> tuple[TakePlayback, list[int]]:
    """A player of an ``n_frames`` take at ``rate``, started from frame 0, and the frames it shows."""
    pb = TakePlayback()
    shown: list[int] = []
    pb.frame_changed.connect(shown.append)
    pb.set_length(n_frames, rate)
    pb.set_frame(0)
    pb.play()
    return pb, shown


def test_the_timer_is_armed_for_the_next_frame_on_the_clock(qtbot, clock):
    pb, shown = _playing_from_frame_0()
    assert pb.timer.isSingleShot()
    pb._tick()                         # the first tick: the clock starts, frame 0 is shown already
    assert shown == [0] and pb.timer.remainingTime() in (16, 17)   # frame 1 is due at 16.7 ms
    clock[0] += 0.0041                 # a tick at 4.1 ms (woken early): nothing yet, armed again
    pb._tick()
    assert shown == [0] and pb.timer.remainingTime() in (13, 14)   # in 12.6 ms
    clock[0] += 0.0125                 # the tick for frame 1, at 16.6 ms (a ms early): nothing yet, armed again
    pb._tick()
    assert shown == [0] and pb.timer.remainingTime() in (0, 1)
    draw = [0.012]                     # the clock time drawing a frame takes
    pb.frame_changed.connect(lambda _f: clock.__setitem__(0, clock[0] + draw[0]))
    clock[0] += 0.0005                 # 17.1 ms: frame 1, drawn by 29.1 ms
    pb._tick()
    assert shown == [0, 1] and pb.timer.remainingTime() in (4, 5)  # frame 2 at 33.3 ms
    # a slow frame: the clock reaches frame 3 while frame 2 is drawn: frame 3 is drawn at once, late
    clock[0] = 1000.0 + 2 / 60 + 0.0002
    draw[0] = 0.02                     # drawn by 53.5 ms
    pb._tick()
    assert shown == [0, 1, 2] and pb.timer.remainingTime() == 0
    draw[0] = 0.03                     # frame 3, drawn by 83.5 ms: the clock passed frame 4 too (it is at 5)
    pb._tick()
    assert shown == [0, 1, 2, 3] and pb.timer.remainingTime() == 0
    assert pb.late_frames == 1
    draw[0] = 0.05                     # one frame behind: frame 4 is drawn, late, not skipped; drawn by 133.5 ms
    pb._tick()
    assert shown == [0, 1, 2, 3, 4] and pb.timer.remainingTime() == 0
    draw[0] = 0.0
    pb._tick()                         # three frames behind: the frame the clock is at, 8 (5 to 7 skipped)
    assert shown == [0, 1, 2, 3, 4, 8] and pb.timer.remainingTime() in (16, 17)   # frame 9 at 150 ms
    pb.pause()
    assert not pb.playing and not pb.timer.isActive()


def test_the_clock_starts_when_the_first_frame_is_shown_not_at_play(qtbot, clock):
    """A first tick 50 ms after Play (the press's own work) starts the take there: frame 1 is due a frame after
    it, and no frame is skipped to catch up with a clock started at the press."""
    pb, shown = _playing_from_frame_0()
    clock[0] += 0.05                   # three frames' time after Play
    pb._tick()
    assert shown == [0] and pb.timer.remainingTime() in (16, 17)
    for f in range(1, 4):
        clock[0] += 1 / 60 + 0.0001
        pb._tick()
    assert shown == [0, 1, 2, 3]       # on a clock started at Play: 0, 3, 4, 5
    pb.pause()
    pb.play()                          # from frame 3, a second start: the clock starts at its first tick again
    clock[0] += 0.5
    pb._tick()
    clock[0] += 1 / 60 + 0.0001
    pb._tick()
    assert shown == [0, 1, 2, 3, 4]


def test_a_take_faster_than_60_fps_draws_at_most_60_frames_a_second(qtbot, clock):
    pb = TakePlayback()
    pb.set_length(240, 120.0)
    pb.set_frame(0)
    pb.play()
    clock[0] += 0.002
    pb._tick()                         # frame 0 again: nothing to draw; the next due is 1/60 s after this tick
    assert pb.timer.remainingTime() in (16, 17)


def test_real_playback_plays_a_60_fps_take_in_order_and_ends_on_time(qtbot):
    """On the real clock and timer, with 8 ms of drawing a frame: one second of a 60 fps take shows its frames in
    order, ending on the last one a second after Play. (A frame may be skipped when the shared test machine
    wakes the event loop late; the scheduling itself is pinned on a fake clock above.)"""
    pb = TakePlayback()
    shown = []
    pb.frame_changed.connect(lambda f: (shown.append(f), time.sleep(0.008)))
    pb.set_length(61, 60.0)
    pb.loop = False
    pb.set_frame(0)
    t0 = time.perf_counter()
    pb.play()
    qtbot.waitUntil(lambda: not pb.playing, timeout=5000)
    elapsed = time.perf_counter() - t0
    assert shown == sorted(set(shown)) and shown[-1] == 60 and len(shown) >= 30
    assert 0.99 < elapsed < 1.15


def test_a_late_clock_past_the_end_still_draws_the_last_frame_as_a_tick_then_stops(qtbot, clock):
    """Without looping, a clock that passed the end while a frame near it was drawn (another process took the
    CPU) ends on the last frame, drawn as every frame is (``ticked``: the views redraw on it), then pauses."""
    pb, shown = _playing_from_frame_0(n_frames=10)
    pb.loop = False
    ticked: list[int] = []
    pb.ticked.connect(ticked.append)
    pb._tick()                          # the clock starts at frame 0
    clock[0] += 7.5 / 60
    pb._tick()                          # frame 7
    clock[0] += 5 / 60                  # frame 7 took five frames to draw: the clock is at 12, past the end (9)
    pb._tick()
    assert shown == [0, 7, 9] and ticked == [7, 9] and not pb.playing
    pb._tick()                          # nothing more
    assert shown == [0, 7, 9] and ticked == [7, 9]
