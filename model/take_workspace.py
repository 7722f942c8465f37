"""A motion-capture take and what is done with it, without Qt (ALGORITHMS.md §4, §5, §7): the take, its marker
map, the solve settings, the solve and its report. The GUI's Mocap panel (``app.mocap_controller``) and the
command line's ``solve`` both work through ``TakeWorkspace``; the exports are in ``model.take_exports``.

Solve settings are a plain dict, as the panel and the command line gather them:
``mode`` ('global' or 'region'), ``level`` (hierarchy level of a per-region solve), ``residual``,
``lam_sparsity``, ``lam_temporal``, ``rbf_scale``, ``rbf_lambda``, ``retarget`` (solver options,
``solvers.take_solve.DEFAULTS`` for any left out; lengths in cm and the λ's in cm², whatever the rig's units:
``model.units`` converts them), ``calibration_frames``, ``neutral_frames`` (None: the first
``calibration_frames``; ``"auto"``; or ``"A:B"`` / (A, B), inclusive), ``stable`` (marker names or patterns such as
``root-*``, comma-separated, for the head motion), ``fixed_head`` (markers already head-stabilised in rig space) and
``antagonists`` (the shape pairs kept apart, as names; None: the rig's, ``model.antagonists``) and ``rate`` (the frame
rate of a take whose file gives none, ``--rate``; None: ``read_take``'s defaults).
"""
from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from solvers.take_solve import DEFAULTS, Progress, TakeSolution, TakeSolver, marker_rest, residual_preparation

from .correctives import solver_correctives
from .errors import RigInputError, shown
from .marker_map import MarkerMap, auto_marker_map, load_marker_map
from .pose import PoseEvaluator
from .rig import Rig
from .segmentation import SegmentationSettings
from .takes import MarkerTake, WeightTake
from .units import take_solver_options, unit_scale

# Defaults of a solve, chosen by measurement (see README, Motion capture). On the ICT Live Link take a global
# solve measured 0.205 mm dense RMS against the actor's true surface and a two-region solve 0.212 mm: per-region
# solves are offered, the global solve is the default.
SOLVE_DEFAULTS = {"regional": False, "threshold": SegmentationSettings().t, "level": 2}

# The solver options a settings dict may carry (the rest of it says how the solve is set up).
SOLVER_OPTIONS = ("residual", "lam_sparsity", "lam_temporal", "rbf_scale", "rbf_lambda", "retarget", "lam_antagonist")

# A marker missing in more than this fraction of the frames is left out of the solve with a warning.
MOSTLY_MISSING = 0.5


def parse_neutral_frames(value, where: str = "--neutral-frames"):
    """None, 'auto' or (first, last) from a settings value: None, 'auto', 'A:B' (inclusive) or a pair.
    RigInputError (one sentence) otherwise."""
    if value is None or (isinstance(value, str) and value.strip().lower() == "auto"):
        return None if value is None else "auto"
    if isinstance(value, str):
        parts = value.split(":")
        try:
            a, b = (int(parts[0]), int(parts[1])) if len(parts) == 2 else (None, None)
        except ValueError:
            a = b = None
        if a is None:
            raise RigInputError(f"{where}: '{value[:40]}' is not a frame range A:B or 'auto'.")
        value = (a, b)
    a, b = int(value[0]), int(value[1])
    if a > b:
        raise RigInputError(f"{where}: the neutral range {a}:{b} ends before it starts.")
    return a, b


def check_calibration_settings(settings: dict) -> None:
    """The solve settings' calibration, before any take: a count of calibration frames that is a whole number of 0
    or more (0: no calibration, the markers taken as the rig's own face in rig space; head motion is still solved),
    and no neutral range for a solve that calibrates nothing. RigInputError (one sentence) otherwise."""
    n = settings.get("calibration_frames", DEFAULTS["calibration_frames"])
    try:
        whole = float(n) == int(n) and int(n) >= 0
    except (TypeError, ValueError, OverflowError):
        whole = False
    if not whole:
        raise RigInputError(f"--calibration-frames: {shown(n, 20)} is not a count of frames (0, no calibration, or "
                            "more).")
    neutral = parse_neutral_frames(settings.get("neutral_frames"))
    if n == 0 and neutral is not None and not settings.get("fixed_head"):
        raise RigInputError("--neutral-frames: a solve with --calibration-frames 0 calibrates on no neutral; give "
                            "the neutral frames or no calibration, not both.")


