"""Real-time playback of a take: the current frame, play / pause / step / loop on a precise timer that shows the
frame the clock is at (a frame drawn late by up to ``late_frames`` is still drawn; frames are skipped when drawing
stays slow), and a drawn-frames-per-second meter. It knows
nothing of what a frame shows: ``app.mocap_controller`` listens to ``frame_changed`` and draws it.

The timer is scheduled by the clock: each tick arms a single shot for the moment the next frame is due, at once
when drawing the last one took the whole frame (a fixed interval of int(1000 / 60) = 16 ms beat against the
take's 16.67 ms frames: every 25th tick found no new frame, and a tick the event loop delayed could skip one).
"""
from __future__ import annotations

import math
import time

from PySide6 import QtCore


class TakePlayback(QtCore.QObject):
    frame_changed = QtCore.Signal(int)       # a new frame is current: show it
    ticked = QtCore.Signal(int)              # the timer moved to this frame (after frame_changed)
    playing_changed = QtCore.Signal(bool)
    fps_measured = QtCore.Signal(float)      # frames drawn per second over the last ticks

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.n_frames = 0
        self.rate = 30.0
        self.frame = -1
        self.loop = True
        self.fps = 0.0
        self.max_rate = 60.0      # frames drawn per second at most (a faster take skips frames)
        # how many frames playback may fall behind the clock and still draw the next frame rather than skip to the
        # clock's: one slow frame (another process took the CPU) is made up by the next faster ones instead of
        # being dropped; the animation stays within this many frames of real time, more behind it skips
        self.late_frames = 1
        self.timer = QtCore.QTimer(self)
        self.timer.setTimerType(QtCore.Qt.PreciseTimer)
        self.timer.setSingleShot(True)   # armed by each tick for the next frame's time
        self.timer.timeout.connect(self._tick)
        self._playing = False
        self._start = (0.0, 0)
        self._started = False     # the clock's origin is the first tick's time (see ``_tick``)
        self._last_tick = 0.0
        self._tick_times: list[float] = []

    def set_length(self, n_frames: int, rate: float) -> None:
        """A new take (or none: 0 frames): stop, and no frame is current until ``set_frame``."""
        self.pause()
        self.n_frames, self.rate, self.frame = int(n_frames), float(rate), -1

    def set_frame(self, frame: int) -> None:
        """Make ``frame`` (clamped to the take) current; emits ``frame_changed`` when it changes."""
        if self.n_frames == 0:
            return
        frame = min(max(int(frame), 0), self.n_frames - 1)
        if frame == self.frame:
            return
        self.frame = frame
        self.frame_changed.emit(frame)

    @property
    def playing(self) -> bool:
        return self._playing

    def play(self, on: bool = True) -> None:
        if not on:
            self.pause()
            return
        if self.n_frames == 0:
            self.playing_changed.emit(False)
            return
        start = 0 if self.frame >= self.n_frames - 1 else max(self.frame, 0)
        self._start = (time.perf_counter(), start)
        self._started = False
        self._tick_times = []
        self._playing = True
        self.timer.start(0)   # the first tick shows the start frame (if it is not shown yet)
        self.playing_changed.emit(True)

    def pause(self) -> None:
        was = self._playing
        self._playing = False
        self.timer.stop()
        if was:
            self.playing_changed.emit(False)

    def toggle(self) -> None:
        self.pause() if self.playing else self.play()

    def step(self, frames: int) -> None:
        """Pause and move ``frames`` frames, clamped to the take."""
        self.pause()
        if self.n_frames:
            self.set_frame(max(self.frame, 0) + frames)

    def _tick(self) -> None:
        if not self._playing:
            return
        now = self._last_tick = time.perf_counter()
        if not self._started:
            # The animation starts when its first frame is shown, not when Play was pressed: the first tick comes
            # after the press's own work (the play button, the status; 20-60 ms for a first play in the main
            # window), and a clock started at the press began the take that far behind, catching up by dropping
            # frames (issue 20: keyed playback dropped the 2nd to 15th frames of its first play at 60 fps).
            self._start = (now, self._start[1])
            self._started = True
        t0, f0 = self._start
        target = f0 + int((now - t0) * self.rate)
        if self.rate <= self.max_rate and f0 <= self.frame < target <= self.frame + 1 + self.late_frames:
            target = self.frame + 1     # behind the clock by at most ``late_frames``: the next frame, late
        end = False
        if target >= self.n_frames:
            if self.loop:
                self._start = (now, 0)
                target = 0
            else:       # the end: its last frame drawn as every frame is (a late clock may have passed it)
                target, end = self.n_frames - 1, True
        if target != self.frame:
            self.set_frame(target)
            self.ticked.emit(target)
            self._tick_times.append(time.perf_counter())
            self._tick_times = self._tick_times[-30:]
            if len(self._tick_times) >= 2:
                dt = (self._tick_times[-1] - self._tick_times[0]) / (len(self._tick_times) - 1)
                self.fps = 1.0 / dt if dt > 0 else 0.0
                self.fps_measured.emit(self.fps)
        if end:
            self.pause()
        else:
            self._schedule()

    def _schedule(self) -> None:
        """Arm the timer for when the frame after the shown one is due: at once if the clock is there already
        (drawing took a frame: it is drawn late rather than skipped, unless the clock is more than ``late_frames``
        past it too), else
        when the clock reaches its next frame (also when the shown frame is ahead of the clock). Never sooner
        than ``max_rate`` allows after this tick's start."""
        if not self._playing:   # a listener paused
            return
        t0, f0 = self._start
        now = time.perf_counter()
        clock = f0 + int((now - t0) * self.rate)
        due = t0 + (min(self.frame, clock) + 1 - f0) / self.rate
        if self.rate > self.max_rate:   # a fast take: skip frames, no faster than max_rate (a slower one: none)
            due = max(due, self._last_tick + 1.0 / self.max_rate)
        self.timer.start(max(0, math.ceil((due - now) * 1000.0)))
