"""An actor's own rig from a template rig (Ma et al. 2016 §3; ALGORITHMS.md §9; issue 15 item 5).

``personalize_rig`` takes a template rig and measurements of the actor — a neutral scan, pose scans (the
rig's topology, actor space, rig units, weights unknown) and/or a marker take — and returns a new rig with
the same shape names, presets and correctives (the correctives re-based onto the actor by the same
deformation transfer as the shapes, with no data: they keep their drivers, rule and mute state).

* Scans (the main path): the neutral is the neutral scan (or, without one, re-estimated from the pose
  scans by the row of ones of Ma's W); the deltas are refined by ``solvers.personalize.personalize``.
* A marker take alone: the template neutral is aligned to the actor's neutral markers (the mean of the
  calibration frames). The actor's markers are placed rigidly on the rig's marker points (Kabsch: the actor's
  face where the rig's is, at the actor's size), the template is scaled to them by the similarity (Umeyama 1991)
  and bent onto them by the thin-plate surface warp (``solvers.surface_warp``: smooth over the surface, so a
  lower-lip marker does not pull the upper lip as the Euclidean Gaussian RBF used before did); the deltas are
  the template's transferred onto that neutral (the deformation-gradient and closeness terms of Ma's energy, no
  data term). Scaling the template
  about the rig's origin instead put the face 5.5 mm from the actor's (a placement, not a shape, error).

``shape_change_report`` measures how far each shape moved from the template (for the CLI's report and the
GUI's heat map, ``solvers.personalize.shape_change``).
"""
from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np

from solvers.personalize import LAM_D, LAM_R, PersonalizeResult, ShapeChange, personalize, shape_change

from .errors import RigInputError
from .input_files import regular_file
from .rig import Rig
from .units import length

# How far a marker's displacement carries over the surface (cm, ℓ of ``solvers.surface_warp``): measured on
# actor_take, the moving face 2.61 / 2.52 / 2.67 mm from the truth at 6 / 10 / 14 cm (a Gaussian RBF of 3 cm: 3.2)
WARP_LENGTH = 10.0


def scan_paths(items) -> list[Path]:
    """Files and folders (every ``*.obj`` inside, sorted by name) as a list of OBJ paths."""
    out: list[Path] = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            found = sorted(regular_file(q) for q in p.iterdir() if q.suffix.lower() == ".obj")   # none passed over
            if not found:
                raise RigInputError(f"{p}: the folder holds no .obj scans.")
            out.extend(found)
        else:
            out.append(p)
    return out


def _checked_scan(points, where: str, rig: Rig) -> np.ndarray:
    a = np.asarray(points, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] != rig.n_vertices:
        n = a.shape[0] if a.ndim == 2 else a.size // 3
        raise RigInputError(f"{where}: has {n} vertices but the rig has {rig.n_vertices}; a scan must have the "
                            "rig's vertices in the rig's order (wrap it to the rig first).")
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise RigInputError(f"{where}: vertex {int(np.flatnonzero(bad)[0])} has NaN or infinite coordinates "
                            f"({int(bad.sum())} vertices in all); a scan must measure every vertex.")
    return a


def read_scan(scan, rig: Rig, label: str = "scan") -> np.ndarray:
    """(V, 3) vertices of a scan given as an OBJ path or an array, checked against the rig."""
    if isinstance(scan, (str, Path)):
        from .obj_io import read_obj
        return _checked_scan(read_obj(scan).vertices, str(scan), rig)
    return _checked_scan(scan, label, rig)


