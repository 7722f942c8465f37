"""A motion-capture take and what is done with it, without Qt (ALGORITHMS.md §4, §5, §7): the take, its marker
map, the solve settings, the solve and its report. The GUI's Mocap panel (``app.mocap_controller``) and the
command line's ``solve`` both work through ``TakeWorkspace``; the exports are in ``model.take_exports``.

Solve settings are a plain dict, as the panel and the command line gather them:
``mode`` ('global' or 'region'), ``level`` (hierarchy level of a per-region solve), ``residual``,
``lam_sparsity``, ``lam_temporal``, ``rbf_scale``, ``rbf_lambda`` (solver options, ``solvers.take_solve.DEFAULTS``
for any left out), ``calibration_frames`` and ``fixed_head`` (markers already head-stabilised in rig space).
"""
from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from solvers.take_solve import DEFAULTS, Progress, TakeSolution, TakeSolver

from .correctives import solver_correctives
from .errors import RigInputError
from .marker_map import MarkerMap, auto_marker_map, load_marker_map
from .pose import PoseEvaluator
from .rig import Rig, unit_scale
from .segmentation import SegmentationSettings
from .takes import MarkerTake, WeightTake

# Defaults of a solve, chosen by measurement (see README, Motion capture). On the ICT Live Link take a global
# solve measured 0.205 mm dense RMS against the actor's true surface and a two-region solve 0.212 mm: per-region
# solves are offered, the global solve is the default.
SOLVE_DEFAULTS = {"regional": False, "threshold": SegmentationSettings().t, "level": 2}

# The solver options a settings dict may carry (the rest of it says how the solve is set up).
SOLVER_OPTIONS = ("residual", "lam_sparsity", "lam_temporal", "rbf_scale", "rbf_lambda")


def read_take(path: str | Path, rig: Rig | None = None) -> MarkerTake | WeightTake:
    """Open a marker take (C3D, TRC, CSV) or a Live Link Face CSV, whose weights are mapped onto ``rig``'s shapes.
    Raises RigInputError (one sentence naming the file) for anything unreadable."""
    from .livelink import is_livelink_csv, read_livelink_csv
    from .takes import load_take
    path = Path(path)
    try:
        if path.suffix.lower() == ".csv" and path.is_file() and is_livelink_csv(path):
            if rig is None:
                raise RigInputError(f"{path}: open a rig before playing a Live Link Face take on it.")
            return read_livelink_csv(path, rig.shape_names)
        return load_take(path)
    except (OSError, ValueError) as exc:
        raise RigInputError(f"{path}: could not be read ({exc}).") from None


def regional_solve_options(segmentation, level: int) -> dict:
    """The solver's ``regions`` and ``blend`` for a per-region solve on ``level`` of a segmentation
    (``model.segmentation``); RigInputError when there is none or the level does not exist."""
    if segmentation is None:
        raise RigInputError("A per-region solve needs a segmentation: segment the rig first.")
    n = len(segmentation.levels)
    if not 0 <= level < n:
        raise RigInputError(f"Level {level} does not exist: the segmentation has levels 0 to {n - 1}.")
    lvl = segmentation.levels[level]
    return {"regions": [r.vertices for r in lvl.regions], "blend": lvl.blend}


def solve_take(rig: Rig, take: MarkerTake, marker_map: MarkerMap, *, evaluator: PoseEvaluator | None = None,
               progress: Progress = None, cancel=None, calibration_frames: int = DEFAULTS["calibration_frames"],
               **options) -> TakeSolution:
    """Solve a marker take onto a rig with a marker map (``solvers.take_solve.TakeSolver``).

    Uses the take's and rig's units; markers of the map missing from the take are dropped. The rig's live
    (unmuted) correctives are solved with the shapes, and every dense frame is the rig's pose evaluation
    (``evaluator``: a float64 ``PoseEvaluator`` of ``rig``, built here if not given) plus the residual.
    ``options`` go to ``TakeSolver``. The solution's marker columns follow ``marker_map.match(take)``."""
    labels, cols = marker_map.match(take)
    binding = marker_map.binding(rig, labels)
    if evaluator is None or evaluator.dtype != np.float64:
        evaluator = PoseEvaluator(rig, dtype=np.float64)
    surface = partial(evaluator.pose, blend=options.get("blend"))
    solver = TakeSolver(rig.neutral, rig.deltas, binding, correctives=solver_correctives(rig), surface=surface,
                        **options)
    sol = solver.solve(take.positions[:, cols], unit_factor=unit_scale(take.units, rig.units),
                       calibration_frames=calibration_frames, calibrate=calibration_frames > 0,
                       progress=progress, cancel=cancel)
    sol.labels = labels
    return sol


