"""How close a rig comes to the actor of ``mocap/actor_take`` (shared data README): the two measurements of
issue 15's personalisation target, kept in one place so that a change of the take-solve API touches one line.

``dense_error_solved``: solve the take with its marker map on the rig (``model.take_workspace.solve_take``)
and compare the dense head-stabilised result with ``truth_dense_face.npz`` over its ``moving`` vertices.
``dense_error_true_weights``: pose the rig with ``truth_weights.csv`` (no solve) and compare the same way.
``weights_error_solved``: the take solved on the rig, its weights against ``truth_weights.csv`` (RMS over every
frame and shape the truth names).
Both: RMS distance per frame over the moving vertices, averaged over the truth's frames, in rig units. With
``within`` (rig units) only the moving vertices that near a marker (the face the markers cover) are measured.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np


def truth(take_dir: Path):
    z = np.load(take_dir / "truth_dense_face.npz")
    with open(take_dir / "truth_weights.csv") as fh:
        rows = list(csv.reader(fh))
    names = rows[0][1:]
    table = np.array([[float(v) for v in r] for r in rows[1:]])
    return z["frames"].astype(int), z["positions"].astype(np.float64), z["moving"].astype(int), names, table


def _rms(surfaces, positions, moving) -> float:
    return float(np.mean([np.sqrt(((x[moving] - p[moving]) ** 2).sum(axis=1).mean())
                          for x, p in zip(surfaces, positions)]))


def dense_error_true_weights(rig, take_dir: Path) -> float:
    """The rig posed with the true weights against the actor's true face (rig units)."""
    frames, positions, moving, names, table = truth(take_dir)
    idx = [rig.shape_index(n) for n in names]
    rows = {int(f): i for i, f in enumerate(table[:, 0])}
    n = positions.shape[1]
    surfaces = []
    for f in frames:
        w = np.zeros(rig.n_shapes)
        w[idx] = table[rows[int(f)], 1:]
        surfaces.append(rig.neutral[:n] + np.tensordot(w, rig.deltas[:, :n], 1))
    return _rms(surfaces, positions, moving)


def covered(rig, take_dir: Path, within: float) -> np.ndarray:
    """The truth's moving vertices within ``within`` (rig units) of one of the marker map's points on ``rig``."""
    from scipy.spatial import cKDTree
    from model.marker_map import load_marker_map
    mm = load_marker_map(take_dir / "marker_map.json")
    moving = truth(take_dir)[2]
    d, _ = cKDTree(mm.binding(rig) @ rig.neutral).query(rig.neutral[moving])
    return moving[d < within]


def dense_error_solved(rig, take_dir: Path, *, within: float | None = None, placed: bool = False):
    """The take solved on the rig with its marker map, dense result against the actor's true face (rig units);
    with ``within``, the pair (all moving vertices, those within ``within`` of a marker: ``covered``). With
    ``placed`` the rig's neutral is first put where the actor's is (one rigid transform, Kabsch, from the rig's
    neutral to ``actor_neutral.obj`` over the vertices measured, applied to every frame): for a rig built from a
    take alone, whose markers cannot say where the actor's face sits in the truth's frame."""
    from model.marker_map import load_marker_map
    from model.obj_io import read_obj
    from model.takes import load_take
    from model.take_workspace import solve_take
    from solvers.rigid import kabsch
    frames, positions, moving, _, _ = truth(take_dir)
    sol = solve_take(rig, load_take(take_dir / "take.c3d"), load_marker_map(take_dir / "marker_map.json"))
    n = positions.shape[1]
    surfaces = [sol.dense(int(f))[:n] for f in frames]
    actor = read_obj(take_dir / "actor_neutral.obj").vertices[:n]

    def error(vertices):
        if not placed:
            return _rms(surfaces, positions, vertices)
        R, t = kabsch(rig.neutral[vertices], actor[vertices])
        return _rms((x @ R.T + t for x in surfaces), positions, vertices)
    if within is None:
        return error(moving)
    return error(moving), error(covered(rig, take_dir, within))


def weights_error_solved(rig, take_dir: Path) -> float:
    """The take solved on the rig with its marker map: RMS of its weights minus the true weights (every frame, every
    shape ``truth_weights.csv`` names)."""
    from model.marker_map import load_marker_map
    from model.takes import load_take
    from model.take_workspace import solve_take
    _, _, _, names, table = truth(take_dir)
    sol = solve_take(rig, load_take(take_dir / "take.c3d"), load_marker_map(take_dir / "marker_map.json"))
    W = sol.shape_weights[:, [rig.shape_index(n) for n in names]]
    assert W.shape == table[:, 1:].shape and (table[:, 0] == np.arange(len(table))).all()
    return float(np.sqrt(((W - table[:, 1:]) ** 2).mean()))