def neutral_frames_of(take, calibration_frames: int = 30, neutral_frames=None,
                      where: str = "--neutral-frames") -> tuple[int, int]:
    """(first, last), counted from 0 and inclusive: the take's frames the actor's neutral is read from -- the chosen
    range ``neutral_frames`` ('A:B' or a pair, as the solve's ``--neutral-frames``; the Mocap panel's "Use This
    Frame as Neutral") or else the first ``calibration_frames``. RigInputError (one sentence) for 'auto' or a range
    outside the take."""
    from .take_workspace import parse_neutral_frames
    neutral = parse_neutral_frames(neutral_frames, where)
    name, F = take.source or "The take", take.n_frames
    if neutral == "auto":
        raise RigInputError(f"{where}: personalising takes the actor's neutral as a frame range A:B, not 'auto'.")
    if neutral is None:
        if not 1 <= calibration_frames <= F:
            raise RigInputError(f"{name}: has {F} frames; --calibration-frames {calibration_frames} must be 1 to {F} "
                                "(the actor's neutral frames at its start).")
        return 0, int(calibration_frames) - 1
    a, b = neutral
    if not 0 <= a <= b < F:
        raise RigInputError(f"{name}: the neutral frames {a}:{b} ({where}) are outside the take, which has frames 0 "
                            f"to {F - 1}.")
    return a, b


def _marker_neutral(rig: Rig, take, marker_map, calibration_frames: int = 30,
                    neutral_frames=None) -> tuple[np.ndarray, dict]:
    """The template neutral rigidly aligned, scaled and surface-warped onto the actor's neutral markers (the mean of
    the frames ``neutral_frames_of`` gives)."""
    from solvers.rigid import kabsch, umeyama
    from solvers.surface_warp import biharmonic_warp

    from .marker_map import auto_marker_map, calibration_cloud

    first, last = neutral_frames_of(take, calibration_frames, neutral_frames)
    frames = slice(first, last + 1)
    if marker_map is None:
        marker_map, _ = auto_marker_map(rig, take, calibration_frames=frames)
    marker_map.validate(rig, take)
    labels, cols = marker_map.match(take)
    binding = marker_map.binding(rig, labels)
    cloud = calibration_cloud(take, frames, rig.units)[cols]
    rest = binding @ rig.neutral
    R, t = kabsch(cloud, rest)                       # rest ≈ R cloud + t
    aligned = cloud @ R.T + t                        # the actor's markers placed rigidly on the rig's, size kept
    s, Rs, ts = umeyama(rest, aligned, scale=True)   # aligned ≈ s Rs rest + ts
    base = s * rig.neutral @ Rs.T + ts               # the template at the actor's size and place (the whole head)
    moved = s * rest @ Rs.T + ts
    neutral = base + biharmonic_warp(base, rig.triangles(), binding, aligned - moved,
                                     length=s * length(WARP_LENGTH, rig.units))
    fit = float(np.sqrt(((binding @ neutral - aligned) ** 2).sum(axis=1).mean()))
    return neutral, {"markers": len(labels), "marker_fit": fit, "scale": float(s), "neutral_frames": [first, last]}


