"""What a worked take exports (``model.take_workspace.TakeWorkspace``), without Qt: the per-frame weights as a CSV,
every frame's surface as a PC2 point cache, and the solve report as JSON. The GUI's Mocap panel and the command
line's ``solve`` call these. Each raises RigInputError (one sentence) when there is nothing to export.
"""
from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

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
    """Every frame's surface: the solve's dense result (head-stabilised, rig units), or the rig posed by the
    weight take (``evaluator``, the rig's pose evaluation)."""
    if workspace.solution is not None:
        return workspace.solution.iter_dense()
    if isinstance(workspace.take, WeightTake):
        ev = evaluator if evaluator is not None else PoseEvaluator(workspace.rig, dtype=np.float64)
        return (ev.evaluate(w) for w in workspace.take.weights)
    raise RigInputError("Nothing to export: solve a marker take or load a Live Link Face take first.")


def export_pc2(workspace, path: str | Path, frames: Iterable[np.ndarray] | None = None,
               evaluator: PoseEvaluator | None = None) -> None:
    """Every frame's surface (``take_surfaces``, or ``frames`` already computed) as a PC2 point cache."""
    from .pc2 import write_pc2
    frames = take_surfaces(workspace, evaluator) if frames is None else frames
    write_pc2(path, frames, n_points=workspace.rig.n_vertices, start_frame=0, sample_rate=1.0)


def export_report(workspace, path: str | Path) -> dict:
    """The solve report (``TakeWorkspace.report``) as JSON; returns it."""
    from .atomic import atomic_write
    report = workspace.report()
    atomic_write(path, (json.dumps(report, indent=1) + "\n").encode("utf-8"))
    return report


def export_solve_outputs(workspace, weights_path: str | Path, cache_path: str | Path | None = None,
                         report_path: str | Path | None = None) -> dict:
    """The weights CSV, and optionally the PC2 cache and the report, written as one set
    (``model.output_set``): a solve killed while writing leaves either all the old files or all the new ones.
    Returns the report."""
    from .output_set import write_set
    from .pc2 import pc2_writer
    from .weights_csv import weights_csv_bytes
    W = workspace.playing_weights()
    if W is None:
        raise RigInputError("Nothing to export: solve a marker take or load a Live Link Face take first.")
    report = workspace.report()
    csv_bytes = weights_csv_bytes(weights_path, W, list(workspace.rig.shape_names), rate=workspace.rate)
    writers = {weights_path: lambda f: f.write(csv_bytes)}
    if cache_path:
        writers[cache_path] = pc2_writer(cache_path, take_surfaces(workspace), n_points=workspace.rig.n_vertices,
                                         start_frame=0, sample_rate=1.0)[0]
    if report_path:
        text = (json.dumps(report, indent=1) + "\n").encode("utf-8")
        writers[report_path] = lambda f: f.write(text)
    write_set(writers)
    return report
