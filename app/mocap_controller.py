"""Motion capture in the GUI: load a take and a marker map, solve it onto the rig off the GUI thread, play it
back in two linked views (projection + markers | dense result coloured by residual), export the results.

Weight takes (Live Link Face CSV) play directly on the rig in the main viewport. ``install(window)``
adds the Mocap panel and the Mocap Views dock to a MainWindow (ALGORITHMS.md §4, §5, §7).
"""
from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app import settings as app_settings
from app.background import BackgroundRunner
from model.errors import RigInputError
from model.rig import unit_scale
from model.takes import MarkerTake, WeightTake
from app.mocap_frames import FrameCache, captured_area_faces
from solvers.normals import VertexNormals, compact_faces
from widgets.curve_plot import CurvePlot
from widgets.mocap_panel import MocapPanel
from widgets.side_by_side import SideBySideView

TAKE_FILTER = "Takes (*.c3d *.trc *.csv);;C3D (*.c3d);;TRC (*.trc);;CSV / Live Link Face (*.csv)"


class _ProgressRelay(QtCore.QObject):
    progress = QtCore.Signal(int, int, str)  # emitted on the worker thread, delivered on the GUI thread


class MocapController(QtCore.QObject):
    solved = QtCore.Signal()          # a solve finished and is shown
    solve_failed = QtCore.Signal(str)
    frame_shown = QtCore.Signal(int)

    def __init__(self, window, panel: MocapPanel, views: SideBySideView, weight_plot: CurvePlot,
                 error_plot: CurvePlot, parent=None) -> None:
        super().__init__(parent or window)
        self.window, self.document = window, window.document
        self.panel, self.views = panel, views
        self.weight_plot, self.error_plot = weight_plot, error_plot
        self.take: MarkerTake | WeightTake | None = None
        self.take_path: Path | None = None
        self.marker_map = None
        self.solution = None
        self.cache: FrameCache | None = None
        self.frame = 0
        self.runner = BackgroundRunner(self)
        self._shut_down = False
        self._views_split = False  # the Mocap Views splitter got its first layout (saved on shutdown)
        self._relay = _ProgressRelay(self)
        self._relay.progress.connect(self._on_progress)
        self._cancel = threading.Event()
        self._progress: QtWidgets.QProgressDialog | None = None
        self._fill_stop = threading.Event()
        self._fill_thread: threading.Thread | None = None
        self.timer = QtCore.QTimer(self)
        self.timer.setTimerType(QtCore.Qt.PreciseTimer)
        self.timer.timeout.connect(self._tick)
        self._play_start = (0.0, 0)
        self._tick_times: list[float] = []
        self.playback_fps = 0.0
        p = panel
        p.load_take_requested.connect(self.load_take_dialog)
        p.load_map_requested.connect(self.load_map_dialog)
        p.auto_map_requested.connect(self.auto_map)
        p.solve_requested.connect(self.solve)
        p.export_weights_requested.connect(lambda: self._export_dialog("Export Weights CSV", "CSV (*.csv)",
                                                                       "_weights.csv", self.export_weights_csv))
        p.export_pc2_requested.connect(lambda: self._export_dialog("Export PC2 Point Cache", "PC2 (*.pc2)",
                                                                   ".pc2", self.export_pc2))
        p.export_report_requested.connect(lambda: self._export_dialog("Export Marker Error Report", "JSON (*.json)",
                                                                      "_marker_error.json", self.export_report))
        p.frame_requested.connect(self.set_frame)
        p.play_toggled.connect(self.play)
        p.curves_changed.connect(self._update_weight_curves)
        weight_plot.frame_requested.connect(self.set_frame)
        error_plot.frame_requested.connect(self.set_frame)
        self.document.rig_changed.connect(self._on_rig_change)
        self._sync_panel()

    # --- state helpers ----------------------------------------------------------------------------
    @property
    def rig(self):
        return self.document.rig

    @property
    def n_frames(self) -> int:
        if isinstance(self.take, WeightTake):
            return self.take.n_frames
        return self.solution.n_frames if self.solution is not None else 0

    @property
    def rate(self) -> float:
        return float(self.take.rate) if self.take is not None else 30.0

    def _sync_panel(self) -> None:
        markers = isinstance(self.take, MarkerTake)
        playable = self.n_frames > 0
        self.panel.set_marker_mode(markers, solved=playable)
        self.panel.set_weights_exportable(playable)
        self.panel.play_button.setEnabled(playable)
        self.panel.slider.setEnabled(playable)

    def _error(self, title: str, message: str) -> None:
        self.window.show_error(title, message)
        self.panel.set_status(message)

    # --- loading ----------------------------------------------------------------------------------
    def load_take_dialog(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self.window, "Load Take", "", TAKE_FILTER)
        if path:
            self.load_take(path)

    def _read_take(self, path: Path):
        from model.livelink import is_livelink_csv, read_livelink_csv
        from model.takes import load_take
        if path.suffix.lower() == ".csv" and path.is_file() and is_livelink_csv(path):
            if self.rig is None:
                raise RigInputError(f"{path}: open a rig before playing a Live Link Face take on it.")
            return read_livelink_csv(path, self.rig.shape_names)
        return load_take(path)

    def load_take(self, path: str | Path) -> bool:
        """Open a take; on failure keep whatever was loaded and say why."""
        path = Path(path)
        try:
            take = self._read_take(path)
        except RigInputError as exc:
            self._error("Could not load the take", str(exc))
            return False
        except (OSError, ValueError) as exc:
            self._error("Could not load the take", f"{path}: could not be read ({exc}).")
            return False
        self.pause()
        self._drop_solution()
        self.take, self.take_path = take, path
        if isinstance(take, MarkerTake):
            self.panel.take_label.setText(f"{path.name}: {take.n_frames} frames at {take.rate:g} fps, "
                                          f"{take.n_markers} markers ({take.units}), "
                                          f"{int(take.missing.sum())} missing samples")
            if self.marker_map is not None:
                self._describe_map(self.marker_map)
            self.panel.set_status("Load or build a marker map, then Solve.")
        else:
            self.panel.take_label.setText(self._weight_take_text(take, path))
            self._start_weight_playback()
        self._sync_panel()
        return True

    def _weight_take_text(self, take: WeightTake, path: Path) -> str:
        driven = int((np.abs(take.weights).max(axis=0) > 0).sum())
        text = (f"{path.name}: Live Link Face, {take.n_frames} frames at {take.rate:g} fps, "
                f"drives {driven} of {len(take.names)} rig shapes")
        if take.unmapped:
            text += f"; unmapped columns ({len(take.unmapped)}): {', '.join(take.unmapped)}"
        return text

    def load_map_dialog(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self.window, "Load Marker Map", "", "Marker maps (*.json)")
        if path:
            self.load_map(path)

    def load_map(self, path: str | Path) -> bool:
        from model.marker_map import load_marker_map
        try:
            mm = load_marker_map(path)
            self._validate_map(mm)
        except RigInputError as exc:
            self._error("Could not use the marker map", str(exc))
            return False
        self.marker_map = mm
        self._drop_solution()
        self._describe_map(mm)
        return True

    def _validate_map(self, mm) -> list[str]:
        if self.rig is None:
            raise RigInputError("Open a rig before loading a marker map.")
        take = self.take if isinstance(self.take, MarkerTake) else None
        warnings = mm.validate(self.rig, take)
        absent = mm.missing_from(take) if take is not None else []
        if absent:
            raise RigInputError(f"{mm.source or 'marker map'}: names {len(absent)} markers the take "
                                f"{Path(take.source).name if take.source else ''} does not have "
                                f"({', '.join(absent[:6])}{'…' if len(absent) > 6 else ''}).".replace(" ()", " ("))
        return warnings

    def _describe_map(self, mm) -> None:
        name = Path(mm.source).name if mm.source else "automatic map"
        self.panel.map_label.setText(f"{name}: {len(mm.labels)} markers on the rig ({mm.rig_units})")

    def auto_map(self) -> bool:
        from model.marker_map import auto_marker_map
        if not isinstance(self.take, MarkerTake) or self.rig is None:
            self._error("Could not map markers", "Load a marker take (and open a rig) before mapping its markers.")
            return False
        try:
            mm, info = auto_marker_map(self.rig, self.take,
                                       calibration_frames=self.panel.settings()["calibration_frames"])
        except RigInputError as exc:
            self._error("Could not map markers", str(exc))
            return False
        self.marker_map = mm
        self._drop_solution()
        self._describe_map(mm)
        rms = float(info.get("rms", float("nan"))) * unit_scale(self.rig.units, "mm")
        self.panel.set_status(f"Automatic map: {len(mm.labels)} markers, fit RMS {rms:.2f} mm.")
        return True

    # --- solving ----------------------------------------------------------------------------------
    def solve_options(self) -> dict:
        s = dict(self.panel.settings())
        mode, level = s.pop("mode"), s.pop("level")
        if mode == "region":
            seg = self.window.segmentation.segmentation
            if seg is None:
                raise RigInputError("A per-region solve needs a segmentation: segment the rig first.")
            if level >= len(seg.levels):
                raise RigInputError(f"The segmentation has {len(seg.levels)} levels; pick a level below that.")
            lvl = seg.levels[level]
            s["regions"] = [r.vertices for r in lvl.regions]
            s["blend"] = lvl.blend
        return s

    def solve(self) -> None:
        """Solve the take onto the rig off the GUI thread, with a cancellable progress dialog."""
        from solvers.take_solve import SolveCancelled, solve_take
        if not isinstance(self.take, MarkerTake) or self.marker_map is None or self.rig is None:
            self._error("Could not solve", "Load a marker take and a marker map (or Auto Map) before solving.")
            return
        if self.runner.busy:
            return
        try:
            self._validate_map(self.marker_map)
            options = self.solve_options()
        except RigInputError as exc:
            self._error("Could not solve", str(exc))
            self.solve_failed.emit(str(exc))
            return
        self.pause()
        rig, take, mm = self.rig, self.take, self.marker_map
        self._cancel = cancel = threading.Event()
        relay = self._relay

        def job():
            try:
                return solve_take(rig, take, mm, progress=lambda d, t, w: relay.progress.emit(d, t, w),
                                  cancel=cancel.is_set, **options)
            except SolveCancelled:
                return None
            except ValueError as exc:
                raise RigInputError(f"The take could not be solved: {exc}") from None

        dlg = QtWidgets.QProgressDialog("Solving the take…", "Cancel", 0, take.n_frames, self.window)
        dlg.setWindowTitle("Solving")
        dlg.setWindowModality(QtCore.Qt.WindowModal)
        dlg.setMinimumDuration(200)
        dlg.canceled.connect(cancel.set)
        self._progress = dlg
        self.panel.set_status("Solving…")
        self.runner.submit(job, self._on_solved, self._on_solve_failed)

    def _on_progress(self, done: int, total: int, what: str) -> None:
        dlg = self._progress
        if dlg is not None:
            dlg.setLabelText(f"Solving the take: {what} (frame {min(done, total)}/{total})")
            dlg.setMaximum(total)
            dlg.setValue(min(done, total - 1))

    def _close_progress(self) -> None:
        if self._progress is not None:
            self._progress.canceled.disconnect()
            self._progress.close()
            self._progress.deleteLater()
            self._progress = None

    def wait(self, msecs: int = 120000) -> None:
        """Block until a running solve is done and delivered (scripts and tests)."""
        self.runner.wait(msecs)
        QtWidgets.QApplication.processEvents()

    def cancel_solve(self) -> None:
        self._cancel.set()

    def _on_solve_failed(self, message: str) -> None:
        self._close_progress()
        self._error("Could not solve", message)
        self.solve_failed.emit(message)

    def _on_solved(self, solution) -> None:
        self._close_progress()
        if solution is None:
            self.panel.set_status("Solve cancelled; nothing changed.")
            self.solve_failed.emit("cancelled")
            return
        if solution.solver.V != self.rig.n_vertices:  # the rig changed while solving
            self.panel.set_status("The rig changed during the solve; solve again.")
            self.solve_failed.emit("rig changed")
            return
        self._drop_solution()
        self.solution = solution
        counts, indices = captured_area_faces(self.rig, solution.solver.residual_vertices)
        shown, local = compact_faces(indices)  # the views draw these vertices only
        normals = VertexNormals(counts, local, len(shown))  # one for the cache and both views
        self.cache = FrameCache(solution, self.take, self.rig.units, normals=normals, shown=shown)
        mm = unit_scale(self.rig.units, "mm")
        first, _, _ = self.cache.frame(0)
        self.views.set_surface(first, counts, indices, focus=self._face_box(solution.solver.rest),
                               n_markers=len(solution.labels), clim=self._residual_clim(),
                               residual_title="residual (mm)", normals=normals)
        self._show_views_dock()
        err = solution.marker_rmse * mm
        self.error_plot.title = "marker error RMS (mm)"
        self.error_plot.set_curves([("projection", err), ("dense", solution.marker_rmse_residual * mm)])
        self._init_weight_curves(solution.weights)
        self.panel.set_frames(solution.n_frames, self.rate)
        with_c = "" if not solution.solver.C else f" with the rig's {solution.solver.C} corrective(s)"
        self.panel.set_status(f"Solved {solution.n_frames} frames{with_c} in {solution.solve_seconds:.1f} s "
                              f"({solution.frames_per_second:.0f} frames/s); marker RMS {np.nanmean(err):.2f} mm "
                              f"mean, {np.nanmax(err):.2f} mm max.")
        self._sync_panel()
        self.frame = -1
        self.set_frame(0)
        self._start_fill()
        self.solved.emit()

    def _show_views_dock(self) -> None:
        """Show the Mocap Views dock; the first time, split it as the user last did (else half views, half
        curves)."""
        self.views_dock.show()
        splitter = self.views.parentWidget()
        if not self._views_split and isinstance(splitter, QtWidgets.QSplitter):
            self._views_split = True
            saved = app_settings.settings().value("mocap/viewsSplitter")

            def split() -> None:  # once the dock has its size (the next turn of the event loop)
                if saved is None or not splitter.restoreState(saved):
                    splitter.setSizes([max(1, sum(splitter.sizes()) // 2)] * 2)
            QtCore.QTimer.singleShot(0, split)

    @staticmethod
    def _face_box(markers: np.ndarray) -> np.ndarray:
        """Corners of the markers' bounding box grown by a quarter: what the views frame."""
        lo, hi = markers.min(axis=0), markers.max(axis=0)
        pad = 0.25 * (hi - lo)
        return np.array([lo - pad, hi + pad])

    def _residual_clim(self) -> tuple[float, float]:
        """Colour range of the residual in mm: from a few sampled frames (99th percentile), fixed for the take."""
        c = self.cache
        samples = np.unique(np.linspace(0, c.n_frames - 1, 6).astype(int))
        vals = np.concatenate([c.frame(int(f))[2] for f in samples])
        hi = float(np.percentile(vals[vals > 0], 99)) if (vals > 0).any() else 1.0
        return 0.0, max(hi, 1e-3)

    def _drop_solution(self) -> None:
        self._stop_fill()
        self.solution = None
        self.cache = None
        self.frame = 0
        self.weight_plot.set_curves([])
        self.error_plot.set_curves([])

    # --- background filling of the frame cache ---------------------------------------------------
    def _start_fill(self) -> None:
        self._stop_fill()
        self._fill_stop = stop = threading.Event()
        cache = self.cache
        self._fill_thread = threading.Thread(target=cache.fill, args=(stop,), daemon=True, name="mocap-cache")
        self._fill_thread.start()

    def _stop_fill(self) -> None:
        self._fill_stop.set()
        if self._fill_thread is not None:
            self._fill_thread.join()
            self._fill_thread = None

    def precompute(self) -> None:
        """Compute every frame's display arrays now (benchmarks; playback otherwise fills them lazily)."""
        self._stop_fill()
        if self.cache is not None:
            self.cache.fill()

    # --- curves -----------------------------------------------------------------------------------
    def _init_weight_curves(self, W: np.ndarray) -> None:
        names = self.rig.shape_names
        top = [names[k] for k in np.argsort(-np.abs(W).max(axis=0))[:4] if np.abs(W[:, k]).max() > 0]
        self.panel.set_curve_shapes(names, top)
        self._update_weight_curves()

    def _playing_weights(self) -> np.ndarray | None:
        if isinstance(self.take, WeightTake):
            return self.take.weights
        return self.solution.weights if self.solution is not None else None

    def _update_weight_curves(self) -> None:
        W = self._playing_weights()
        if W is None:
            return
        names = self.rig.shape_names
        chosen = [n for n in self.panel.checked_curves() if n in names]
        self.weight_plot.title = "weights"
        self.weight_plot.set_curves([(n, W[:, names.index(n)]) for n in chosen], y_range=(0.0, 1.0))
        self.weight_plot.set_cursor(self.frame)

    # --- playback ---------------------------------------------------------------------------------
    def _start_weight_playback(self) -> None:
        take = self.take
        self.panel.set_frames(take.n_frames, take.rate)
        self._init_weight_curves(take.weights)
        self.error_plot.set_curves([])
        self.panel.set_status("Live Link Face take: plays on the rig in the main viewport (no undo steps).")
        self.frame = -1
        self.set_frame(0)

    def set_frame(self, frame: int) -> None:
        """Show one frame: both views (marker take) or the rig's pose (weight take), the curves' cursors."""
        n = self.n_frames
        if n == 0:
            return
        frame = int(np.clip(frame, 0, n - 1))
        if frame == self.frame:
            return
        self.frame = frame
        if isinstance(self.take, WeightTake):
            if self.take.weights.shape[1] == self.rig.n_shapes:
                self.document.set_weights(self.take.weights[frame])
        elif self.cache is not None:
            proj, dense, res = self.cache.frame(frame)
            self.views.show_frame(proj, dense, res, self.cache.markers[frame], self.cache.fitted[frame],
                                  normals=self.cache.normals(frame))
        self.panel.show_frame(frame, n, self.rate)
        self.weight_plot.set_cursor(frame)
        self.error_plot.set_cursor(frame)
        self.frame_shown.emit(frame)

    def play(self, on: bool = True) -> None:
        if not on:
            self.pause()
            return
        if self.n_frames == 0:
            self.panel.set_playing(False)
            return
        start = 0 if self.frame >= self.n_frames - 1 else max(self.frame, 0)
        self._play_start = (time.perf_counter(), start)
        self._tick_times = []
        self.panel.set_playing(True)
        self.timer.start(max(1, int(1000 / min(self.rate, 60.0))))

    def pause(self) -> None:
        self.timer.stop()
        self.panel.set_playing(False)

    def toggle_play(self) -> None:
        """Play or pause the take (Ctrl+Space)."""
        self.pause() if self.playing else self.play()

    def step(self, frames: int) -> None:
        """Pause and move ``frames`` frames (Alt+, / Alt+.), clamped to the take."""
        self.pause()
        if self.n_frames:
            self.set_frame(max(self.frame, 0) + frames)

    @property
    def playing(self) -> bool:
        return self.timer.isActive()

    def _tick(self) -> None:
        """Real-time playback: show the frame the clock is at (frames are skipped if drawing is slow)."""
        t0, f0 = self._play_start
        now = time.perf_counter()
        target = f0 + int((now - t0) * self.rate)
        n = self.n_frames
        if target >= n:
            if self.panel.loop_check.isChecked():
                self._play_start = (now, 0)
                target = 0
            else:
                self.set_frame(n - 1)
                self.pause()
                return
        if target == self.frame:
            return
        self.set_frame(target)
        if isinstance(self.take, WeightTake):
            self.window.redraw_now()
        self._tick_times.append(time.perf_counter())
        self._tick_times = self._tick_times[-30:]
        if len(self._tick_times) >= 2:
            dt = (self._tick_times[-1] - self._tick_times[0]) / (len(self._tick_times) - 1)
            self.playback_fps = 1.0 / dt if dt > 0 else 0.0
            self.panel.fps_label.setText(f"{self.playback_fps:.0f} fps drawn · take {self.rate:g} fps")

    # --- rig changes ------------------------------------------------------------------------------
    def _on_rig_change(self) -> None:
        self.panel.set_units(self.document.rig.units)
        self.pause()
        self._drop_solution()
        if isinstance(self.take, WeightTake) and self.take_path is not None:
            try:  # map the recording onto the new rig's shapes
                self.take = self._read_take(self.take_path)
            except RigInputError as exc:
                self.take = None
                self.panel.take_label.setText("no take")
                self.panel.set_status(f"The Live Link Face take does not fit this rig: {exc}")
            else:
                self.panel.take_label.setText(self._weight_take_text(self.take, self.take_path))
                self._start_weight_playback()
        elif self.marker_map is not None:
            try:
                self._validate_map(self.marker_map)
            except RigInputError as exc:
                self.marker_map = None
                self.panel.map_label.setText("no marker map")
                self.panel.set_status(f"The marker map does not fit this rig: {exc}")
        self._sync_panel()

    # --- exports ----------------------------------------------------------------------------------
    def _export_dialog(self, title: str, filt: str, suffix: str, fn) -> None:
        stem = self.take_path.stem if self.take_path else "take"
        self.window.save_dialog(title, stem + suffix, filt, fn)

    def _write(self, what: str, path, writer) -> bool:
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
        from model.weights_csv import write_weights_csv
        W = self._playing_weights()
        if W is None:
            self._error("Nothing to export", "Solve a marker take or load a Live Link Face take first.")
            return False
        return self._write("weights", path,
                           lambda: write_weights_csv(path, W, list(self.rig.shape_names), rate=self.rate))

    def export_pc2(self, path) -> bool:
        """Every frame's surface as a PC2 point cache: the dense solve (head-stabilised), or the rig posed by
        the weight take."""
        from model.pc2 import write_pc2
        if self.cache is not None:
            frames = (self.cache.frame(f)[1] for f in range(self.cache.n_frames))
        elif isinstance(self.take, WeightTake):
            ev = self.document.evaluator
            frames = (ev.evaluate(w) for w in self.take.weights)
        else:
            self._error("Nothing to export", "Solve a marker take or load a Live Link Face take first.")
            return False
        QtWidgets.QApplication.setOverrideCursor(QtCore.Qt.WaitCursor)
        try:
            return self._write("point cache", path, lambda: write_pc2(path, frames, n_points=self.rig.n_vertices))
        finally:
            QtWidgets.QApplication.restoreOverrideCursor()

    def error_report(self) -> dict:
        """Per-frame and per-marker errors of the solve in mm (JSON-ready)."""
        sol, take = self.solution, self.take
        mm = unit_scale(self.rig.units, "mm")
        mis = sol.misfit * mm
        with np.errstate(invalid="ignore"):
            d = np.linalg.norm(mis, axis=2)                                  # (F, M), NaN where missing
            per_marker = np.sqrt(np.nanmean(d * d, axis=0))
        def clean(a):
            return [None if not np.isfinite(x) else round(float(x), 5) for x in np.ravel(a)]
        return {
            "take": str(self.take_path) if self.take_path else take.source,
            "marker_map": self.marker_map.source or "automatic",
            "rig": self.rig.name, "units": "mm", "frames": int(sol.n_frames), "rate": float(take.rate),
            "options": {k: v for k, v in self.panel.settings().items()},
            "solve_seconds": round(float(sol.solve_seconds), 4),
            "summary": {"rmse_mean": float(np.nanmean(sol.marker_rmse * mm)),
                        "rmse_max": float(np.nanmax(sol.marker_rmse * mm)),
                        "rmse_with_residual_mean": float(np.nanmean(sol.marker_rmse_residual * mm)),
                        "worst_marker": sol.labels[int(np.nanargmax(per_marker))]},
            "per_frame_rmse": clean(sol.marker_rmse * mm),
            "per_frame_rmse_with_residual": clean(sol.marker_rmse_residual * mm),
            "per_marker_rmse": dict(zip(sol.labels, clean(per_marker))),
            "missing_samples": {lab: int(np.isnan(d[:, i]).sum()) for i, lab in enumerate(sol.labels)},
        }

    def export_report(self, path) -> bool:
        from model.atomic import atomic_write
        if self.solution is None:
            self._error("Nothing to export", "Solve a marker take first.")
            return False
        report = self.error_report()
        return self._write("marker error report", path,
                           lambda: atomic_write(path, (json.dumps(report, indent=1) + "\n").encode("utf-8")))

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
        self._stop_fill()
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
                        (panel.calibration_spin, "mocap/calibrationFrames")):
        app_settings.remember(widget, key)
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
    return controller


def _add_take_actions(window, controller: MocapController) -> None:
    """Animation menu: play / pause and step the take from the keyboard (Space plays the keyed animation)."""
    window.add_separator("animation")
    for text, slot, key, tip in (
            ("Play / Pause &Take", controller.toggle_play, "Ctrl+Space", "Play or pause the loaded take"),
            ("Previous Take Frame", lambda: controller.step(-1), "Alt+,", "Step the take one frame back"),
            ("Next Take Frame", lambda: controller.step(1), "Alt+.", "Step the take one frame on")):
        window.add_action("animation", text, lambda _=False, f=slot: f(), key, tip)
    controller.panel.play_button.setToolTip("Play or pause the take (Ctrl+Space); Alt+, and Alt+. step a frame")
