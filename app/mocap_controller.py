"""Motion capture in the GUI: the Mocap panel and the Mocap Views dock around a ``model.take_workspace.TakeWorkspace``
(take, marker map, solve, report; Qt-free, shared with the command line). The solve and the filling of the
per-frame display arrays run on a background runner (``app.background``); ``app.mocap_playback.TakePlayback``
plays the take; the exports are ``model.take_exports``. Two linked views show the projection with the markers
and the dense result coloured by residual. Weight takes (a Live Link Face CSV, a weights CSV) play directly on the rig
in the main viewport. ``install(window)`` adds the panel and the dock to a MainWindow (ALGORITHMS.md §4, §5, §7).
"""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app import settings as app_settings
from app.background import BackgroundRunner
from app.mocap_frames import FrameCache, captured_area_faces
from app.mocap_playback import TakePlayback
from model.errors import RigInputError
from model.marker_map import load_marker_map
from model.rig import unit_scale
from model.wording import count
from model.pc2 import check_room_for_pc2
from model.take_exports import export_pc2, export_report, export_weights_csv, take_surfaces
from model.take_workspace import TakeWorkspace, solver_options
from model.takes import MarkerTake, WeightTake
from solvers.normals import VertexNormals, compact_faces
from widgets.curve_plot import CurvePlot
from widgets.mocap_panel import MocapPanel
from widgets.side_by_side import SideBySideView

# How long a paused scrub waits for the fill to reach the frame (computing nothing on the GUI thread) before the views
# show the nearest ready frame: on ICT FaceKit a block of frames is ~15 ms, so a scrub shows its own frame at once.
SCRUB_WAIT = 0.1

TAKE_FILTER = "Takes (*.c3d *.trc *.csv);;C3D (*.c3d);;TRC (*.trc);;CSV / Live Link Face (*.csv)"


