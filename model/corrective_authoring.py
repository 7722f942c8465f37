"""Authoring correctives (Smith 2006 §5.6–5.8): the surface a corrective is made on, and a corrective made from a
scan. These pose the rig (``model.pose``), so they live apart from ``model.correctives``, which the pose
evaluation itself uses (activation rules and the corrective list)."""
from __future__ import annotations

import numpy as np

from .correctives import RULES, Corrective, activation_for, find_corrective
from .errors import RigInputError
from .pose import PoseEvaluator


def driver_pose(rig, drivers, weights=None) -> np.ndarray:
    """(K,) weight vector with the drivers at ``weights`` (a number, a list, or None for 1) and others 0."""
    w = np.zeros(rig.n_shapes)
    vals = np.ones(len(drivers)) if weights is None else np.broadcast_to(np.asarray(weights, float), (len(drivers),))
    for d, v in zip(drivers, vals):
        w[rig.shape_index(d)] = v
    return w


def authoring_surface(rig, drivers, weights=None, evaluator=None) -> tuple[np.ndarray, np.ndarray]:
    """The current surface ``x_cur`` (V, 3) float64 for authoring a corrective on ``drivers``, and its pose.

    The drivers are set to ``weights`` (default 1) and every other shape to 0; every corrective already
    on the rig except the one for this exact driver set is applied, muted or not. Correctives of the same or
    higher order on other driver sets contain a driver at 0 and so add exactly 0, which leaves every
    lower-order corrective applied, as Smith's authoring step requires: ``e_c = (x_des − x_cur) / a_c(w)``.

    ``evaluator``: the rig's float64 ``model.pose.PoseEvaluator`` (the document keeps one); built here if not
    given (about 0.3 s on ICT FaceKit). Returns (x_cur, w).
    """
    drivers = list(drivers)
    if len(drivers) < 2:
        raise RigInputError(f"A corrective needs two or more driver shapes, got {len(drivers)}.")
    w = driver_pose(rig, drivers, weights)
    return _pose_without(rig, drivers, w, evaluator), w


def _pose_without(rig, drivers, w, evaluator=None) -> np.ndarray:
    """(V, 3) float64 pose ``w`` of ``rig`` with every corrective, muted or not, except the one on ``drivers``."""
    if evaluator is None or evaluator.dtype != np.float64:
        evaluator = PoseEvaluator(rig, dtype=np.float64)
    own = find_corrective(rig.correctives, drivers)
    return np.asarray(evaluator.evaluate(w, exclude=[own.name] if own is not None else (), include_muted=True),
                      dtype=np.float64)


SCAN_MIN_ACTIVATION = 1e-3   # a fitted scan whose corrective fires less than this does not show the combination


def corrective_from_scan(rig, drivers, scan, rule: str = "product", *, fit: bool = False, name: str = "",
                         source: str = "the scan", evaluator=None) -> tuple[Corrective, np.ndarray]:
    """The corrective of ``drivers`` made from a scan (V, 3) in the rig's vertex order (Smith §5.6; future work 1),
    and the pose it was made at: what the GUI's "From scan…" and the ``corrective`` command both do.

    ``fit`` False: the scan is the drivers at 1, ``e = (scan − x_cur) / a`` (``authoring_surface``). ``fit``
    True: the scan is a free performance: fit all weights (bounded least squares), keep the residual over the
    drivers' region (``solvers.correctives.corrective_from_scan``). ``source`` names the scan in messages.
    Raises RigInputError (one sentence) for bad drivers or rule, a scan of another vertex count or with NaN,
    and a fitted scan in which the combination does not fire.
    """
    from solvers.correctives import corrective_delta, driver_region, fit_scan_weights
    from solvers.correctives import corrective_from_scan as residual_corrective
    drivers = [str(d).strip() for d in drivers if str(d).strip()]
    if len(drivers) < 2:
        raise RigInputError(f"A corrective needs two or more driver shapes, got {len(drivers)}.")
    idx = [rig.shape_index(d) for d in drivers]
    if rule not in RULES:
        raise RigInputError(f"'{rule}' is an unknown rule for a corrective; use one of {', '.join(RULES)}.")
    scan = np.asarray(scan, dtype=np.float64)
    if scan.ndim != 2 or scan.shape != rig.neutral.shape:
        raise RigInputError(f"{source} has {scan.shape[0] if scan.ndim else 0} vertices but the rig has "
                            f"{rig.n_vertices}; a scan must have the rig's vertices in the same order.")
    if not np.isfinite(scan).all():
        raise RigInputError(f"{source} has NaN or infinite coordinates.")
    if fit:
        w = fit_scan_weights(rig.neutral, rig.deltas, scan)
        a = activation_for(drivers, rule, rig.shape_names, w)
        if a < SCAN_MIN_ACTIVATION:
            raise RigInputError(f"{source} does not show {' + '.join(drivers)}: the fitted weights leave the "
                                f"corrective's activation at {a:.2g}.")
        x_fit = _pose_without(rig, drivers, w, evaluator)
        delta = residual_corrective(scan, x_fit, driver_region(rig.deltas[idx]), a)
    else:
        x_cur, w = authoring_surface(rig, drivers, evaluator=evaluator)
        delta = corrective_delta(scan, x_cur, activation_for(drivers, rule, rig.shape_names, w))
    return Corrective(name=name, drivers=drivers, rule=rule, delta=delta), w