def check_take_calibration(take: MarkerTake, settings: dict) -> None:
    """The solve settings' neutral against ``take``, before any work on it: a range ``--neutral-frames A:B``
    inside the take, and no more calibration frames than it has (the first ``calibration_frames``, or the length of
    the stretch ``auto`` looks for: the whole take, expressions and all, taken as the neutral gave a marker RMSE 3x
    larger on the shared actor take). RigInputError (one sentence naming the take and its frames) otherwise."""
    check_calibration_settings(settings)
    fixed_head, calibration, _ = _head_and_options(settings, take)
    if fixed_head or calibration == 0:
        return
    where, F = take.source or "The take", take.n_frames
    neutral = parse_neutral_frames(settings.get("neutral_frames"))
    if isinstance(neutral, tuple):
        a, b = neutral
        if not 0 <= a <= b < F:
            raise RigInputError(f"{where}: the neutral frames {a}:{b} (--neutral-frames) are outside the take, which "
                                f"has frames 0 to {F - 1}.")
    elif calibration > F:
        raise RigInputError(f"{where}: has {F} frames, fewer than the {calibration} calibration frames its neutral "
                            f"would come from (--calibration-frames); give at most {F}, or --neutral-frames A:B.")


def resolve_stable(labels: list[str], spec, where: str = "") -> list[str]:
    """The take's marker labels named by ``spec`` (comma-separated names or fnmatch patterns such as ``root-*``, or a
    list of them), in take order. RigInputError (one sentence, naming the take ``where``) for a name the take does
    not have or fewer than 3."""
    from fnmatch import fnmatchcase
    items = [x.strip() for x in (spec.split(",") if isinstance(spec, str) else spec) if x.strip()]
    chosen, absent = set(), []
    for item in items:
        hits = [lab for lab in labels if fnmatchcase(lab, item)]
        if not hits:
            absent.append(item)
        chosen.update(hits)
    if absent:
        raise RigInputError(f"{where or 'take'}: the stable markers {', '.join(absent[:6])} are not in the take "
                            f"(it has {', '.join(labels[:6])}{'…' if len(labels) > 6 else ''}).")
    found = [lab for lab in labels if lab in chosen]
    if len(found) < 3:
        raise RigInputError(f"{where or 'take'}: head motion needs at least 3 stable markers, but "
                            f"'{', '.join(items)}' names "
                            f"{len(found)} ({', '.join(found) or 'none'}).")
    return found


def read_take(path: str | Path, rig: Rig | None = None, *, rate: float | None = None) -> MarkerTake | WeightTake:
    """Open a marker take (C3D, TRC, CSV), or a weight take on ``rig``'s shapes: a Live Link Face CSV (its ARKit
    columns mapped by ``model.livelink.default_arkit_mapping``) or a weights CSV (``frame,time,<shapes>``).
    ``rate``: the frame rate of a take whose file gives none (``model.takes.load_take``).
    Raises RigInputError (one sentence naming the file) for anything unreadable."""
    from .livelink import is_livelink_csv, read_livelink_csv
    from .take_data import rate_not_used
    from .takes import load_take
    from .weights_csv import is_weights_csv, read_weights_take
    path = Path(path)
    try:
        if path.suffix.lower() == ".csv" and path.is_file():
            for is_kind, read, what in ((is_livelink_csv, read_livelink_csv, "a Live Link Face take"),
                                        (is_weights_csv, partial(read_weights_take, rate=rate), "a weights CSV")):
                if is_kind(path):
                    if rig is None:
                        raise RigInputError(f"{path}: open a rig before playing {what} on it.")
                    take = read(path, rig.shape_names)
                    take.warnings += rate_not_used(path, take.rate, rate)   # a rate of its own: the file's kept
                    return take
        return load_take(path, rate=rate)
    except RigInputError:
        raise
    except (OSError, ValueError) as exc:
        raise RigInputError(f"{path}: could not be read ({exc}).") from None