def personalize_rig_detailed(rig: Rig, neutral_scan=None, scans=(), take=None, marker_map=None, *,
                             calibration_frames: int = 30, neutral_frames=None, name: str | None = None,
                             progress=None, **options) -> tuple[Rig, PersonalizeResult, dict]:
    """``personalize_rig`` returning also the solver's result and a JSON-able summary. A take's neutral is the mean of
    its frames ``neutral_frames`` ('A:B' or (first, last), inclusive, counted from 0; the summary's
    ``neutral_frames``), or of its first ``calibration_frames``. ``progress``: called with each stage reached (the
    actor's neutral, shape k/K of the solve, the correctives), one short phrase."""
    def say(stage: str) -> None:
        if progress is not None:
            progress(stage)
    scans = list(scans or [])
    if neutral_scan is None and not scans and take is None:
        raise RigInputError("personalize needs measurements of the actor: a neutral scan, pose scans or a "
                            "marker take; none was given.")
    if scans and take is not None:
        raise RigInputError("personalize takes pose scans or a marker take, not both: the take is for an "
                            "actor without pose scans.")
    if rig.n_shapes == 0:
        raise RigInputError(f"{rig.source or rig.name}: the rig has no shapes to personalise.")
    n_scans = len(scans) + (neutral_scan is not None)
    if n_scans:
        say(f"reading {n_scans} scan{'s' if n_scans != 1 else ''}")
    neutral = None if neutral_scan is None else read_scan(neutral_scan, rig, "the neutral scan")
    poses = np.stack([read_scan(s, rig, f"scan {i + 1}") for i, s in enumerate(scans)]) if scans \
        else np.zeros((0, rig.n_vertices, 3))
    summary: dict = {"scans": len(scans), "neutral": "scan" if neutral is not None else "template"}
    if take is not None and neutral is None:
        say("the actor's neutral from the take's markers")
        neutral, info = _marker_neutral(rig, take, marker_map, calibration_frames, neutral_frames)
        summary.update(neutral="warped to the take's neutral markers", **info)
    elif neutral is None:
        summary["neutral"] = "re-estimated from the pose scans"
    triangles = rig.triangles()
    result = personalize(rig.neutral, rig.deltas, triangles, poses, neutral, progress=progress, **options)

    def carried(deltas: list) -> np.ndarray:
        """Offsets that are not fitted to scans (correctives, in-betweens) carried onto the actor's face."""
        return personalize(rig.neutral, np.stack(deltas), triangles, np.zeros((0, rig.n_vertices, 3)),
                           result.neutral, lam_r=options.get("lam_r", LAM_R), lam_d=options.get("lam_d", LAM_D)).deltas
    correctives = []
    live = [c for c in rig.correctives]
    if live:
        say(f"carrying {len(live)} corrective{'s' if len(live) != 1 else ''} onto the actor")
        correctives = [dataclasses.replace(c, delta=d) for c, d in zip(live, carried([c.delta for c in live]))]
    inbetweens = {}
    items = [(n, ib) for n, v in rig.inbetweens.items() for ib in v]
    if items:   # the shape list's in-betweens move to the actor as the correctives do
        from .rig import Inbetween
        for (n, ib), d in zip(items, carried([ib.delta for _, ib in items])):
            inbetweens.setdefault(n, []).append(Inbetween(ib.weight, d))
    out = Rig(neutral=result.neutral, face_counts=rig.face_counts.copy(), face_indices=rig.face_indices.copy(),
              shape_names=list(rig.shape_names), deltas=result.deltas, units=rig.units,
              name=name or f"{rig.name}_actor", source="", correctives=correctives,
              presets={k: dict(v) for k, v in rig.presets.items()}, inbetweens=inbetweens,
              muted=list(rig.muted), solo=list(rig.solo), ranges=dict(rig.ranges),
              corners=copy.deepcopy(rig.corners), materials=dict(rig.materials))   # the same faces: UVs, parts
    summary.update(unknowns=result.unknowns, seconds=round(result.seconds, 3),
                   delta_seconds=[round(s, 3) for s in result.delta_seconds],
                   delta_cpu_seconds=[round(s, 3) for s in result.delta_cpu_seconds], cg_iterations=result.cg_iterations,
                   fit_rms=[float(f) for f in result.fit_rms], units=rig.units)
    return out, result, summary


def personalize_rig(rig: Rig, neutral_scan=None, scans=(), take=None, marker_map=None, **options) -> Rig:
    """The actor's own rig (module docstring): same shape names, presets and correctives as ``rig``.

    neutral_scan: an OBJ path or (V, 3) array of the actor's neutral in the rig's topology; scans: OBJ
    paths or (V, 3) arrays of the actor's poses; take: a ``model.takes.MarkerTake`` of the actor with its
    ``marker_map`` (or None: mapped automatically). ``options`` go to ``solvers.personalize.personalize``.
    The caller writes the new project."""
    return personalize_rig_detailed(rig, neutral_scan, scans, take, marker_map, **options)[0]


def shape_change_report(template: Rig, actor: Rig) -> tuple[ShapeChange, list[dict]]:
    """Per-shape change of ``actor`` against ``template`` (same shapes): the ShapeChange (with its (K, V)
    heat map) and rows {shape, rms, max, relative} sorted by rms, largest first."""
    if template.shape_names != actor.shape_names or template.n_vertices != actor.n_vertices:
        raise RigInputError("the rigs to compare have different shapes or vertex counts.")
    ch = shape_change(template.deltas, actor.deltas)
    rows = [{"shape": n, "rms": float(ch.rms[k]), "max": float(ch.max[k]), "relative": float(ch.relative[k])}
            for k, n in enumerate(template.shape_names)]
    rows.sort(key=lambda r: -r["rms"])
    return ch, rows
