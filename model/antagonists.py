"""A rig's antagonist pairs (ALGORITHMS.md §13), by name: derived from the rig (``solvers.antagonists``) less the
pairs that real faces use together.

``ALLOWED_TOGETHER`` was measured on the shared takes (../shared/data/mocap, the Live Link Face performance on
ICT FaceKit): of the pairs the rule finds on ICT (cosine < −0.5 over a shared support of at least half the
smaller shape's), these are both above 0.2 in some frame of the true weights, so forbidding them loses real poses.
ARKit's mouthClose is made to be used with jawOpen (lips shut while the jaw drops; the performance holds both at
0.5): every pair with mouthClose is allowed, on any rig. A rig's list can be edited (``antagonists`` in the solve
settings: a list of "A+B" names).
"""
from __future__ import annotations

import weakref

import numpy as np

from solvers.antagonists import antagonist_pairs
from solvers.take_solve import DEFAULTS

from .errors import RigInputError

ALLOWED_TOGETHER = frozenset(frozenset(p.split("+")) for p in (
    "eyeLookDown_L+eyeSquint_L", "eyeLookDown_R+eyeSquint_R", "jawForward+jawOpen", "jawForward+mouthRollLower",
    "jawForward+mouthRollUpper", "jawOpen+mouthPucker", "mouthDimple_L+mouthFunnel", "mouthDimple_R+mouthFunnel",
    "mouthFrown_L+mouthPucker", "mouthFrown_R+mouthPucker", "mouthFrown_L+mouthUpperUp_L",
    "mouthFrown_R+mouthUpperUp_R", "mouthFrown_L+noseSneer_L", "mouthFrown_R+noseSneer_R",
    "mouthFunnel+mouthRollLower", "mouthFunnel+mouthRollUpper", "mouthFunnel+mouthStretch_L",
    "mouthFunnel+mouthStretch_R", "mouthLowerDown_L+noseSneer_L", "mouthLowerDown_R+noseSneer_R",
    "mouthPucker+mouthRollLower", "mouthPucker+mouthRollUpper", "mouthPucker+mouthStretch_L",
    "mouthPucker+mouthStretch_R"))
TOGETHER_BY_DESIGN = ("mouthClose",)


_FOUND: tuple | None = None   # (a weak reference to the deltas last asked about, their pairs by index)


def rig_antagonists(rig) -> list[tuple[str, str]]:
    """The rig's antagonist pairs as (name, name), most opposed first.

    The pairs of the last deltas asked about are kept while those deltas live (an edit replaces a rig's arrays,
    never changes them): a marker drag's press and every take solve in the window ask again (0.3 s each on the
    106k-vertex, 228-shape studio rig)."""
    global _FOUND
    names = rig.shape_names
    hit = _FOUND
    if hit is None or hit[0]() is not rig.deltas:
        hit = _FOUND = (weakref.ref(rig.deltas), antagonist_pairs(rig.deltas))
    out = []
    for i, j, _ in hit[1]:
        a, b = names[i], names[j]
        if frozenset((a, b)) in ALLOWED_TOGETHER or a in TOGETHER_BY_DESIGN or b in TOGETHER_BY_DESIGN:
            continue
        out.append((a, b))
    return out


def solve_pairs(rig, options: dict) -> list | None:
    """The pairs a take solve with ``options`` keeps apart, by name: the options' own ``antagonists`` (a project's
    edited list), else the rig's (``rig_antagonists``, about 0.07 s on ICT) while the penalty ``lam_antagonist``
    is on; None when there are none to keep apart."""
    if options.get("antagonists") is not None:
        return list(options["antagonists"])
    if options.get("lam_antagonist", DEFAULTS["lam_antagonist"]):
        return rig_antagonists(rig)
    return None


def pair_indices(rig, pairs) -> list[tuple[int, int]]:
    """Shape index pairs for (name, name) pairs or "A+B" strings; RigInputError naming an unknown shape."""
    out = []
    for p in pairs:
        a, b = p.split("+") if isinstance(p, str) else p
        for n in (a, b):
            if n not in rig.shape_names:
                raise RigInputError(f"The antagonist pair {a}+{b} names {n}, which the rig does not have.")
        out.append((rig.shape_names.index(a), rig.shape_names.index(b)))
    return out


def strong_pairs(W: np.ndarray, pairs: list[tuple[int, int]], level: float = 0.2) -> list[tuple[int, int, int]]:
    """(i, j, frames) of the pairs with both weights above ``level`` in some row of W (F, K) (or (K,))."""
    W = np.atleast_2d(W)
    out = []
    for i, j in pairs:
        n = int(((W[:, i] > level) & (W[:, j] > level)).sum())
        if n:
            out.append((i, j, n))
    return out