def regional_solve_options(segmentation, level: int) -> dict:
    """The solver's ``regions`` and ``blend`` for a per-region solve on ``level`` of a segmentation
    (``model.segmentation``), and the regions of the levels above it (``coarser_regions``, finest first, without
    the top one-region level, which is the global solve) for the coarse-to-fine solve; RigInputError when there is
    none or the level does not exist."""
    if segmentation is None:
        raise RigInputError("A per-region solve needs a segmentation: segment the rig first.")
    n = len(segmentation.levels)
    if not 0 <= level < n:
        raise RigInputError(f"Level {level} does not exist: the segmentation has levels 0 to {n - 1}.")
    lvl = segmentation.levels[level]
    coarser = [[r.vertices for r in segmentation.levels[up].regions] for up in range(level + 1, n - 1)]
    return {"regions": [r.vertices for r in lvl.regions], "blend": lvl.blend, "coarser_regions": coarser}


def solve_take(rig: Rig, take: MarkerTake, marker_map: MarkerMap, *, evaluator: PoseEvaluator | None = None,
               progress: Progress = None, cancel=None, calibration_frames: int = DEFAULTS["calibration_frames"],
               neutral=None, stable=None, prepared: dict | None = None, **options) -> TakeSolution:
    """Solve a marker take onto a rig with a marker map (``solvers.take_solve.TakeSolver``).

    Uses the take's and rig's units; markers of the map missing from the take are dropped, and so are markers
    missing in most frames (``MOSTLY_MISSING``; listed in ``solution.left_out`` with the reason). ``neutral``: the
    actor's neutral frames (None: the first ``calibration_frames``, 'auto', or (first, last)); ``stable``: names or
    patterns of the markers the head motion is taken from (``resolve_stable``); those the map does not bind (a head
    band) are used as rigid head markers. The rig's live (unmuted) correctives are solved with the shapes, and every
    dense frame is the rig's pose evaluation (``evaluator``: a float64 ``PoseEvaluator`` of ``rig``, built here if
    not given) plus the residual. ``options`` go to ``TakeSolver``, their lengths physical (cm, and cm² for the
    λ's: ``solvers.take_solve.DEFAULTS``) whatever the rig's units, converted here (``model.units``) so that the
    same face solves alike in m, cm or mm. The solution's marker columns follow
    ``marker_map.match(take)`` without the markers left out. ``prepared``: the solver's per-rig preparation kept
    across takes of this rig (``TakeSolver``'s ``prepared``; a batch worker keeps one)."""
    labels, cols = marker_map.match(take)
    missing = np.isnan(take.positions).any(axis=2).mean(axis=0)               # (take markers,) fraction
    keep = missing[cols] <= MOSTLY_MISSING
    left_out = {lab: f"missing in {100 * missing[take.labels.index(lab)]:.0f}% of the frames"
                for lab, k in zip(labels, keep) if not k}
    labels, cols = [lab for lab, k in zip(labels, keep) if k], cols[keep]
    if len(labels) < 3:
        raise RigInputError(f"{take.source or 'The take'}: only {len(labels)} mapped markers are seen in most "
                            "frames; a solve needs at least 3.")
    stable_mask, head_cols = None, []
    if stable:
        names = resolve_stable(take.labels, stable, take.source)
        stable_mask = np.array([lab in names for lab in labels])
        head_cols = [take.labels.index(lab) for lab in names
                     if lab not in marker_map.markers and missing[take.labels.index(lab)] <= MOSTLY_MISSING]
        if int(stable_mask.sum()) + len(head_cols) < 3:
            raise RigInputError(f"Head motion needs at least 3 stable markers seen in most frames, but "
                                f"'{stable}' finds {int(stable_mask.sum()) + len(head_cols)}.")
    for i, lab in enumerate(take.labels):
        if lab not in marker_map.markers and i not in head_cols:
            left_out.setdefault(lab, f"missing in {100 * missing[i]:.0f}% of the frames" if missing[i] > MOSTLY_MISSING
                                else "not in the marker map")
    binding = marker_map.binding(rig, labels)
    options = take_solver_options(options, rig.units)      # physical lengths (cm, cm²) -> the rig's units
    from .antagonists import pair_indices, solve_pairs
    pairs = solve_pairs(rig, options)
    if pairs is not None:
        options["antagonists"] = pair_indices(rig, pairs)
    if evaluator is None or evaluator.dtype != np.float64:
        evaluator = PoseEvaluator(rig, dtype=np.float64)
    surface = partial(evaluator.pose, blend=options.get("blend"))
    many = evaluator.evaluate_many if options.get("blend") is None else None
    from .shape_weights import live_mask
    live = live_mask(rig)     # muted (and unsoloed) shapes do not explain markers: their weights go to 0
    deltas = rig.deltas if live.all() else rig.deltas * live[:, None, None]
    solver = TakeSolver(rig.neutral, deltas, binding, correctives=solver_correctives(rig), surface=surface,
                        surface_many=many, prepared=prepared, **options)
    try:
        sol = solver.solve(take.positions[:, cols], unit_factor=unit_scale(take.units, rig.units),
                           calibration_frames=calibration_frames, calibrate=calibration_frames > 0,
                           neutral=neutral, stable=stable_mask,
                           head_markers=take.positions[:, head_cols] if head_cols else None,
                           progress=progress, cancel=cancel)
    except ValueError as exc:
        text = str(exc)
        raise RigInputError(f"{take.source or 'The take'}: {text[:1].lower()}{text[1:]}") from None
    sol.labels = labels
    sol.left_out = left_out
    sol.head_labels = [take.labels[c] for c in head_cols]
    if sol.region_weights is not None:
        # one weight per shape for the weights CSV and a DCC (the background row alone is the first, global pass:
        # on the shared take it is 0.075 mm RMS from the regional surface, the fit 0.020)
        from solvers.surface_fit import global_weights_of_regional
        sol.fitted_weights = global_weights_of_regional(deltas, solver.blend, sol.region_weights,
                                                        lower=solver.lower, upper=solver.upper)
    return sol


