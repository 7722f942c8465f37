"""Keyframes: set keys of the current pose, scrub and play the interpolated animation, export it
(ALGORITHMS.md §8: keys store poses; a timeline interpolates them — ``model.keyframes.Timeline``).

A key stores the whole pose: a global weight vector, or per-region weights of one segmentation level. All
keys of a project share one form; a global key set on a regional timeline is the same vector in every region,
and a regional timeline keeps its level's partition of unity with it, so it plays back exactly after the
segmentation changes or the project is reopened. Saved in the project: ``sections['keyframes']`` (times,
interpolation, frame rate, length, level) and ``arrays['keyframes/...']`` (the key weights, the blend, and
``keyframes/keyed``, (N, K) bool, when some key keys only some shapes).
A key may key one shape (the slider's context menu, or S with shapes selected in the Graph Editor): each shape
is then a curve of its own, which the Graph Editor (widgets/graph_editor.py) shows and edits (move a key in time
and value, delete it). Setting, moving or removing a key and changing the settings are undo steps; scrubbing,
playing and jumping between keys (, and .) are not edits.
"""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from PySide6 import QtCore

from app.document import PoseState
from app.mocap_playback import TakePlayback
from app.marker_commands import SetSectionArraysCommand
from app.marker_controller import pose_at_level, same_blend
from model.atomic import write_error
from model.errors import RigInputError
from model.keyframes import Keyframe, Timeline, keyed_frames, keyed_global_weights
from model.pose import PoseEvaluator
from model.pc2 import check_room_for_pc2, write_pc2
from model.weights_csv import write_weights_csv
from model.wording import count
from widgets.graph_editor import GraphEditor
from widgets.timeline import TimelinePanel

SECTION = "keyframes"
ARRAY_KEYS = ("keyframes/weights", "keyframes/blend_data", "keyframes/blend_indices", "keyframes/blend_indptr",
              "keyframes/keyed")
DEFAULTS = {"interpolation": "smooth", "fps": 24.0, "duration": 2.0}


class _KeyEditCommand(SetSectionArraysCommand):
    """A key edit whose undo and redo also show the animation's pose at the current time again (the Graph
    Editor's moves and deletes, Set Key, Remove Key): the viewport follows the curves, as Maya and Blender
    re-evaluate. ``follow_first``: its first redo too (a key set of the pose shown leaves that pose as it is)."""

    def __init__(self, controller: "KeyframeController", *args, follow_first: bool = True) -> None:
        super().__init__(controller.document, *args)
        self.controller = controller
        self._follow = follow_first

    def redo(self) -> None:
        super().redo()
        if self._follow:
            self.controller.scrub(self.controller.time)
        self._follow = True

    def undo(self) -> None:
        super().undo()
        self.controller.scrub(self.controller.time)