def _head_and_options(settings: dict, take: MarkerTake) -> tuple[bool, int, dict]:
    """(fixed head, calibration frames, solver options without the regions) of ``settings`` on ``take``.
    A one-frame take (a keyframe) has no neutral frames to calibrate on and no motion to follow: its markers
    are taken as already in rig space, and temporal smoothness has no neighbour to act on."""
    options = {k: settings[k] if settings.get(k) is not None else DEFAULTS[k] for k in SOLVER_OPTIONS}
    fixed_head = bool(settings.get("fixed_head")) or take.n_frames == 1
    if fixed_head:
        options["head_motion"] = False
    if take.n_frames == 1:
        options.update(lam_temporal=0.0, two_pass=False)
    calibration = 0 if fixed_head else int(settings.get("calibration_frames", DEFAULTS["calibration_frames"]))
    return fixed_head, calibration, options


def solver_options(settings: dict, take: MarkerTake, segmentation=None) -> tuple[dict, int]:
    """(``TakeSolver`` options, calibration frames) for solve ``settings`` on ``take``: the GUI and the command
    line build a solve only here (``segmentation`` for a per-region solve)."""
    _, calibration, options = _head_and_options(settings, take)
    if settings.get("mode", "global") == "region":
        options.update(regional_solve_options(segmentation, int(settings.get("level", 0))))
    return options, calibration


def solve_report(rig: Rig, take: MarkerTake, solution: TakeSolution, settings: dict, *, take_path=None,
                 map_source: str = "") -> dict:
    """The solve report (README, "Solve report"), JSON-ready, lengths in the rig's units: what the GUI's Export
    Report and ``solve --report`` write."""
    fixed_head, calibration, options = _head_and_options(settings, take)
    sol = solution
    with np.errstate(invalid="ignore"):
        d = np.linalg.norm(sol.misfit, axis=2)                       # (F, M) rig units, NaN where missing
        per_marker = np.sqrt(np.nanmean(d * d, axis=0))

    def clean(a) -> list:
        return [None if not np.isfinite(x) else float(x) for x in np.ravel(a)]
    labels = list(sol.labels or [])
    used = set(labels)
    return {
        "rig": rig.name, "take": str(take_path) if take_path else take.source,
        "marker_map": map_source or "automatic",
        "frames": sol.n_frames, "rate": float(take.rate), "markers": len(labels), "rig_units": rig.units,
        "solve_seconds": float(sol.solve_seconds), "frames_per_second": float(sol.frames_per_second),
        "marker_rmse": float(np.nanmean(sol.marker_rmse)),
        "marker_rmse_max": float(np.nanmax(sol.marker_rmse)),
        "marker_rmse_with_residual": float(np.nanmean(sol.marker_rmse_residual)),
        "marker_rmse_per_frame": clean(sol.marker_rmse),
        "marker_rmse_per_frame_with_residual": clean(sol.marker_rmse_residual),
        "marker_rmse_per_marker": dict(zip(labels, clean(per_marker))),
        "worst_marker": labels[int(np.nanargmax(per_marker))] if np.isfinite(per_marker).any() else None,
        "missing_samples": {lab: int(np.isnan(d[:, i]).sum()) for i, lab in enumerate(labels)},
        "markers_left_out": [lab for lab in take.labels if lab not in used],
        "neutral_frames": [0, min(calibration, take.n_frames) - 1] if calibration > 0 else None,
        "mode": "regional" if settings.get("mode") == "region" else "global",
        "level": int(settings["level"]) if settings.get("mode") == "region" else None,
        "head": "fixed" if fixed_head else "solved",
        "options": {k: options[k] for k in SOLVER_OPTIONS},
        "residual": options["residual"],
        "correctives": [c.name for c in rig.correctives if not c.muted],   # solved with the shapes
    }