def _settings_options(settings: dict) -> dict:
    """The solver options ``settings`` give (``SOLVER_OPTIONS``), the defaults for those they leave out."""
    return {k: settings[k] if settings.get(k) is not None else DEFAULTS[k] for k in SOLVER_OPTIONS}


def prepare_solver(rig: Rig, marker_map: MarkerMap, settings: dict) -> dict:
    """``solve_take``'s ``prepared`` made before any take, for takes that carry every marker of ``marker_map``
    solved with ``settings``: the residual's preparation (``solvers.take_solve.residual_preparation``: the
    vertices it moves, the phantom ring and the kernel matrix; ~10 ms on ICT; not its evaluation matrix, which is
    made where it is used: on ICT it is 12 MB, a third of the rig's deltas, made in ~12 ms in a fresh process). A
    batch makes it once, with its job, and sends it to every worker with the job, instead of each worker's first take
    making it again; a take without some of the map's markers makes its own."""
    options = take_solver_options(_settings_options(settings), rig.units)
    rest = marker_rest(rig.neutral, marker_map.binding(rig, marker_map.labels))
    prepared: dict = {}
    residual = {k: options[k] for k in ("residual", "rbf_scale", "rbf_lambda", "phantom_distance")}
    residual_preparation(np.asarray(rig.neutral, dtype=np.float64), rest, prepared=prepared, **residual)
    return prepared


