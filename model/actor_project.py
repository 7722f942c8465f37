"""The actor's project (issue 15): a template rig personalised to an actor (``model.personalize``) written as a new
project that keeps the template's project (its settings, take, markers, keyframes, antagonist pairs) and records how
far each shape moved, per vertex, for the heat map. Qt-free: the window runs it in a child process
(``app.personalize_job``), the tests call it directly.

Section ``personalize``: ``{"template", "shapes", "units", "summary", "rows"}``; array ``personalize/change``:
(K, V) float32, ``‖d_k(v) − d*_k(v)‖`` in the rig's units.
"""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from .atomic import write_error
from .errors import RigInputError
from .rig import unit_scale

SECTION = "personalize"          # project section: {"template", "shapes", "units", "summary"}
CHANGE = "personalize/change"    # project array: (K, V) float32 change per vertex, rig units


def personalize_project(template, project_state: dict, request: dict, progress=None):
    """The actor's project from ``template`` (a Rig, not the live one) and the dialog's ``request`` (Qt-free: runs on
    a worker thread). ``project_state``: {weights, sections, arrays, antagonists, template} carried into the new
    project. Writes ``request['output']`` and returns (path, summary, rows of ``shape_change_report`` in mm).
    ``progress``: called with each stage reached, one short phrase (``personalize_rig_detailed``'s and the
    writing's)."""
    def say(stage: str) -> None:
        if progress is not None:
            progress(stage)
    from .personalize import personalize_rig_detailed, scan_paths
    from .project import Project, save_project

    out = Path(request["output"])
    scans = scan_paths(request.get("scans") or [])
    take = marker_map = None
    if request.get("take"):
        say("reading the take")
        from .take_workspace import read_take
        from .takes import MarkerTake
        take = read_take(request["take"])
        if not isinstance(take, MarkerTake):
            raise RigInputError(f"{request['take']}: is a weight take ({take.file_format}), not marker trajectories.")
        if request.get("marker_map"):
            from .marker_map import load_marker_map
            marker_map = load_marker_map(request["marker_map"])
    elif request.get("marker_map"):
        raise RigInputError("A marker map needs a marker take to go with it.")
    actor, _, summary = personalize_rig_detailed(template, request.get("neutral_scan"), scans, take, marker_map,
                                                 calibration_frames=int(request.get("calibration_frames") or 30),
                                                 neutral_frames=request.get("neutral_frames") if take else None,
                                                 name=out.stem, progress=progress)
    say("writing the actor's project")
    sections = copy.deepcopy(project_state.get("sections") or {})
    arrays = dict(project_state.get("arrays") or {})
    rows = record_change(sections, arrays, template, actor, summary, project_state.get("template") or template.name)
    weights = project_state.get("weights")
    project = Project(rig=actor, weights=None if weights is None or len(weights) != actor.n_shapes else weights,
                      sections=sections, arrays=arrays, antagonists=project_state.get("antagonists"))
    try:
        save_project(project, out)
    except OSError as exc:
        raise write_error(out, exc) from None
    return out, summary, rows


def record_change(sections: dict, arrays: dict, template, actor, summary: dict, template_label: str) -> list[dict]:
    """Put how far ``actor``'s shapes moved from ``template``'s into a project's ``sections`` and ``arrays`` (what the
    heat map shows); returns the rows of ``shape_change_report`` with lengths in mm."""
    from .personalize import shape_change_report
    change, rows = shape_change_report(template, actor)
    mm = unit_scale(template.units, "mm")
    rows = [dict(r, rms=r["rms"] * mm, max=r["max"] * mm) for r in rows]
    sections[SECTION] = {"template": template_label, "shapes": list(actor.shape_names), "units": actor.units,
                         "summary": _jsonable(summary), "rows": rows}
    arrays[CHANGE] = change.per_vertex.astype(np.float32)
    return rows


def _jsonable(summary: dict) -> dict:
    out = {}
    for k, v in summary.items():
        if isinstance(v, (str, int, float, bool)) or v is None:
            out[k] = v
        elif isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) for x in v):
            out[k] = [float(x) for x in v]
    return out


def change_rows(section: dict, change: np.ndarray) -> list[dict]:
    """{shape, rms, max, relative} (mm) per shape of a saved change, largest RMS first: the rows saved with it, or
    measured again from the (K, V) change when they are missing or damaged."""
    names = section["shapes"]
    saved = section.get("rows")
    if isinstance(saved, list) and len(saved) == len(names) and all(
            isinstance(r, dict) and r.get("shape") in names and all(
                isinstance(r.get(k), (int, float)) and not isinstance(r.get(k), bool) for k in ("rms", "max", "relative"))
            for r in saved):
        return sorted(saved, key=lambda r: -r["rms"])
    mm = unit_scale(section.get("units", "cm"), "mm")
    rows = []
    for k, name in enumerate(names):
        c = change[k].astype(np.float64)
        moved = c[c > 0]
        rms = float(np.sqrt((moved ** 2).mean())) if moved.size else 0.0
        rows.append({"shape": name, "rms": rms * mm, "max": float(c.max(initial=0.0)) * mm, "relative": 0.0})
    rows.sort(key=lambda r: -r["rms"])
    return rows