class KeyframeController(QtCore.QObject):
    """The keyed animation; owns the Timeline panel (``panel``, in ``dock``, under the viewport), the Graph
    Editor (``graph``, in ``graph_dock``) and the Animation menu's Set Key (S, ``set_key_action``), Play / Pause
    (Space, ``play_action``), Remove Key, next/previous key (. and ,), and the File menu's keyed exports."""

    time_changed = QtCore.Signal(float)

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window, self.document = window, window.document
        self.panel = panel = TimelinePanel(window)
        self.dock = window.add_dock("Timeline", panel, QtCore.Qt.BottomDockWidgetArea)
        self.set_key_action = window.add_action("animation", "&Set Key", self.key_pressed, "S",
                                                "Key the current pose at the current time (only the shapes "
                                                "selected in the Graph Editor, when it is shown)")
        self.play_action = window.add_action("animation", "&Play / Pause", self.toggle_play, "Space",
                                             "Play or pause the keyed animation")
        window.add_action("animation", "&Remove Key", lambda: self.remove_key(), None,
                          "Remove the key at the current time")
        self.next_key_action = window.add_action("animation", "&Next Key", lambda: self.jump_to_key(1), ".",
                                                 "Go to the next key (of the shapes selected in the Graph Editor, "
                                                 "else of any shape)")
        self.previous_key_action = window.add_action("animation", "P&revious Key", lambda: self.jump_to_key(-1),
                                                     ",", "Go to the previous key")
        self.graph = GraphEditor(window)
        self.graph_dock = window.add_dock("Graph Editor", self.graph, QtCore.Qt.BottomDockWidgetArea)
        self.graph_dock.hide()   # on demand: the viewport keeps the room on first start
        window.add_action("animation", "&Graph Editor", self.show_graph_editor, "Ctrl+G",
                          "Show the animation's weight curves with each shape's keys (also in View ▸ Panels)")
        window.add_action("file", "Export Keyed &Weights as CSV…", lambda: self.export_csv_dialog(), None,
                          "Write the keyed animation's weights per frame as CSV: one column per shape, the global "
                          "rig's weights that best reproduce each frame's surface")
        window.add_action("file", "Export Keyed Weights per Re&gion as CSV…",
                          lambda: self.export_csv_dialog(per_region=True), None,
                          "Write a marker-keyed (regional) animation's weights per frame as CSV, one column per "
                          "shape per region (<shape>@region<r>)")
        window.add_action("file", "Export Keyed Animation as P&C2…", self.export_pc2_dialog, None,
                          "Write the keyed animation as a PC2 point cache")
        self.timeline = Timeline()
        self.blend: sp.csr_matrix | None = None
        self.level: int | None = None
        self.fps = DEFAULTS["fps"]
        self.duration = DEFAULTS["duration"]
        self.time = 0.0
        # real-time playback on the take player's clock: the frame the clock is at is shown; a frame is drawn late
        # when playback fell at most a frame behind, and skipped when it fell further (slow frames never slow the
        # animation down by more than that)
        self.playback = TakePlayback(self)
        self.playback.frame_changed.connect(self._play_frame)
        # the next playback frame's surface and normals, evaluated on a worker while this one is drawn
        self._ahead: tuple[int, PoseState, int, Future] | None = None   # frame, pose, rig version, job
        self._worker: ThreadPoolExecutor | None = None
        self.playback.ticked.connect(lambda _f: window.redraw_now())
        self.playback.playing_changed.connect(panel.set_playing)
        d = self.document
        d.rig_changed.connect(self._on_new_document)
        d.section_changed.connect(lambda name: self._load() if name == SECTION else None)
        p = panel
        p.time_changed.connect(self.scrub)
        p.play_toggled.connect(self.set_playing)
        p.set_key_requested.connect(self.key_pressed)
        p.key_step_requested.connect(self.jump_to_key)
        p.remove_key_requested.connect(self.remove_key)
        p.interpolation_changed.connect(lambda v: self.set_settings(interpolation=v))
        p.fps_changed.connect(lambda v: self.set_settings(fps=v))
        p.duration_changed.connect(lambda v: self.set_settings(duration=v))
        p.export_csv_requested.connect(lambda: self.export_csv_dialog())
        p.export_pc2_requested.connect(self.export_pc2_dialog)
        window.shapes_panel.key_shape_requested.connect(self.set_shape_key)
        g = self.graph
        g.time_requested.connect(self.scrub)
        g.key_moved.connect(self.move_shape_key)
        g.key_deleted.connect(self.remove_shape_key)
        g.selection_changed.connect(lambda _shapes: self._show_graph())
        self.graph_dock.visibilityChanged.connect(lambda on: self._show_graph() if on else None)
        if d.project is not None:
            self._load()

    # --- the project section --------------------------------------------------------------------------
    def _stored(self) -> tuple[dict | None, dict]:
        proj = self.document.project
        return proj.sections.get(SECTION), {k: proj.arrays.get(k) for k in ARRAY_KEYS}

    def _on_new_document(self) -> None:
        """Another rig or project opened: its timeline from its start (the time of the last one stayed, on a
        timeline without its keys), or where a saved project's playhead was (``app.session_state``, after this)."""
        self.time = 0.0
        self._load()

    def show_time(self, t: float) -> None:
        """Put the playhead at ``t`` (clamped to the timeline) without posing the face: a saved project's time, its
        saved pose being the one shown."""
        self.time = float(np.clip(t, 0.0, self.duration))
        self._show()

    def _load(self) -> None:
        """Rebuild the timeline from the project (after open, set key, undo, ...)."""
        sec, arrays = self._stored()
        sec = dict(DEFAULTS, **(sec or {}))
        self.fps, self.duration = float(sec["fps"]), float(sec["duration"])
        self.level = sec.get("level")
        old_blend, self.blend = self.blend, None
        keys = []
        try:
            W = arrays["keyframes/weights"]
            if sec.get("times") and W is not None:
                M = arrays["keyframes/keyed"]
                if M is not None and np.shape(M) != (len(W), np.shape(W)[-1]):
                    raise RigInputError(f"the keyed shapes are a {np.shape(M)} array for {len(W)} keys")
                keys = [Keyframe(t, w, None if M is None else M[i]) for i, (t, w) in enumerate(zip(sec["times"], W))]
            if self.level is not None and arrays["keyframes/blend_data"] is not None:
                shape = tuple(sec["blend_shape"])
                self.blend = sp.csr_matrix((arrays["keyframes/blend_data"], arrays["keyframes/blend_indices"],
                                            arrays["keyframes/blend_indptr"]), shape=shape)
                if same_blend(old_blend, self.blend):
                    self.blend = old_blend  # keep the object the document's pose refers to
            self.timeline = Timeline(keys, interpolation=sec["interpolation"])
        except (RigInputError, KeyError, ValueError, TypeError) as exc:
            self.timeline = Timeline()
            self.window.show_status(f"The project's keyframes were not loaded: {exc}", 10000)
        self.time = min(self.time, self.duration)
        self._show()

    def _snapshot(self, timeline: Timeline, blend, level, fps=None, duration=None) -> tuple[dict, dict]:
        sec = {"interpolation": timeline.interpolation, "fps": float(fps or self.fps),
               "duration": float(duration or self.duration), "level": level,
               "times": [k.time for k in timeline.keys]}
        arrays = {k: None for k in ARRAY_KEYS}
        if timeline.keys:
            arrays["keyframes/weights"] = np.stack([k.weights for k in timeline.keys])
            if any(k.keyed is not None for k in timeline.keys):
                arrays["keyframes/keyed"] = np.stack([k.mask for k in timeline.keys])
        if blend is not None:
            b = sp.csr_matrix(blend)
            sec["blend_shape"] = list(b.shape)
            arrays.update({"keyframes/blend_data": b.data, "keyframes/blend_indices": b.indices,
                           "keyframes/blend_indptr": b.indptr})
        return sec, arrays

    def _push(self, new: tuple, text: str, follow: bool | str = False) -> None:
        """One undo step to the keyframes ``new``; ``follow``: the viewport shows the animation's pose after it, its
        undo and its redo ('undo': after its undo and a later redo only, the pose shown kept when it is done)."""
        if follow:
            self.document.undo_stack.push(_KeyEditCommand(self, SECTION, self._stored(), new, text,
                                                          follow_first=follow != "undo"))
        else:
            self.document.undo_stack.push(SetSectionArraysCommand(self.document, SECTION, self._stored(), new, text))

    # --- edits ----------------------------------------------------------------------------------------
    def show_graph_editor(self) -> None:
        """Animation ▸ Graph Editor (Ctrl+G): above the timeline, a third of the window high the first time."""
        first = not self.graph_dock.isVisible() and self.graph_dock.height() < 150
        self.graph_dock.show()
        self.graph_dock.raise_()
        if first and not self.graph_dock.isFloating():
            self.window.resizeDocks([self.graph_dock], [max(240, self.window.height() // 3)], QtCore.Qt.Vertical)

    def selected_shapes(self) -> list[int]:
        """The shapes S keys alone: those selected in the Graph Editor while it is shown (else none: the pose)."""
        return self.graph.selected_shapes() if self.graph_dock.isVisible() else []

    def key_pressed(self) -> None:
        """Animation ▸ Set Key (S): the shapes selected in the Graph Editor, else the whole pose."""
        self.set_key(shapes=self.selected_shapes() or None)

    def set_key(self, time: float | None = None, shapes: list[int] | None = None) -> None:
        """Key the current pose at ``time`` (default: the current time); one undo step. ``shapes``: key only
        those shapes (their current weights), the others keep their curves."""
        t = self.time if time is None else float(time)
        state = self.document.pose_state()
        tl = self.timeline.copy()
        blend, level = self.blend, self.level
        note = ""
        if blend is None and state.is_regional:
            blend, level = state.blend, state.level
            for k in tl.keys:  # the global keys become the same vector in every region
                k.weights = np.tile(k.weights, (blend.shape[1], 1))
        if blend is not None and state.is_regional and not same_blend(state.blend, blend) \
                and state.level is not None and (level is None or state.level < level):
            # a pose of a finer level than the keys': the keys follow it to that level (a coarse region is a
            # union of fine ones, so the earlier keys keep their surface), and this key is stored exactly
            background = self.document.project.weights
            for k in tl.keys:
                k.weights = pose_at_level(PoseState(background, k.weights, blend, level), state.blend)
            note = f" (the keys moved to level {state.level}, finer than level {level})"
            blend, level = state.blend, state.level
        if blend is None:
            w = state.weights
        else:
            if state.is_regional and not same_blend(state.blend, blend):
                note = f" (on the keys' finer level {level})"
            w = pose_at_level(state, blend)
        if shapes:
            mask = np.zeros(w.shape[-1], dtype=bool)
            mask[list(shapes)] = True
            tl.set_key(t, w, mask)
            names = self.document.rig.shape_names
            what = names[shapes[0]] if len(shapes) == 1 else count(len(shapes), "shape")
        else:
            tl.set_key(t, w)
            what = "the pose"
        if t > self.duration:
            self.duration = t
        # undone, the face shows what the animation gives at this time without the key (it stayed at the key's pose)
        self._push(self._snapshot(tl, blend, level), f"Key {what} at {t:.3g} s", follow="undo")
        self.window.show_status(f"Keyed {what} at {t:.3f} s{note}.", 4000)

    def set_shape_key(self, k: int) -> None:
        """Key shape ``k`` alone at the current time (a slider's context menu)."""
        self.set_key(shapes=[int(k)])

    def move_shape_key(self, k: int, time: float, new_time: float, value: float) -> bool:
        """Move shape ``k``'s key at ``time`` to ``new_time`` with weight ``value`` (the Graph Editor's drag);
        one undo step, the viewport shows the result."""
        tl = self.timeline.copy()
        try:
            tl.move_shape_key(k, time, min(max(new_time, 0.0), self.duration), value)
        except RigInputError as exc:
            self.window.show_status(str(exc), 4000)
            return False
        name = self.document.rig.shape_names[k]
        self._push(self._snapshot(tl, self.blend, self.level), f"Move key of {name}", follow=True)
        self.window.show_status(f"Moved the key of {name} to {new_time:.3f} s, weight {value:.3g}.", 4000)
        return True

    def remove_shape_key(self, k: int, time: float) -> bool:
        """Remove shape ``k``'s key at ``time`` (the Graph Editor's Delete); one undo step."""
        tl = self.timeline.copy()
        try:
            tl.remove_shape_key(time, k)
        except RigInputError as exc:
            self.window.show_status(str(exc), 4000)
            return False
        keep = tl.keys and self.blend is not None
        name = self.document.rig.shape_names[k]
        self._push(self._snapshot(tl, self.blend if keep else None, self.level if keep else None),
                   f"Delete key of {name}", follow=True)
        self.window.show_status(f"Deleted the key of {name} at {time:.3f} s.", 4000)
        return True

    def jump_to_key(self, direction: int) -> bool:
        """Go to the next (1) or previous (-1) key: of the shapes selected in the Graph Editor, else any."""
        shapes = self.selected_shapes()
        keys = self.timeline.keys if not shapes else [k for k in self.timeline.keys
                                                       if any(k.keys_shape(s) for s in shapes)]
        T = np.array([k.time for k in keys])
        T = T[T > self.time + 1e-6] if direction > 0 else T[T < self.time - 1e-6][::-1]
        if not T.size:
            self.window.show_status("No key after this time." if direction > 0 else "No key before this time.", 3000)
            return False
        self.scrub(float(T[0]))
        return True

    def remove_key(self, time: float | None = None) -> bool:
        t = self.time if time is None else float(time)
        if self.timeline.key_at(t) is None:
            self.window.show_status(f"There is no key at {t:.3f} s.", 4000)
            return False
        tl = self.timeline.copy()
        tl.remove_key(t)
        keep = tl.keys and self.blend is not None
        self._push(self._snapshot(tl, self.blend if keep else None, self.level if keep else None),
                   f"Remove key at {t:.3g} s", follow=True)
        return True

    def set_settings(self, *, interpolation: str | None = None, fps: float | None = None,
                     duration: float | None = None) -> None:
        tl = self.timeline.copy(interpolation=interpolation)
        new = self._snapshot(tl, self.blend, self.level, fps=fps, duration=duration)
        if new[0] != self._snapshot(self.timeline, self.blend, self.level)[0]:
            self._push(new, "Timeline settings")

    # --- time -----------------------------------------------------------------------------------------
    def pose_at(self, t: float) -> PoseState:
        """The interpolated pose at time ``t`` (the timeline must have keys)."""
        w = self.timeline.evaluate(t)
        if self.blend is None:
            return PoseState(w)
        return PoseState(self.document.project.weights.copy(), w, self.blend, self.level)

    def scrub(self, t: float, evaluated: tuple[PoseState, np.ndarray, np.ndarray] | None = None) -> None:
        """Go to time ``t`` and show the interpolated pose (navigation, not an undo step). ``evaluated``: (a pose
        state, its surface, its normals) evaluated ahead (``_play_frame``), used if the state is the one at ``t``."""
        self.time = min(max(float(t), 0.0), self.duration)
        if self.timeline.keys:
            state, surface = self.pose_at(self.time), None
            if evaluated is not None and evaluated[0].equals(state):
                surface = evaluated[1]
                self.window.viewport.use_normals(surface, evaluated[2])
            self.document.set_pose_state(state, surface=surface)
        self._show()
        self.time_changed.emit(self.time)

    def _play_frame(self, frame: int) -> None:
        """Show playback frame ``frame``. While playing (a global or a marker-keyed, regional animation), the next
        frame's surface and normals are then evaluated on a worker thread, in the time the main thread waits for this
        frame's render (llvmpipe's raster threads; VTK releases the GIL): the next tick finds them ready when the
        clock asks for that frame with the same pose and rig (else they are dropped), ~1.4 ms (pose and normals) less
        on the main thread a frame. At most one evaluation runs at a time, and never beside the main thread's own (it
        is joined first); one that failed (the rig edited under it) is dropped like a stale one and the frame
        evaluated here."""
        ahead, self._ahead = self._ahead, None
        evaluated = None
        if ahead is not None and ahead[3].exception() is None:   # waits for it
            if ahead[0] == frame and ahead[2] == self.document.rig_version:   # no shape edited meanwhile
                evaluated = (ahead[1], *ahead[3].result())
        self.scrub(frame / self.fps, evaluated)
        nxt = frame + 1
        normals = self.window.viewport.normals_function()
        if self.playing and self.timeline.keys and nxt < self.playback.n_frames and normals is not None:
            state = self.pose_at(min(nxt / self.fps, self.duration))
            if self._worker is None:
                self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="keyed-playback")
            document = self.document

            def evaluate() -> tuple[np.ndarray, np.ndarray]:
                surface = document.evaluate_state(state)
                return surface, normals(surface)
            self._ahead = (nxt, state, document.rig_version, self._worker.submit(evaluate))

    def set_playing(self, on: bool) -> None:
        if on and not self.timeline.keys:
            self.window.show_status("Set a key first (S) to play an animation.", 4000)
            on = False
        pb = self.playback
        if on:
            pb.set_length(len(self.frame_times()), self.fps)
            pb.frame = int(round(self.time * self.fps))   # from where the time is (the end: from the start)
            pb.play()
        else:
            pb.pause()
        self.panel.set_playing(on)

    def toggle_play(self) -> None:
        self.set_playing(not self.playing)

    @property
    def playing(self) -> bool:
        return self.playback.playing

    def _show(self) -> None:
        self.panel.set_state(self.time, self.duration, self.fps, [k.time for k in self.timeline.keys],
                             self.timeline.interpolation)
        self._show_graph()

    def _show_graph(self) -> None:
        """The Graph Editor's curves (only while it is shown: sampling every frame is work) and its playhead."""
        g = self.graph
        if self.document.rig is not None and g.shape_names != list(self.document.rig.shape_names):
            g.set_shapes(self.document.rig.shape_names)
        if self.graph_dock.isVisible() and not self.playing:
            g.set_animation(self.timeline, self.frame_times())
        g.set_time(self.time)

    # --- export ---------------------------------------------------------------------------------------
    def frame_times(self) -> np.ndarray:
        return np.arange(int(round(self.duration * self.fps)) + 1) / self.fps

    def _require_keys(self) -> None:
        if not self.timeline.keys:
            raise RigInputError("There are no keys to export: set a key first (S).")

    def _csv_job(self, path: str | Path, per_region: bool):
        """The CSV export as a job (a closure over a snapshot of the animation, run on any thread)."""
        self._require_keys()
        rig, timeline, blend, times = self.document.rig, self.timeline, self.blend, self.frame_times()
        names, deltas = list(rig.shape_names), rig.deltas

        def job() -> int:
            if per_region and blend is not None:
                W = keyed_frames(timeline, times)
                R = W.shape[1] - 1
                cols = [f"{n}@region{r}" for r in range(R) for n in names] + names
                W = W.reshape(W.shape[0], -1)
            else:
                W, cols = keyed_global_weights(timeline, times, deltas, blend), names
            _written(path, lambda: write_weights_csv(path, W, cols, times=times))
            return len(times)
        return job

    def _pc2_job(self, path: str | Path):
        self._require_keys()
        rig, times = self.document.rig, self.frame_times()
        check_room_for_pc2(path, len(times), rig.n_vertices)
        states = [self.pose_at(t) for t in times]

        def job() -> int:
            ev = PoseEvaluator(rig, dtype=np.float64)   # its own: the GUI thread's evaluator keeps drawing
            frames = (ev.pose(s.weights if s.region_weights is None else s.region_weights, s.blend) for s in states)
            return _written(path, lambda: write_pc2(path, frames, n_points=rig.n_vertices, start_frame=0.0,
                                                    sample_rate=1.0))
        return job

    def export_csv(self, path: str | Path, per_region: bool = False) -> int:
        """Write the keyed animation's weights per frame (frame, time, one column per shape): the global rig's
        weights that best reproduce each frame's surface (a regional timeline is fitted, ``keyed_global_weights``),
        or with ``per_region`` each region's row as ``<shape>@region<r>`` then the background row under the
        shape names. Returns the number of frames (runs here; the menu runs it in the background)."""
        return self._csv_job(path, per_region)()

    def export_pc2(self, path: str | Path) -> int:
        """Write the keyed animation as a PC2 point cache (one sample per frame). Returns the frame count."""
        return self._pc2_job(path)()

    def _export_dialog(self, title: str, suffix: str, filt: str, make_job) -> None:
        def write(path: str) -> None:
            if self.window.refuses_export_over_inputs(path):   # not over the rig's own files, the project, ...
                return
            try:
                job = make_job(path)
            except RigInputError as exc:
                self.window.show_error("Could not export", str(exc))
                return
            self.window.run_in_background(f"{title}…", job,
                                          lambda n: self.window.show_status(f"Exported {n} frames to {path}", 5000),
                                          lambda message: self.window.show_error("Could not export", message))
        if self.document.project is None:
            return
        try:   # nothing to export is said at once, not after a file name was chosen
            self._require_keys()
        except RigInputError as exc:
            self.window.show_error("Could not export", str(exc))
            return
        self.window.save_dialog(title, f"{self.document.rig.name}_keys{suffix}", filt, write)

    def export_csv_dialog(self, per_region: bool = False) -> None:
        self._export_dialog("Export Keyed Weights per Region as CSV" if per_region else "Export Keyed Weights as CSV",
                            "_regions.csv" if per_region else ".csv", "CSV (*.csv)",
                            lambda path: self._csv_job(path, per_region))

    def export_pc2_dialog(self) -> None:
        self._export_dialog("Export Keyed Animation as PC2", ".pc2", "Point cache (*.pc2)", self._pc2_job)


def _written(path, write):
    """Run ``write()``; an unwritable file is one sentence naming it."""
    try:
        return write()
    except OSError as exc:
        raise write_error(path, exc) from exc