def _head_and_options(settings: dict, take: MarkerTake) -> tuple[bool, int, dict]:
    """(fixed head, calibration frames, solver options without the regions) of ``settings`` on ``take``.
    A one-frame take (a keyframe) has no neutral frames to calibrate on and no motion to follow: its markers
    are taken as already in rig space, and temporal smoothness has no neighbour to act on."""
    options = _settings_options(settings)
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
    fixed_head, calibration, options = _head_and_options(settings, take)
    if not fixed_head:
        options["neutral"] = parse_neutral_frames(settings.get("neutral_frames"))
        options["stable"] = settings.get("stable") or None
    if settings.get("mode", "global") == "region":
        options.update(regional_solve_options(segmentation, int(settings.get("level", 0))))
    if settings.get("antagonists") is not None:   # the project's edited pairs ("A+B" or (A, B)); else the rig's
        options["antagonists"] = list(settings["antagonists"])
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
    left_out = sol.left_out or {}
    head = list(sol.head_labels or [])
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
        "markers_left_out": [lab for lab in take.labels if lab not in used and lab not in head],
        "markers_left_out_why": {lab: left_out.get(lab, "not in the marker map")
                                 for lab in take.labels if lab not in used and lab not in head},
        "head_markers": head,
        "neutral_frames": [int(x) for x in sol.neutral_frames] if sol.neutral_frames is not None else None,
        "neutral_frames_how": ("the most neutral stretch: nearest the rig's neutral after a similarity "
                               f"({sol.neutral_reason['distance_to_rig_neutral']:.2f} of the take's median) and "
                               f"still ({sol.neutral_reason['stillness']:.2f} of the median motion)"
                               if sol.neutral_reason else
                               "fixed head: none" if fixed_head else
                               "no calibration (calibration frames 0): the markers taken as the rig's own face"
                               if sol.neutral_frames is None else "as chosen"
                               if settings.get("neutral_frames") else "the first calibration frames"),
        "motion_explained": clean([sol.motion_explained])[0],
        "motion_explained_per_marker": dict(zip(labels, clean(sol.motion_explained_per_marker)))
        if sol.motion_explained_per_marker is not None else {},
        "mode": "regional" if settings.get("mode") == "region" else "global",
        "level": int(settings["level"]) if settings.get("mode") == "region" else None,
        "head": "fixed" if fixed_head else "solved",
        "options": {k: options[k] for k in SOLVER_OPTIONS},
        "residual": options["residual"],
        "correctives": [c.name for c in rig.correctives if not c.muted],   # solved with the shapes
        # the project's edited antagonist pairs ("A+B"), or None: the pairs found from the rig
        "antagonists": None if settings.get("antagonists") is None else
        [p if isinstance(p, str) else "+".join(p) for p in settings["antagonists"]],
        "warnings": list(take.warnings),     # what the take's reader decided (a file cut short, labels renamed)
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
        """(F, K) weights to play or export, one per shape: the weight take's or the solve's (a regional solve's
        fitted to its surface: ``TakeSolution.shape_weights``); None before either."""
        if isinstance(self.take, WeightTake):
            return self.take.weights
        return self.solution.shape_weights if self.solution is not None else None

    def load_take(self, path: str | Path, rate: float | None = None) -> MarkerTake | WeightTake:
        take = read_take(path, self.rig, rate=rate)
        self.take, self.take_path, self.solution = take, Path(path), None
        return take

    def prepare_solve(self, path: str | Path, marker_map: MarkerMap | None, settings: dict,
                      check_outputs: Callable[[TakeWorkspace], None] | None = None) -> bool:
        """What ``solve`` and ``batch`` do with a take file before solving it: load it, then map its markers with
        ``marker_map`` (markers the take lacks are warnings, not a refusal) or automatically from its neutral
        frames (``settings``' ``calibration_frames``, ``neutral_frames`` and ``stable``; checked against the take
        first: ``check_take_calibration``). False for a weight take (Live Link Face, weights CSV): it has nothing
        to solve, it plays on the rig as it is. ``settings``' ``rate``: the frame rate of a take whose file gives
        none (``read_take``). ``check_outputs(self)``: called once the take is read, before any mapping or solving
        (what its outputs will take: ``model.take_exports.check_solve_output_space``)."""
        self.load_take(path, settings.get("rate"))
        if check_outputs is not None:
            check_outputs(self)
        if self.marker_take is None:
            return False
        if self.rig.n_shapes == 0:      # nothing to solve for (and automatic mapping maps onto what the shapes move)
            raise RigInputError(f"{self.rig.source or self.rig.name}: the rig has no shapes to solve the take's "
                                "markers with.")
        check_take_calibration(self.take, settings)
        if marker_map is not None:
            self.set_map(marker_map, strict=False)
        else:
            self.auto_map(settings.get("calibration_frames", DEFAULTS["calibration_frames"]),
                          neutral_frames=settings.get("neutral_frames"), stable=settings.get("stable"))
        return True

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

    def auto_map(self, calibration_frames: int = DEFAULTS["calibration_frames"], *, neutral_frames=None,
                 stable=None) -> float:
        """Map the take's markers onto the rig (``find_auto_map``) and use that map; returns the fit RMS (rig
        units)."""
        mm, rms = self.find_auto_map(calibration_frames, neutral_frames=neutral_frames, stable=stable)
        self.marker_map, self.solution = mm, None
        return rms

    def find_auto_map(self, calibration_frames: int = DEFAULTS["calibration_frames"], *, neutral_frames=None,
                      stable=None) -> tuple[MarkerMap, float]:
        """(map, fit RMS in rig units): the take's markers mapped onto the rig from its neutral frames (the first
        ``calibration_frames``, a range or 'auto': ``parse_neutral_frames``) and re-fitted from its motion, without
        changing the workspace (seconds of work: the GUI runs it in the background). ``stable``
        (``resolve_stable``) is checked first so that a bad list is refused before any work; stable markers off
        the face (a head band) and markers never seen in the neutral are not mapped."""
        if self.marker_take is None or self.rig is None:
            raise RigInputError("Load a marker take (and open a rig) before mapping its markers.")
        if stable:
            resolve_stable(self.take.labels, stable, self.take.source)
        take, n = self.take, max(1, int(calibration_frames))
        neutral = parse_neutral_frames(neutral_frames)
        frames: int | slice = n
        if isinstance(neutral, tuple):
            if not 0 <= neutral[0] <= neutral[1] < take.n_frames:
                raise RigInputError(f"{take.source or 'The take'}: the neutral frames {neutral[0]}:{neutral[1]} "
                                    f"(--neutral-frames) are outside the take, which has frames 0 to "
                                    f"{take.n_frames - 1}.")
            frames = slice(neutral[0], neutral[1] + 1)
        elif neutral == "auto":
            # a first map from the whole take finds the most neutral stretch, which is then mapped again
            from solvers.retarget import neutral_stretch
            mm, _ = auto_marker_map(self.rig, take, calibration_frames=slice(None), refine=0)
            labels, cols = mm.match(take)
            rest = mm.binding(self.rig, labels) @ self.rig.neutral
            a, b, _ = neutral_stretch(take.positions[:, cols] * unit_scale(take.units, self.rig.units), rest, n)
            frames = slice(a, b + 1)
        mm, info = auto_marker_map(self.rig, take, calibration_frames=frames)
        return mm, float(info.get("rms", float("nan")))

    def set_rig(self, rig: Rig) -> list[str]:
        """A new rig: the solution goes, a weight take is mapped onto the new shapes and the marker map
        is checked again; what no longer fits is dropped. Returns one sentence per thing dropped."""
        self.rig, self.solution = rig, None
        dropped = []
        if isinstance(self.take, WeightTake) and self.take_path is not None:
            given = None if self.take.rate_from_file else self.take.rate   # a rate given for an untimed file stays
            try:
                self.take = read_take(self.take_path, rig, rate=given)
            except RigInputError as exc:
                self.take = self.take_path = None
                dropped.append(f"The weight take does not fit this rig: {exc}")
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
              progress: Progress = None, cancel=None, antagonists: list | None = None,
              prepared: dict | None = None) -> TakeSolution:
        """Solve the take with ``settings`` (see the module docstring); ``segmentation`` for a per-region solve;
        ``antagonists`` the pairs ``model.antagonists.solve_pairs`` already found for these settings and rig (a
        batch finds them once), not a setting: the report still says whose pairs they are; ``prepared`` the
        solver's per-rig preparation kept across takes (``solve_take``). Keeps and returns the solution
        (``solvers.take_solve.SolveCancelled`` propagates)."""
        self.check_ready()
        solution = self.solve_detached(settings, segmentation=segmentation, evaluator=evaluator,
                                       progress=progress, cancel=cancel, antagonists=antagonists, prepared=prepared)
        self.accept(solution, settings)
        return solution

    def solve_detached(self, settings: dict, *, segmentation=None, evaluator=None, progress=None,
                       cancel=None, antagonists: list | None = None, prepared: dict | None = None) -> TakeSolution:
        """``solve`` without keeping the result (for a worker thread; ``accept`` keeps it)."""
        options, calibration = solver_options(settings, self.take, segmentation)
        if antagonists is not None and options.get("antagonists") is None:
            options["antagonists"] = antagonists
        try:
            return solve_take(self.rig, self.take, self.marker_map, evaluator=evaluator, progress=progress,
                              cancel=cancel, calibration_frames=calibration, prepared=prepared, **options)
        except RigInputError:       # already one sentence naming the file
            raise
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