class TakeWorkspace:
    """The take being worked on: the take (markers, or a Live Link Face weight take), its marker map, the last
    solve's settings and its solution. Every method raises RigInputError with one sentence on bad input and
    leaves what was loaded in place."""

    def __init__(self, rig: Rig | None = None) -> None:
        self.rig = rig
        self.take: MarkerTake | WeightTake | None = None
        self.take_path: Path | None = None
        self.marker_map: MarkerMap | None = None
        self.settings: dict = {}
        self.solution: TakeSolution | None = None

    # --- what is loaded ---------------------------------------------------------------------------
    @property
    def marker_take(self) -> MarkerTake | None:
        return self.take if isinstance(self.take, MarkerTake) else None

    @property
    def rate(self) -> float:
        return float(self.take.rate) if self.take is not None else 30.0

    @property
    def n_frames(self) -> int:
        """Frames there are to play: the weight take's, or the solved take's (0 before a solve)."""
        if isinstance(self.take, WeightTake):
            return self.take.n_frames
        return self.solution.n_frames if self.solution is not None else 0

    def playing_weights(self) -> np.ndarray | None:
        """(F, K) weights to play or export: the weight take's or the solve's; None before either."""
        if isinstance(self.take, WeightTake):
            return self.take.weights
        return self.solution.weights if self.solution is not None else None

    def load_take(self, path: str | Path) -> MarkerTake | WeightTake:
        take = read_take(path, self.rig)
        self.take, self.take_path, self.solution = take, Path(path), None
        return take

    def load_map(self, path: str | Path, *, strict: bool = True) -> MarkerMap:
        mm = load_marker_map(path)
        self.set_map(mm, strict=strict)
        return mm

    def set_map(self, marker_map: MarkerMap, *, strict: bool = True) -> list[str]:
        """Use ``marker_map`` after checking it against the rig and the take; ``strict`` also refuses a map
        naming markers the take does not have (the GUI). Returns the warnings."""
        warnings = self.check_map(marker_map, strict=strict)
        self.marker_map, self.solution = marker_map, None
        return warnings

    def check_map(self, marker_map: MarkerMap, *, strict: bool = True) -> list[str]:
        if self.rig is None:
            raise RigInputError("Open a rig before loading a marker map.")
        take = self.marker_take
        warnings = marker_map.validate(self.rig, take)
        absent = marker_map.missing_from(take) if (take is not None and strict) else []
        if absent:
            raise RigInputError(f"{marker_map.source or 'marker map'}: names {len(absent)} markers the take "
                                f"{Path(take.source).name if take.source else ''} does not have "
                                f"({', '.join(absent[:6])}{'…' if len(absent) > 6 else ''}).".replace(" ()", " ("))
        return warnings

    def auto_map(self, calibration_frames: int = DEFAULTS["calibration_frames"]) -> float:
        """Map the take's markers onto the rig from its neutral calibration frames; returns the fit RMS (rig
        units)."""
        if self.marker_take is None or self.rig is None:
            raise RigInputError("Load a marker take (and open a rig) before mapping its markers.")
        mm, info = auto_marker_map(self.rig, self.take, calibration_frames=calibration_frames)
        self.marker_map, self.solution = mm, None
        return float(info.get("rms", float("nan")))

    def set_rig(self, rig: Rig) -> list[str]:
        """A new rig: the solution goes, a Live Link Face take is mapped onto the new shapes and the marker map
        is checked again; what no longer fits is dropped. Returns one sentence per thing dropped."""
        self.rig, self.solution = rig, None
        dropped = []
        if isinstance(self.take, WeightTake) and self.take_path is not None:
            try:
                self.take = read_take(self.take_path, rig)
            except RigInputError as exc:
                self.take = self.take_path = None
                dropped.append(f"The Live Link Face take does not fit this rig: {exc}")
        elif self.marker_map is not None:
            try:
                self.check_map(self.marker_map)
            except RigInputError as exc:
                self.marker_map = None
                dropped.append(f"The marker map does not fit this rig: {exc}")
        return dropped

    # --- solving ----------------------------------------------------------------------------------
    def check_ready(self) -> None:
        if self.marker_take is None or self.marker_map is None or self.rig is None:
            raise RigInputError("Load a marker take and a marker map (or Auto Map) before solving.")
        self.check_map(self.marker_map)

    def solve(self, settings: dict, *, segmentation=None, evaluator: PoseEvaluator | None = None,
              progress: Progress = None, cancel=None) -> TakeSolution:
        """Solve the take with ``settings`` (see the module docstring); ``segmentation`` for a per-region solve.
        Keeps and returns the solution (``solvers.take_solve.SolveCancelled`` propagates)."""
        self.check_ready()
        solution = self.solve_detached(settings, segmentation=segmentation, evaluator=evaluator,
                                       progress=progress, cancel=cancel)
        self.accept(solution, settings)
        return solution

    def solve_detached(self, settings: dict, *, segmentation=None, evaluator=None, progress=None,
                       cancel=None) -> TakeSolution:
        """``solve`` without keeping the result (for a worker thread; ``accept`` keeps it)."""
        options, calibration = solver_options(settings, self.take, segmentation)
        try:
            return solve_take(self.rig, self.take, self.marker_map, evaluator=evaluator, progress=progress,
                              cancel=cancel, calibration_frames=calibration, **options)
        except ValueError as exc:
            raise RigInputError(f"The take could not be solved: {exc}") from None

    def accept(self, solution: TakeSolution, settings: dict) -> None:
        self.solution, self.settings = solution, dict(settings)

    def report(self) -> dict:
        """The report of the last solve (``solve_report``)."""
        if self.solution is None:
            raise RigInputError("Solve a marker take first.")
        return solve_report(self.rig, self.take, self.solution, self.settings, take_path=self.take_path,
                            map_source=self.marker_map.source if self.marker_map is not None else "")