def solve_progress_text(done: int, total: int, what: str, n_frames: int) -> str:
    """The solve's progress in the take's frames: a two-pass solve reports 2 x frames steps ("frame 169/716" on a
    358-frame take); it is said as the pass and the frame within it."""
    if what != "solving" or n_frames <= 0 or total <= n_frames:
        return f"{what} (frame {min(done, total)}/{total})" if what == "solving" else f"{what}…"
    passes = max(1, round(total / n_frames))
    k = min((max(done, 1) - 1) // n_frames, passes - 1)
    frame = min(done - k * n_frames, n_frames)
    name = ("forward", "backward")[k] if passes == 2 else f"{k + 1} of {passes}"
    return f"{name} pass, frame {frame}/{n_frames}"


class _ProgressRelay(QtCore.QObject):
    progress = QtCore.Signal(int, int, str)  # emitted on the worker thread, delivered on the GUI thread
    filled = QtCore.Signal(object)           # the frame cache it was filling (a block of its frames is ready)


class MocapController(QtCore.QObject):
    solved = QtCore.Signal()          # a solve finished and is shown
    solve_failed = QtCore.Signal(str)
    map_found = QtCore.Signal()       # Auto Map's map arrived and is used
    frame_shown = QtCore.Signal(int)

    def __init__(self, window, panel: MocapPanel, views: SideBySideView, weight_plot: CurvePlot,
                 error_plot: CurvePlot, parent=None) -> None:
        super().__init__(parent or window)
        self.window, self.document = window, window.document
        self.panel, self.views = panel, views
        self.weight_plot, self.error_plot = weight_plot, error_plot
        self.workspace = TakeWorkspace(self.document.rig)
        self.cache: FrameCache | None = None
        self.runner = BackgroundRunner(self)     # the solve
        self.playback = TakePlayback(self)
        self._solving = False
        self._shut_down = False
        self._views_split = False  # the Mocap Views splitter got its first layout (saved on shutdown)
        self._relay = _ProgressRelay(self)
        self._relay.progress.connect(self._on_progress)
        self._relay.filled.connect(self._on_filled)
        self._waiting: int | None = None     # the frame the views wait for while they show the nearest ready one
        self._said_before_wait = ""          # the panel's status then, said again once the frame is shown
        self.views_frame: int | None = None  # the take frame the views show (another while ``_waiting``)
        self._cancel = threading.Event()
        self._progress: QtWidgets.QProgressDialog | None = None
        self._solve_frames = 0   # the frames of the take being solved (the progress is said in them)
        self._fill_stop = threading.Event()
        self._fill_thread: threading.Thread | None = None   # fills the frame cache, following the playhead
        pb = self.playback
        pb.frame_changed.connect(self._show_frame)
        pb.ticked.connect(self._on_tick)
        pb.playing_changed.connect(panel.set_playing)
        pb.playing_changed.connect(lambda _on: self._show_waited_frame())
        pb.fps_measured.connect(lambda fps: panel.fps_label.setText(f"{fps:.0f} fps drawn · take {pb.rate:g} fps"))
        p = panel
        p.load_take_requested.connect(self.load_take_dialog)
        p.load_map_requested.connect(self.load_map_dialog)
        p.auto_map_requested.connect(self.auto_map)
        p.solve_requested.connect(self.solve)
        p.export_weights_requested.connect(lambda: self._export_dialog("Export Weights CSV", "CSV (*.csv)",
                                                                       "_weights.csv", self.export_weights_csv))
        p.export_pc2_requested.connect(lambda: self._export_dialog("Export PC2 Point Cache", "PC2 (*.pc2)",
                                                                   ".pc2", self.export_pc2))
        p.export_report_requested.connect(lambda: self._export_dialog("Export Solve Report", "JSON (*.json)",
                                                                      "_report.json", self.export_report))
        p.frame_requested.connect(self.set_frame)
        p.neutral_frames_requested.connect(self.use_neutral_frames)
        p.rate_requested.connect(self.set_take_rate)
        from app.marker_map_editor import MarkerMapEditor
        self.map_editor = MarkerMapEditor(window, self)   # the map shown on the rig, its points dragged
        p.map_shown.connect(self.map_editor.show)
        p.save_map_requested.connect(self.save_map_dialog)
        p.play_toggled.connect(self.play)
        p.curves_changed.connect(self._update_weight_curves)
        p.loop_check.toggled.connect(lambda on: setattr(pb, "loop", on))
        pb.loop = p.loop_check.isChecked()
        weight_plot.frame_requested.connect(self.set_frame)
        error_plot.frame_requested.connect(self.set_frame)
        self.document.rig_changed.connect(self._on_rig_change)
        self.document.shapes_changed.connect(self._on_shapes_change)
        self._shape_names: list[str] | None = None    # the shape list the take and solve line up with
        self._sync_panel()

    # --- state ------------------------------------------------------------------------------------
    @property
    def rig(self):
        return self.document.rig

    @property
    def take(self) -> MarkerTake | WeightTake | None:
        return self.workspace.take

    @property
    def marker_map(self):
        return self.workspace.marker_map

    @property
    def solution(self):
        return self.workspace.solution

    @property
    def n_frames(self) -> int:
        return self.workspace.n_frames

    @property
    def rate(self) -> float:
        return self.workspace.rate

    @property
    def frame(self) -> int:
        return self.playback.frame

    @property
    def playing(self) -> bool:
        return self.playback.playing

    def _sync_panel(self) -> None:
        playable = self.n_frames > 0
        self.panel.set_marker_mode(isinstance(self.take, MarkerTake), solved=playable)
        self.panel.set_weights_exportable(playable)
        self.panel.play_button.setEnabled(playable)
        self.panel.slider.setEnabled(playable)

    def _error(self, title: str, message: str) -> None:
        self.window.show_error(title, message)
        self.panel.set_status(message)

    # --- loading ----------------------------------------------------------------------------------
    def load_take_dialog(self) -> None:
        path = app_settings.open_file(self.window, "mocap/takeFolder", "Load Take", TAKE_FILTER)
        if path:
            self.load_take(path)

    def load_take(self, path: str | Path, rate: float | None = None) -> bool:
        """Open a take; on failure keep whatever was loaded and say why. ``rate``: the frame rate of a take whose
        file gives none (None: the rate last given for this file, ``app.settings.take_rate``, else the reader's
        assumed one); remembered for the file."""
        ws = self.workspace
        try:
            take = ws.load_take(path, rate)
            kept = app_settings.take_rate(path) if rate is None and not take.rate_from_file else None
            if kept is not None and kept != take.rate:
                take = ws.load_take(path, kept)
        except RigInputError as exc:
            self._error("Could not load the take", str(exc))
            return False
        if rate is not None and not take.rate_from_file:
            app_settings.remember_take_rate(path, take.rate)
        self._drop_solution()
        path = Path(path)
        self.panel.set_take_rate(None if take.rate_from_file else take.rate)
        if isinstance(take, MarkerTake):
            self.panel.take_label.setText(f"{path.name}: {take.n_frames} frames at {take.rate:g} fps, "
                                          f"{take.n_markers} markers ({take.units}), "
                                          f"{int(take.missing.sum())} missing samples")
            if ws.marker_map is not None:
                self._describe_map(ws.marker_map)
            self._say_next_step()
        else:
            self.panel.take_label.setText(self._weight_take_text(take, path))
            self._start_weight_playback()
        if take.warnings:   # what the reader decided (a rate assumed, labels renamed, ...), in the model's words
            said = self.panel.status_label.text()
            self.panel.set_status(" ".join(["Warning:", *take.warnings] + ([said] if said else [])))
        self.panel.take_label.setToolTip("\n".join(take.warnings))
        self._sync_panel()
        return True

    def set_take_rate(self, rate: float) -> bool:
        """Read the take again at ``rate`` frames a second (the Mocap panel's Frame rate field): only a take whose
        file gives no rate (a plain marker CSV, a weights CSV without times); its solve goes, as with any take
        loaded (loading a take is not an undo step, nor is this). False when refused (said) or not such a take."""
        take, path = self.workspace.take, self.workspace.take_path
        if take is None or take.rate_from_file or path is None:
            return False
        if abs(rate - take.rate) <= 1e-9 * rate:
            return True
        if not self.load_take(path, rate):          # the file gone or changed: the take and its rate stay
            self.panel.set_take_rate(take.rate)
            return False
        return True

    @staticmethod
    def _weight_take_text(take: WeightTake, path: Path) -> str:
        driven = int((np.abs(take.weights).max(axis=0) > 0).sum())
        text = (f"{path.name}: {take.file_format}, {take.n_frames} frames at {take.rate:g} fps, "
                f"drives {driven} of {len(take.names)} rig shapes")
        if take.unmapped:
            text += f"; unmapped columns ({len(take.unmapped)}): {', '.join(take.unmapped)}"
        return text

    def load_map_dialog(self) -> None:
        path = app_settings.open_file(self.window, "mocap/mapFolder", "Load Marker Map", "Marker maps (*.json)")
        if path:
            self.load_map(path)

    def load_map(self, path: str | Path) -> bool:
        try:
            mm = load_marker_map(path)
        except RigInputError as exc:
            self._error("Could not use the marker map", str(exc))
            return False
        return self.replace_map(mm, f"Load marker map {Path(path).name}")

    def replace_map(self, marker_map, text: str) -> bool:
        """Use ``marker_map`` (loaded or found by Auto Map); when it replaces a map, one undo step (``text``): the
        map it replaces may hold points corrected by hand, or an automatic map that took seconds to find."""
        old = self.marker_map
        if old is None or self.document.project is None:
            return self.use_map(marker_map)
        try:
            self.workspace.check_map(marker_map)
        except RigInputError as exc:
            self._error("Could not use the marker map", str(exc))
            return False
        from app.actor_commands import SetMarkerMapCommand
        self.document.undo_stack.push(SetMarkerMapCommand(self, old, marker_map, text))
        return self.marker_map is marker_map

    def use_map(self, marker_map) -> bool:
        """Use a marker map already read (a saved project's); on failure keep what was loaded and say why."""
        try:
            self.workspace.set_map(marker_map)
        except RigInputError as exc:
            self._error("Could not use the marker map", str(exc))
            return False
        self._drop_solution()
        self._describe_map(marker_map)
        self._say_next_step()
        return True

    def open_in_panel(self, kind: str, path: str | Path) -> bool:
        """Load a take (``kind`` "take") or a marker map (else) that was dropped on the window or named on the command
        line, and bring the Mocap panel forward with it: behind the Shapes tab, the drop looked like nothing
        happened."""
        if not (self.load_take(path) if kind == "take" else self.load_map(path)):
            return False
        self.show_panel(f"Loaded {Path(path).name} into the Mocap panel.")
        return True

    def show_panel(self, message: str) -> None:
        """Show and raise the Mocap panel, saying ``message`` in the status bar."""
        self.dock.show()
        self.dock.raise_()
        self.window.show_status(message)

    def _say_next_step(self) -> None:
        """The hint under the panel: what a marker take still needs before Solve."""
        if not isinstance(self.take, MarkerTake):
            return
        if self.marker_map is None:
            self.panel.set_status("Load or build a marker map, then Solve.")
            return
        try:   # a map kept from the last take may not fit this one: say so now, not "Ready" until Solve refuses
            self.workspace.check_map(self.marker_map)
        except RigInputError as exc:
            self.panel.set_status(str(exc))
            return
        self.panel.set_status("Ready: Solve the take.")

    def _describe_map(self, mm) -> None:
        name = Path(mm.source).name if mm.source else "automatic map"
        self.panel.map_label.setText(f"{name}: {len(mm.labels)} markers on the rig ({mm.rig_units})")
        self.map_editor.refresh()

    def save_map_dialog(self) -> None:
        mm = self.marker_map
        if mm is None:
            self._error("Save Map", "There is no marker map to save: load one or Auto Map the take.")
            return
        path = self.workspace.take_path
        self.window.save_dialog("Save Marker Map", (path.stem if path else "take") + "_map.json",
                                "Marker maps (*.json)", self.save_map)

    def save_map(self, path) -> bool:
        """Write the marker map (with the points moved on the rig) as JSON, as ``solve --map`` reads it."""
        return self._write("marker map", path, lambda: self.marker_map.save(path), rewrites="the marker map")

    def auto_map(self) -> bool:
        """Auto Map: the take's markers mapped onto the rig in the background (a few seconds: the registration,
        then the re-fit from the take's motion); the map is used when it arrives, unless the take or the rig
        changed meanwhile. False when the settings are refused at once."""
        ws = self.workspace
        if ws.marker_take is None or ws.rig is None:
            self._error("Could not map markers", "Load a marker take (and open a rig) before mapping its markers.")
            return False
        st = self.panel.settings()
        take, rig = ws.take, ws.rig
        finder = TakeWorkspace(rig)
        finder.take = take

        def done(result) -> None:
            if ws.take is not take or ws.rig is not rig:
                return                      # another take or rig since: this map belongs to neither
            mm, rms = result
            if not self.replace_map(mm, "Auto Map the take's markers"):
                return
            self.panel.set_status(f"Automatic map: {len(mm.labels)} markers, fit RMS "
                                  f"{rms * unit_scale(rig.units, 'mm'):.2f} mm.")
            self.map_found.emit()

        def failed(message: str) -> None:
            self.panel.set_status("")
            self._error("Could not map markers", message)

        self.panel.set_status("Mapping the markers onto the rig…")
        self.window.run_in_background("Mapping markers…", lambda: finder.find_auto_map(
            st["calibration_frames"], neutral_frames=st["neutral_frames"], stable=st["stable"]), done, failed)
        return True

    # --- the actor's neutral ----------------------------------------------------------------------
    def use_neutral_frames(self, first: int, last: int | None = None) -> bool:
        """Make frames ``first``..``last`` (counted from 0; ``last`` None: ``first`` alone) the actor's neutral for
        the next solve, one undo step; ``first`` -1: back to the first calibration frames, -2: found automatically."""
        from app.actor_commands import SetNeutralFramesCommand
        if not isinstance(self.take, MarkerTake) or self.document.project is None:
            self._error("Use as Neutral", "Load a marker take first: its neutral frames are chosen on its timeline.")
            return False
        last = first if last is None else last
        if first == -1:
            new, text = None, "Neutral: the first calibration frames"
        elif first == -2:
            new, text = "auto", "Neutral: found automatically"
        else:
            n = self.take.n_frames
            if not 0 <= first <= last < n:
                self._error("Use as Neutral", f"Frames {first}:{last} are outside the take, which has frames 0 to "
                                              f"{n - 1}.")
                return False
            new = f"{first}:{last}"
            text = f"Use frame {first} as neutral" if first == last else f"Use frames {first}:{last} as neutral"
        old = self.panel.settings()["neutral_frames"]
        if old == new:
            return False
        self.document.undo_stack.push(SetNeutralFramesCommand(self, old, new, text))
        return True

    def use_frame_as_neutral(self) -> bool:
        """Animation ▸ Use Take Frame as Neutral (Alt+N): the frame shown."""
        return False if self._says_no_frames() else self.use_neutral_frames(self.frame)

    def _says_no_frames(self) -> bool:
        """Whether there is no take frame to play or pick, said in the status bar (the take actions did nothing,
        silently, with no take or an unsolved marker take)."""
        if self.n_frames:
            return False
        self.window.show_status("There is no take to play: load one in the Mocap panel." if self.take is None else
                                "Solve the take first: a marker take has frames to play once it is solved.", 4000)
        return True

    def show_neutral_frames(self, value: str | None) -> None:
        """Show the neutral frames setting in the panel (the undo commands call this)."""
        self.panel.set_neutral_frames(value)
        said = ("the first calibration frames" if value is None else "found automatically" if value == "auto"
                else f"frames {value}" if value.split(":")[0] != value.split(":")[-1] else f"frame {value.split(':')[0]}")
        self.panel.set_status(f"The actor's neutral: {said} (counted from 0). Solve again to use it.")

    # --- solving ----------------------------------------------------------------------------------
    def _segmentation(self):
        """The segmentation the Segmentation panel shows (a per-region solve uses its levels), or None."""
        return self.window.segmentation.segmentation

    def solve(self) -> None:
        """Solve the take onto the rig on the background runner, with a cancellable progress dialog."""
        from solvers.take_solve import SolveCancelled
        if self._solving:
            return
        ws = self.workspace
        settings = dict(self.panel.settings())
        if self.document.project.antagonists is not None:   # edited in Edit ▸ Antagonist Pairs (else the rig's)
            settings["antagonists"] = list(self.document.project.antagonists)
        segmentation = self._segmentation() if settings["mode"] == "region" else None
        try:
            ws.check_ready()
            solver_options(settings, ws.take, segmentation)   # a missing segmentation or level is said now
        except RigInputError as exc:
            self._error("Could not solve", str(exc))
            self.solve_failed.emit(str(exc))
            return
        self.pause()
        self._stop_fill()
        self._cancel = cancel = threading.Event()
        relay, version = self._relay, self.document.rig_version
        take, marker_map = ws.take, ws.marker_map
        rig, faces = self.rig, self._shown_faces()

        def job():
            try:
                sol = ws.solve_detached(settings, segmentation=segmentation, cancel=cancel.is_set,
                                        progress=lambda d, t, w: relay.progress.emit(d, t, w))
            except SolveCancelled:
                return None
            # the views' surface and first frames too, here: on the GUI thread they froze the window 0.2-0.3 s
            prepared = views_data(rig, take, sol, faces)
            prepared[3].warm()
            return sol, settings, (version, take, marker_map), (faces, prepared)

        dlg = QtWidgets.QProgressDialog("Solving the take…", "Cancel", 0, ws.take.n_frames, self.window)
        dlg.setWindowTitle("Solving")
        dlg.setWindowModality(QtCore.Qt.WindowModal)
        dlg.setMinimumDuration(200)
        dlg.canceled.connect(cancel.set)
        self._progress = dlg
        self._solve_frames = ws.take.n_frames
        self._solving = True
        self.panel.set_status("Solving…")
        self.runner.submit(job, self._on_solved, self._on_solve_failed)

    def _on_progress(self, done: int, total: int, what: str) -> None:
        dlg = self._progress
        if dlg is not None:
            dlg.setLabelText(f"Solving the take: {solve_progress_text(done, total, what, self._solve_frames)}")
            dlg.setMaximum(total)
            dlg.setValue(min(done, total - 1))

    def _close_progress(self) -> None:
        self._solving = False
        if self._progress is not None:
            self._progress.canceled.disconnect()
            self._progress.close()
            self._progress.deleteLater()
            self._progress = None

    def _shown_faces(self):
        parts = getattr(self.window, "parts", None)
        return parts.shown_faces() if parts is not None else None

    def _set_views_surface(self, solution, keep_camera: bool = False, prepared: tuple | None = None) -> None:
        """The Mocap Views' faces for ``solution`` (the captured area's, of the parts View ▸ Parts shows) and the
        frame cache of their vertices (``prepared`` by ``views_data`` on the solve's thread, else here); the views
        frame the face unless ``keep_camera``."""
        if prepared is None:
            prepared = views_data(self.rig, self.take, solution, self._shown_faces())
        counts, indices, normals, self.cache, first, clim = prepared
        self.views_frame = None          # new meshes: a frame is shown on them next
        self.views.set_surface(first, counts, indices, focus=self._face_box(solution.solver.rest),
                               n_markers=len(solution.labels), clim=clim,
                               residual_title="residual (mm)", normals=normals, keep_camera=keep_camera)

    def parts_changed(self) -> None:
        """View ▸ Parts changed: the Mocap Views of a solved take draw the parts now shown, at the same frame and
        from the same camera; their frame cache is filled again in the background."""
        solution = self.workspace.solution
        if self.cache is None or solution is None:
            return
        self._stop_fill()
        self._set_views_surface(solution, keep_camera=True)
        self.cache.playhead = self.frame
        self._start_fill()      # first: the frame shown is the fill's first
        self._show_frame(self.frame)

    def _on_solve_failed(self, message: str) -> None:
        self._close_progress()
        self._error("Could not solve", message)
        self.solve_failed.emit(message)

    def _on_solved(self, result) -> None:
        self._close_progress()
        if result is None:
            self.panel.set_status("Solve cancelled; nothing changed.")
            self.solve_failed.emit("cancelled")
            return
        solution, settings, (version, take, marker_map), (faces, prepared) = result
        ws = self.workspace
        if version != self.document.rig_version or ws.take is not take or ws.marker_map is not marker_map:
            self.panel.set_status("The rig, the take or the map changed during the solve; solve again.")
            self.solve_failed.emit("changed")
            return
        self._drop_solution()
        self.workspace.accept(solution, settings)
        now = self._shown_faces()
        same_parts = faces is None if now is None else np.array_equal(faces, now)
        self._show_views_dock()   # first: the views are framed at their size, and drawn once (set_frame)
        self._set_views_surface(solution, prepared=prepared if same_parts else None)
        mm = unit_scale(self.rig.units, "mm")
        err = solution.marker_rmse * mm
        self.error_plot.title = "marker error RMS (mm)"
        self.error_plot.set_curves([("projection", err), ("dense", solution.marker_rmse_residual * mm)], rate=self.rate)
        self._init_weight_curves(solution.shape_weights)
        self.panel.set_frames(solution.n_frames, self.rate)
        with_c = "" if not solution.solver.C else f" with the rig's {count(solution.solver.C, 'corrective')}"
        self.panel.set_status(f"Solved {solution.n_frames} frames{with_c} in {solution.solve_seconds:.1f} s "
                              f"({solution.frames_per_second:.0f} frames/s); marker RMS {np.nanmean(err):.2f} mm "
                              f"mean, {np.nanmax(err):.2f} mm max; motion explained "
                              f"{100 * solution.motion_explained:.1f}%" +
                              (f"; neutral frames {solution.neutral_frames[0]}–{solution.neutral_frames[1]}"
                               if solution.neutral_frames is not None else "") +
                              (f"; left out {', '.join(solution.left_out)}" if solution.left_out else "") + ".")
        self._sync_panel()
        self.playback.set_length(solution.n_frames, self.rate)
        self.set_frame(0)
        self._start_fill()
        self.solved.emit()

    def _show_views_dock(self) -> None:
        """Show the Mocap Views dock; the first time, split it as the user last did (else half views, half
        curves)."""
        self.views_dock.show()
        self.views_dock.raise_()   # in front of the Graph Editor, which shares its place above the timeline
        # the dock's size now, not on the event loop's next turn: the views are framed and drawn once, at it
        self.window.layout().activate()
        splitter = self.views.parentWidget()
        if not self._views_split and isinstance(splitter, QtWidgets.QSplitter):
            self._views_split = True
            saved = app_settings.settings().value("mocap/viewsSplitter")
            if saved is None or not splitter.restoreState(saved):
                splitter.setSizes([max(1, sum(splitter.sizes()) // 2)] * 2)

    @staticmethod
    def _face_box(markers: np.ndarray) -> np.ndarray:
        """Corners of the markers' bounding box grown by a quarter: what the views frame."""
        lo, hi = markers.min(axis=0), markers.max(axis=0)
        pad = 0.25 * (hi - lo)
        return np.array([lo - pad, hi + pad])

    def _drop_solution(self) -> None:
        self.pause()
        self._stop_fill()
        self.workspace.solution = None
        if self.cache is not None:   # the views showed that solve: nothing of it stays on screen
            self.views.clear()
        self.cache = None
        self._waiting = self.views_frame = None
        self.playback.set_length(self.n_frames, self.rate)
        self.weight_plot.set_curves([])
        self.error_plot.set_curves([])

    # --- background filling of the frame cache ---------------------------------------------------
    def _start_fill(self) -> None:
        """Compute every frame's display arrays on a thread of their own after a solve, from the frame shown on (the
        cache follows the playhead); each block filled is signalled to the GUI thread (``_on_filled``). Not on the
        runner: its next job starts only once the last one's result reached the event loop, and the views wait for
        this one at once."""
        self._fill_stop = stop = threading.Event()
        cache, relay = self.cache, self._relay
        self._fill_thread = threading.Thread(target=cache.fill, args=(stop, lambda _f: relay.filled.emit(cache)),
                                             name="frame-cache-fill", daemon=True)
        self._fill_thread.start()

    def _stop_fill(self, wait: bool = False) -> None:
        """Stop the fill after the block it is computing (``wait``: and wait for that)."""
        self._fill_stop.set()
        if wait and self._fill_thread is not None:
            self._fill_thread.join()

    def precompute(self) -> None:
        """Compute every frame's display arrays now (benchmarks, tests; otherwise a worker fills them)."""
        self._stop_fill()
        if self.cache is not None:
            self.cache.fill()

    # --- curves -----------------------------------------------------------------------------------
    def _init_weight_curves(self, W: np.ndarray) -> None:
        names = self.rig.shape_names
        top = [names[k] for k in np.argsort(-np.abs(W).max(axis=0))[:4] if np.abs(W[:, k]).max() > 0]
        self.panel.set_curve_shapes(names, top)
        self._update_weight_curves()

    def _update_weight_curves(self) -> None:
        W = self.workspace.playing_weights()
        if W is None:
            return
        names = self.rig.shape_names
        chosen = [n for n in self.panel.checked_curves() if n in names]
        self.weight_plot.title = "weights"
        self.weight_plot.set_curves([(n, W[:, names.index(n)]) for n in chosen], y_range=(0.0, 1.0), rate=self.rate)
        self.weight_plot.set_cursor(self.frame)

    # --- playback ---------------------------------------------------------------------------------
    def _start_weight_playback(self) -> None:
        take = self.take
        self.panel.set_frames(take.n_frames, take.rate)
        self._init_weight_curves(take.weights)
        self.error_plot.set_curves([])
        self.panel.set_status(f"{take.file_format[:1].upper()}{take.file_format[1:]} take: plays on the rig in the "
                              "main viewport (no undo steps).")
        self.playback.set_length(take.n_frames, take.rate)
        self.set_frame(0)

    def set_frame(self, frame: int) -> None:
        """Show one frame: both views (marker take) or the rig's pose (weight take), the curves' cursors."""
        self.playback.set_frame(frame)

    def _show_frame(self, frame: int) -> None:
        if isinstance(self.take, WeightTake):
            if self.take.weights.shape[1] == self.rig.n_shapes:
                self.document.set_weights(self.take.weights[frame])
        elif self.cache is not None:
            self._show_solved_frame(frame)
        self.panel.show_frame(frame, self.n_frames, self.rate)
        self.weight_plot.set_cursor(frame)
        self.error_plot.set_cursor(frame)
        self.frame_shown.emit(frame)

    def _show_solved_frame(self, frame: int) -> None:
        """Both views at ``frame`` if its arrays are filled, else at the nearest filled frame, said in the panel: the
        fill (a worker) is turned to ``frame`` and ``_on_filled`` shows it once computed. Never computed here: a frame
        of a studio rig froze the window 0.2-1.1 s."""
        cache = self.cache
        cache.playhead, cache.speed = frame, (self.rate if self.playing else 0.0)
        ready = cache.is_ready(frame) or (not self.playing and cache.wait_ready(frame, SCRUB_WAIT))
        shown = frame if ready else cache.nearest_ready(frame)
        if shown != frame:
            if self._waiting is None:
                self._said_before_wait = self.panel.status_label.text()
            self._waiting = frame
            n_ready = int(cache.ready.sum())
            self.panel.set_status(f"Computing frame {frame} ({n_ready} of {cache.n_frames} frames ready): the views "
                                  f"show frame {shown} meanwhile." if shown is not None else
                                  f"Computing frame {frame} ({n_ready} of {cache.n_frames} frames ready).")
        elif self._waiting is not None:
            self._waiting = None
            self.panel.set_status(self._said_before_wait)
        if shown is not None and shown != self.views_frame:   # the same nearest frame again: nothing to draw
            self.views_frame = shown
            self.views.show_frame(*cache.frame(shown), cache.markers[shown], cache.fitted[shown],
                                  normals=cache.normals(shown))

    def _on_filled(self, cache) -> None:
        """A block of frames was filled (the fill's signal): the frame the views wait for is shown once ready."""
        if cache is self.cache:
            self._show_waited_frame()

    def _show_waited_frame(self) -> None:
        """The take is still (paused, or a block filled while still): the fill turns to the frame at the playhead,
        shown if it is ready (while playing, the next tick shows its own frame anyway)."""
        cache = self.cache
        if cache is None or self.playing:
            return
        cache.playhead, cache.speed = self.frame, 0.0     # still: the fill computes this frame next
        if self._waiting is not None and cache.is_ready(self.frame):
            self._show_frame(self.frame)

    def _on_tick(self, frame: int) -> None:
        if isinstance(self.take, WeightTake):
            self.window.redraw_now()

    def play(self, on: bool = True) -> None:
        self.playback.play(on)

    def pause(self) -> None:
        self.playback.pause()

    def toggle_play(self) -> None:
        """Play or pause the take (Ctrl+Space)."""
        if not self._says_no_frames():
            self.playback.toggle()

    def step(self, frames: int) -> None:
        """Pause and move ``frames`` frames (Alt+, / Alt+.), clamped to the take."""
        if not self._says_no_frames():
            self.playback.step(frames)

    # --- rig changes ------------------------------------------------------------------------------
    def _on_shapes_change(self) -> None:
        """Shapes renamed, moved, added or deleted (the Shapes list): a solve or a weight take of the old list no
        longer lines up with the shapes, so it is handled as a new rig (the take re-mapped, the solve dropped)."""
        if self.document.rig is not None and list(self.document.rig.shape_names) != self._shape_names:
            self._on_rig_change()

    def _on_rig_change(self) -> None:
        self._shape_names = list(self.document.rig.shape_names)
        self.panel.set_units(self.document.rig.units)
        self._drop_solution()
        messages = self.workspace.set_rig(self.document.rig)
        self.panel.set_status("")   # what it said was of the last rig (a failed load's error stayed for good)
        self._say_next_step()
        for message in messages:
            self.panel.set_status(message)
        if self.workspace.take is None:   # none, or a weight take the new rig dropped: its frame went with it
            self.panel.take_label.setText("no take")
            self.panel.set_take_rate(None)
            self.panel.set_frames(0, 1.0)
        if self.workspace.marker_map is None:
            self.panel.map_label.setText("no marker map")
        self.map_editor.refresh()
        if isinstance(self.take, WeightTake):
            self.panel.take_label.setText(self._weight_take_text(self.take, self.workspace.take_path))
            self._start_weight_playback()
        self._sync_panel()

    # --- exports (model.take_exports) -------------------------------------------------------------
    def _export_dialog(self, title: str, filt: str, suffix: str, fn) -> None:
        path = self.workspace.take_path
        self.window.save_dialog(title, (path.stem if path else "take") + suffix, filt, fn)

    def _write(self, what: str, path, writer, rewrites: str | None = None) -> bool:
        """Write an export (``writer()``), refused over a file the window has open (the take, the rig, the project;
        but ``rewrites``: Save Map may save the marker map over the file it came from)."""
        if self.window.refuses_export_over_inputs(path, f"Could not export the {what}", rewrites=rewrites):
            self.panel.set_status(self.window.last_error)
            return False
        try:
            writer()
        except RigInputError as exc:
            self._error(f"Could not export the {what}", str(exc))
            return False
        except OSError as exc:
            self._error(f"Could not export the {what}", f"{path}: could not be written ({exc.strerror or exc}).")
            return False
        self.window.statusBar().showMessage(f"Exported {path}", 5000)
        self.panel.set_status(f"Exported the {what} to {path}.")
        return True

    def export_weights_csv(self, path) -> bool:
        """Per-frame weights of the solve (or the weight take) as ``frame,time,<rig shapes>``."""
        return self._write("weights", path, lambda: export_weights_csv(self.workspace, path))

    def export_pc2(self, path) -> bool:
        """Every frame's surface as a PC2 point cache: the dense solve (head-stabilised, computed in blocks of
        frames: the views' frame cache holds only the vertices they draw), or the rig posed by the weight take."""
        def write() -> None:
            check_room_for_pc2(path, self.workspace.n_frames, self.workspace.rig.n_vertices)
            export_pc2(self.workspace, path, take_surfaces(self.workspace, self.document.evaluator))
        QtWidgets.QApplication.setOverrideCursor(QtCore.Qt.WaitCursor)
        try:
            return self._write("point cache", path, write)
        finally:
            QtWidgets.QApplication.restoreOverrideCursor()

    def export_report(self, path) -> bool:
        """The solve report (README, "Solve report"): the same file as ``solve --report``."""
        return self._write("solve report", path, lambda: export_report(self.workspace, path))

    # --- teardown ---------------------------------------------------------------------------------
    def shutdown(self) -> None:
        """Stop playback and background work and close the views; the main window calls it on close."""
        if self._shut_down:
            return
        self._shut_down = True
        splitter = self.views.parentWidget()
        if self._views_split and isinstance(splitter, QtWidgets.QSplitter):
            app_settings.settings().setValue("mocap/viewsSplitter", splitter.saveState())  # for the next session
        self.pause()
        self._stop_fill(wait=True)
        self._cancel.set()
        self.runner.shutdown()
        self.views.close_views()


def install(window) -> MocapController:
    """Plug the Mocap panel (right), the Mocap Views dock (bottom) and the take actions of the Animation menu
    into ``window`` (a MainWindow, through its public interface); the window calls it once and keeps the
    controller as ``window.mocap``."""
    panel = MocapPanel(window)
    # the solve's mode, residual kernel and calibration length come back in the next session (the λs and the
    # kernel length stay at their measured defaults: they depend on the rig's units and the take)
    for widget, key in ((panel.mode_combo, "mocap/mode"), (panel.residual_combo, "mocap/residual"),
                        (panel.calibration_spin, "mocap/calibrationFrames"),
                        (panel.advanced_button, "mocap/advancedShown")):   # unfolded by who tunes them
        app_settings.remember(widget, key)
    panel.show_advanced(panel.advanced_button.isChecked())
    dock = window.add_dock("Mocap", panel, QtCore.Qt.RightDockWidgetArea, scroll=True)
    views = SideBySideView()
    weight_plot, error_plot = CurvePlot("weights"), CurvePlot("marker error RMS (mm)")
    # The two faces beside each other, the curves stacked on their right: a face is framed by the views' height,
    # so views wider than about two squares would only add background -- which software OpenGL still pays for
    # on every frame -- while the curves want width for their time axis.
    holder = QtWidgets.QSplitter(QtCore.Qt.Horizontal)
    holder.setObjectName("mocap_views_splitter")
    holder.addWidget(views)
    plots = QtWidgets.QWidget()
    pl = QtWidgets.QVBoxLayout(plots)
    pl.setContentsMargins(0, 0, 0, 0)
    pl.addWidget(weight_plot)
    pl.addWidget(error_plot)
    holder.addWidget(plots)
    holder.setStretchFactor(0, 1)
    holder.setStretchFactor(1, 1)
    holder.setCollapsible(0, False)
    holder.setCollapsible(1, False)
    views_dock = window.add_dock("Mocap Views", holder, QtCore.Qt.BottomDockWidgetArea)
    views_dock.hide()  # shown after the first solve
    controller = MocapController(window, panel, views, weight_plot, error_plot, window)
    controller.dock, controller.views_dock = dock, views_dock
    _add_take_actions(window, controller)
    window.parts.changed.connect(controller.parts_changed)   # the views draw the parts View ▸ Parts shows
    return controller


def _add_take_actions(window, controller: MocapController) -> None:
    """Animation menu: play / pause and step the take from the keyboard (Space plays the keyed animation)."""
    window.add_separator("animation")
    for text, slot, key, tip in (
            ("Play / Pause &Take", controller.toggle_play, "Ctrl+Space", "Play or pause the loaded take"),
            ("Previous Take Frame", lambda: controller.step(-1), "Alt+,", "Step the take one frame back"),
            ("Next Take Frame", lambda: controller.step(1), "Alt+.", "Step the take one frame on"),
            ("Use Take Frame as &Neutral", controller.use_frame_as_neutral, "Alt+N",
             "The take's frame shown becomes the actor's neutral for the next solve (undoable; right-click the "
             "take's slider for a range)")):
        window.add_action("animation", text, lambda _=False, f=slot: f(), key, tip)
    controller.panel.play_button.setToolTip("Play or pause the take (Ctrl+Space); Alt+, and Alt+. step a frame")


def views_data(rig, take, solution, shown_faces) -> tuple:
    """(counts, indices, normals, frame cache, first frame's surface, residual colour range) of the Mocap Views
    for ``solution``: the captured area's faces among ``shown_faces`` (View ▸ Parts; None: all), the vertices they
    use, one normals function for the cache and both views, the cache's first frame computed (the views show it at
    once), and the residual's range in mm from a few sampled frames (99th percentile, from the RBF alone), fixed for
    the take. No Qt: the solve's thread makes it."""
    counts, indices = captured_area_faces(rig, solution.solver.residual_vertices, shown_faces)
    shown, local = compact_faces(indices)  # the views draw these vertices only
    normals = VertexNormals(counts, local, len(shown))
    cache = FrameCache(solution, take, rig.units, normals=normals, shown=shown)
    cache.frame(0)
    first = solution.projection(0)   # the whole rig: the views take the vertices their faces use
    samples = np.unique(np.linspace(0, cache.n_frames - 1, 6).astype(int))
    vals = np.concatenate([cache.residual_lengths(int(f)) for f in samples]).astype(np.float32)
    hi = float(np.percentile(vals[vals > 0], 99)) if (vals > 0).any() else 1.0
    return counts, indices, normals, cache, first, (0.0, max(hi, 1e-3))
