"""What a worked take exports (``model.take_workspace.TakeWorkspace``), without Qt: the per-frame weights as a CSV,
every frame's surface as a PC2 point cache, the rig animated by the weights as glTF, and the solve report as JSON.
A marker take exports its solve; a weight take (Live Link Face or a weights CSV, already on the rig's shapes)
exports the same files from its own weights. The GUI's Mocap panel and the command line's ``solve`` call these.
Each raises RigInputError (one sentence) when there is nothing to export.
"""
from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from solvers.take_solve import DENSE_BLOCK

from .errors import RigInputError
from .pose import PoseEvaluator
from .takes import WeightTake


def export_weights_csv(workspace, path: str | Path) -> None:
    """Per-frame weights of the solve (or of the weight take) as ``frame,time,<rig shapes>``."""
    from .weights_csv import write_weights_csv
    W = workspace.playing_weights()
    if W is None:
        raise RigInputError("Nothing to export: solve a marker take or load a Live Link Face take first.")
    write_weights_csv(path, W, list(workspace.rig.shape_names), rate=workspace.rate)


def take_surfaces(workspace, evaluator: PoseEvaluator | None = None) -> Iterable[np.ndarray]:
    """Every frame's surface, in blocks of frames (n, V, 3): the solve's dense result (head-stabilised, rig
    units), or the rig posed by the weight take (``evaluator``, the rig's pose evaluation, as matrix products)."""
    if workspace.solution is not None:
        return workspace.solution.dense_blocks()     # (n, V, 3) float32 blocks: the PC2 writer takes them whole
    if isinstance(workspace.take, WeightTake):
        ev = evaluator if evaluator is not None else PoseEvaluator(workspace.rig, dtype=np.float64)
        W = workspace.take.weights
        return (ev.evaluate_many(W[i:i + DENSE_BLOCK]) for i in range(0, W.shape[0], DENSE_BLOCK))
    raise RigInputError("Nothing to export: solve a marker take or load a Live Link Face take first.")


def export_pc2(workspace, path: str | Path, frames: Iterable[np.ndarray] | None = None,
               evaluator: PoseEvaluator | None = None) -> None:
    """Every frame's surface (``take_surfaces``, or ``frames`` already computed) as a PC2 point cache."""
    from .pc2 import write_pc2
    frames = take_surfaces(workspace, evaluator) if frames is None else frames
    write_pc2(path, frames, n_points=workspace.rig.n_vertices, start_frame=0, sample_rate=1.0)


def weight_take_report(workspace) -> dict:
    """The report of a weight take played on the rig, JSON-ready: the keys of a solve report (README, "Solve
    report") with null where markers would have measured something, plus what the take drives: ``shapes_driven``
    (the rig's shapes the take moves: a weight other than 0 in some frame), ``unmapped`` (source columns that drive none), ``frames_filled``
    (frames the recording dropped, interpolated in time) and the reader's ``warnings``."""
    take, rig = workspace.take, workspace.rig
    driven = [n for n, on in zip(rig.shape_names, np.abs(take.weights).max(axis=0, initial=0.0) > 0) if on] \
        if take.n_frames else []
    return {"rig": rig.name, "take": str(workspace.take_path) if workspace.take_path else take.source,
            "kind": "weights", "frames": take.n_frames, "rate": float(take.rate), "rig_units": rig.units,
            "solve_seconds": 0.0, "frames_per_second": None, "marker_rmse": None, "motion_explained": None,
            "neutral_frames": None, "markers_left_out": [], "shapes_driven": driven, "unmapped": list(take.unmapped),
            "frames_filled": int(take.filled.sum()) if take.filled is not None else 0,
            "warnings": list(take.warnings), "correctives": [c.name for c in rig.correctives if not c.muted]}


def take_report(workspace) -> dict:
    """The report of what is loaded: the solve's (``TakeWorkspace.report``) or a weight take's."""
    if isinstance(workspace.take, WeightTake):
        return weight_take_report(workspace)
    return workspace.report()


def take_animation(workspace):
    """The weights to play as a ``model.export.WeightAnimation`` (frame k at k / rate seconds)."""
    from .export import WeightAnimation
    W = workspace.playing_weights()
    if W is None:
        raise RigInputError("Nothing to export: solve a marker take or load a Live Link Face take first.")
    return WeightAnimation(times=np.arange(W.shape[0]) / workspace.rate, weights=W,
                           source=str(workspace.take_path or ""))


def export_report(workspace, path: str | Path) -> dict:
    """The solve report (``TakeWorkspace.report``) as JSON; returns it."""
    from .atomic import atomic_write
    report = take_report(workspace)
    atomic_write(path, (json.dumps(report, indent=1) + "\n").encode("utf-8"))
    return report


def export_solve_outputs(workspace, weights_path: str | Path, cache_path: str | Path | None = None,
                         report_path: str | Path | None = None, gltf_path: str | Path | None = None) -> dict:
    """The weights CSV, and optionally the PC2 cache, the report and the rig animated by the weights as glTF
    (``.glb``/``.gltf``, metres, ``model.export``: correctives as extra targets driven by their activations),
    written as one set (``model.output_set``): a solve killed while writing leaves either all the old files or
    all the new ones. For a solved marker take or a weight take alike. Returns the report."""
    from .output_set import write_set
    writers, report = solve_output_writers(workspace, weights_path, cache_path, report_path, gltf_path)
    write_set(writers)
    return report


def check_solve_output_space(workspace, cache_path: str | Path | None = None,
                              gltf_path: str | Path | None = None) -> None:
    """Refuse, once the take is read and before it is solved, a PC2 cache (exactly its frames × the rig's vertices)
    or an animated glTF (at least its keys: ``model.export.export_size``) that its disk has no room for
    (``model.free_space``): a 200,000-frame take's cache of ICT is 64 GB."""
    from .export import export_size
    from .free_space import check_free_space
    from .pc2 import pc2_size
    frames, sizes = workspace.take.n_frames, {}
    if cache_path:
        sizes[cache_path] = pc2_size(frames, workspace.rig.n_vertices)
    if gltf_path:
        sizes[gltf_path] = export_size(workspace.rig, gltf_path, frames)
    check_free_space(sizes, lower_bounds=[gltf_path] if gltf_path else ())


def solve_output_writers(workspace, weights_path: str | Path, cache_path: str | Path | None = None,
                         report_path: str | Path | None = None, gltf_path: str | Path | None = None, *,
                         evaluator: PoseEvaluator | None = None) -> tuple[dict, dict]:
    """(``{path: writer(file)}`` of ``export_solve_outputs``' files, for ``model.output_set.write_set``; the
    report): what ``solve`` writes, which a batch's take writes too, with its preview. ``evaluator``: the rig's
    pose evaluation for a weight take's cache (``take_surfaces``)."""
    from .pc2 import pc2_writer
    from .weights_csv import weights_csv_bytes
    W = workspace.playing_weights()
    if W is None:
        raise RigInputError("Nothing to export: solve a marker take or load a Live Link Face take first.")
    report = take_report(workspace)
    csv_bytes = weights_csv_bytes(weights_path, W, list(workspace.rig.shape_names), rate=workspace.rate)
    writers = {weights_path: lambda f: f.write(csv_bytes)}
    if gltf_path:
        from .export import export_content
        from .export_gltf import gltf_bytes
        glb = gltf_bytes(export_content(workspace.rig, animation=take_animation(workspace)), gltf_path)
        writers[gltf_path] = lambda f: f.write(glb)
    if cache_path:
        writers[cache_path] = pc2_writer(cache_path, take_surfaces(workspace, evaluator),
                                         n_points=workspace.rig.n_vertices, start_frame=0, sample_rate=1.0)[0]
    if report_path:
        text = (json.dumps(report, indent=1) + "\n").encode("utf-8")
        writers[report_path] = lambda f: f.write(text)
    return writers, report
