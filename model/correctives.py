"""Corrective shapes for shapes in superposition (ALGORITHMS.md §6; Smith 2006 §4.5, §5.6–5.8).

A corrective ``e_c`` (V, 3) belongs to a set of two or more driver shapes and is added to the surface
with an activation ``a_c(w)`` computed from the drivers' weights (ALGORITHMS.md §1):
``x(w) = b0 + Σ_k w_k d_k + Σ_c a_c(w) e_c``.

Activation rules, for the drivers ``s_0, ..., s_{n-1}`` of a corrective taken in the *rig's shape order*
(ascending index in ``rig.shape_names``, so the result does not depend on how the user listed them):

``product``       a = Π_m w_{s_m}  (Maya "multiplication").
``hierarchical``  Smith §4.5: a pair is ``a_ij = w_i · w_j``; a corrective of order n > 2 multiplies the
                  activations of two correctives of order n − 1 of the same set: the one that drops the
                  *last* driver and the one that drops the *first* driver,
                  ``a_{s_0..s_{n-1}} = a_{s_0..s_{n-2}} · a_{s_1..s_{n-1}}`` (so ``a_ijk = a_ij · a_jk`` and
                  ``a_ijkl = a_ijk · a_jkl``). With these lower-order activations themselves hierarchical
                  (products of weights at order two) the recursion has the closed form
                  ``a = Π_m w_{s_m} ^ C(n−1, m)`` (binomial exponents: 1,1 / 1,2,1 / 1,3,3,1 ...), which is
                  what is evaluated. A three-way fix therefore fires only when all three drivers are on and
                  grows more slowly than the pair fixes beneath it.
``min``           a = min_m w_{s_m}  (Maya "lowest weighting").
``smooth-min``    Maya's "lowest weighting smooth", defined here as the power mean with exponent −p,
                  ``a = ( (1/n) Σ_m w_{s_m}^(−p) )^(−1/p)`` with p = 4 (``SMOOTH_MIN_POWER``), and a = min_m w
                  when any w ≤ 0. It lies between the lowest and the highest weight, equals w when all
                  drivers are at the same weight w (so 1 when all are 1), tends to 0 as any driver tends
                  to 0 (it is exactly 0 when a driver is 0), and is smooth where two driver weights
                  cross, unlike ``min``.

Every rule is 0 when any driver is 0 and 1 when all drivers are 1.

Evaluation order is by order (number of drivers), then as added: authoring a corrective of order n sees
every corrective of lower order already applied (Smith §5.6–5.8). ``rig.correctives`` is kept in this
order by ``set_correctives`` / ``add_corrective``.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import comb

import numpy as np

from .errors import RigInputError, repeated

RULES = ("product", "hierarchical", "min", "smooth-min")
SMOOTH_MIN_POWER = 4.0


@dataclass(kw_only=True)
class Corrective:
    """A corrective shape: name, driver shape names (2 or more), activation rule, delta (V, 3) float64.

    The name defaults to the drivers joined by '+', e.g. ``browInnerUp_L+browInnerUp_R``. A ``muted``
    corrective (Blender's mute, Maya's target visibility) adds nothing to the evaluated surface and exports;
    its activation is still computed, and authoring still counts it as a lower order.
    """

    drivers: list[str]
    delta: np.ndarray
    rule: str = "product"
    name: str = ""
    muted: bool = False

    def __post_init__(self) -> None:
        self.drivers = [str(d) for d in self.drivers]
        if not self.name:
            self.name = "+".join(self.drivers)
        self.delta = np.ascontiguousarray(self.delta, dtype=np.float64)
        if self.delta.ndim != 2 or self.delta.shape[1] != 3:
            raise RigInputError(f"Corrective '{self.name}': its delta must be a (V, 3) array of 3D offsets.")
        if not np.isfinite(self.delta).all():
            raise RigInputError(f"Corrective '{self.name}': its delta has NaN or infinite values.")
        if self.rule not in RULES:
            raise RigInputError(f"Corrective '{self.name}': unknown rule '{self.rule}'; use one of "
                                f"{', '.join(RULES)}.")
        if len(self.drivers) < 2:
            raise RigInputError(f"Corrective '{self.name}': needs two or more driver shapes, "
                                f"got {len(self.drivers)}.")
        dup = repeated(self.drivers)
        if dup:
            raise RigInputError(f"Corrective '{self.name}': driver listed more than once: {', '.join(dup)}.")

    @property
    def order(self) -> int:
        """Number of drivers (2 for a pair, 3 for a three-way corrective, ...)."""
        return len(self.drivers)

    def copy(self) -> "Corrective":
        return Corrective(drivers=list(self.drivers), delta=self.delta.copy(), rule=self.rule, name=self.name,
                          muted=self.muted)

    # --- project file ----------------------------------------------------------------------------
    def to_dict(self, delta_key: str) -> dict:
        """Manifest entry (JSON); the delta itself is stored as the .npy array ``delta_key``."""
        return {"name": self.name, "drivers": list(self.drivers), "rule": self.rule, "muted": self.muted,
                "delta": delta_key}

    @classmethod
    def from_entry(cls, entry: dict, delta_of) -> "Corrective":
        """Rebuild from a manifest entry; ``delta_of(key)`` returns the stored delta array (a missing key raises
        KeyError). Entries written before correctives could be muted are not muted."""
        try:
            delta = delta_of(entry["delta"])
            return cls(name=str(entry.get("name", "")), drivers=list(entry["drivers"]),
                       rule=str(entry.get("rule", "product")), delta=delta, muted=bool(entry.get("muted", False)))
        except KeyError as e:
            raise RigInputError(f"Corrective entry {entry.get('name', '?')!r} in the project is missing {e}.") from None


# --- validation and order -----------------------------------------------------------------------
def validate_correctives(correctives, shape_names, n_vertices: int | None = None) -> None:
    """Raise RigInputError (one sentence) unless the correctives form a consistent set for this rig.

    Checks: every driver is a shape of the rig (a corrective cannot be driven by a corrective: that
    would make the hierarchy depend on itself), no duplicate names, no two correctives with the same
    driver set, no corrective named like a shape, delta vertex count.
    """
    names = set(shape_names)
    seen_names: dict[str, Corrective] = {}
    seen_sets: dict[frozenset, str] = {}
    corr_names = {c.name for c in correctives}
    for c in correctives:
        for d in c.drivers:
            if d not in names:
                if d == c.name:
                    raise RigInputError(f"Corrective '{c.name}' lists itself as a driver (a cycle).")
                if d in corr_names:
                    raise RigInputError(f"Corrective '{c.name}' is driven by corrective '{d}'; drivers must be "
                                        "shapes of the rig, so the hierarchy cannot form a cycle.")
                raise RigInputError(f"Corrective '{c.name}': the rig has no shape named '{d}'.")
        if c.name in names:
            raise RigInputError(f"Corrective '{c.name}' has the same name as a shape of the rig.")
        if c.name in seen_names:
            raise RigInputError(f"Two correctives are named '{c.name}'.")
        key = frozenset(c.drivers)
        if key in seen_sets:
            raise RigInputError(f"Correctives '{seen_sets[key]}' and '{c.name}' have the same drivers; "
                                "keep one corrective per driver set.")
        seen_names[c.name] = c
        seen_sets[key] = c.name
        if n_vertices is not None and c.delta.shape[0] != n_vertices:
            raise RigInputError(f"Corrective '{c.name}' has {c.delta.shape[0]} vertices but the rig has "
                                f"{n_vertices}.")


def evaluation_order(correctives) -> list:
    """The correctives sorted by order (number of drivers), stable: lower orders come first."""
    return sorted(correctives, key=lambda c: c.order)


def set_correctives(rig, correctives) -> None:
    """Validate ``correctives`` against ``rig`` and store them on it in evaluation order."""
    correctives = list(correctives)
    validate_correctives(correctives, rig.shape_names, rig.n_vertices)
    rig.correctives = evaluation_order(correctives)


def add_corrective(rig, corrective: Corrective, *, replace: bool = True) -> None:
    """Add (or, with ``replace``, replace the one with the same driver set) and keep evaluation order."""
    key = frozenset(corrective.drivers)
    kept = [c for c in rig.correctives if not (replace and frozenset(c.drivers) == key)]
    set_correctives(rig, kept + [corrective])


def find_corrective(correctives, drivers) -> Corrective | None:
    """The corrective with exactly this driver set, or None."""
    key = frozenset(drivers)
    for c in correctives:
        if frozenset(c.drivers) == key:
            return c
    return None


# --- activations --------------------------------------------------------------------------------
def rule_activation(rule: str, driver_weights: np.ndarray) -> np.ndarray:
    """Activation of one rule for driver weights (..., n) given in the rig's shape order -> (...)."""
    W = np.asarray(driver_weights, dtype=np.float64)
    n = W.shape[-1]
    if n < 2:
        raise RigInputError(f"A corrective needs two or more drivers, got {n}.")
    if rule == "product":
        return np.prod(W, axis=-1)
    if rule == "hierarchical":
        exps = np.array([comb(n - 1, m) for m in range(n)], dtype=np.float64)
        return np.prod(W ** exps, axis=-1)
    if rule == "min":
        return W.min(axis=-1)
    if rule == "smooth-min":
        lo = W.min(axis=-1)
        pos = lo > 0
        safe = np.where(pos[..., None], W, 1.0)
        p = SMOOTH_MIN_POWER
        pm = np.mean(safe ** (-p), axis=-1) ** (-1.0 / p)
        return np.where(pos, pm, lo)
    raise RigInputError(f"Unknown corrective rule '{rule}'; use one of {', '.join(RULES)}.")


@lru_cache(maxsize=64)
def _plan(spec: tuple, shape_names: tuple) -> dict:
    """Index arrays that evaluate every corrective at once on (U, K) weights (see the module docstring).

    ``prod_idx``/``prod_mask`` (S, C): the product rules as a product over S factor slots, each driver
    repeated by its exponent (1 for 'product', C(n−1, m) for 'hierarchical'); unused slots count as 1.
    ``min_idx`` (n_max, C): the drivers, padded with the first one (which leaves a minimum unchanged).
    """
    index = {n: i for i, n in enumerate(shape_names)}
    factors, drivers, rules, orders = [], [], [], []
    for name, drv, rule in spec:
        try:
            idx = sorted(index[d] for d in drv)
        except KeyError as e:
            raise RigInputError(f"Corrective '{name}': the rig has no shape named {e}.") from None
        if rule not in RULES:
            raise RigInputError(f"Corrective '{name}': unknown rule '{rule}'.")
        n = len(idx)
        if rule == "hierarchical":
            factors.append([i for m, i in enumerate(idx) for _ in range(comb(n - 1, m))])
        elif rule == "product":
            factors.append(idx)
        else:
            factors.append([])
        drivers.append(idx)
        rules.append(rule)
        orders.append(n)
    C = len(spec)
    S = max(len(f) for f in factors)
    prod_idx = np.zeros((S, C), dtype=np.intp)
    prod_mask = np.zeros((S, C), dtype=bool)
    for c, f in enumerate(factors):
        prod_idx[:len(f), c] = f
        prod_mask[:len(f), c] = True
    n_max = max(orders)
    min_idx = np.array([d + [d[0]] * (n_max - len(d)) for d in drivers], dtype=np.intp).T
    rules = np.array(rules)
    smooth = np.flatnonzero(rules == "smooth-min")
    return {"prod_idx": prod_idx, "prod_mask": prod_mask, "min_idx": min_idx,
            "is_prod": np.isin(rules, ("product", "hierarchical")), "smooth": smooth,
            "smooth_idx": min_idx[:, smooth], "smooth_n": np.array(orders, float)[smooth],
            "smooth_mask": (np.arange(n_max)[:, None] < np.array(orders)[None, smooth])}


def _spec(correctives) -> tuple:
    return tuple((c.name, tuple(c.drivers), c.rule) for c in correctives)


def corrective_activations(correctives, shape_names, weights) -> np.ndarray:
    """(C,) activations a_c(w) of the correctives (in their list order) for a global weight vector (K,).

    Smith 2006 §4.5 (hierarchical) and Maya's combination rules; see the module docstring.
    """
    w = np.asarray(weights, dtype=np.float64).reshape(1, -1)
    return corrective_activations_per_vertex(correctives, shape_names, w)[0]


def corrective_activations_per_vertex(correctives, shape_names, per_vertex_weights) -> np.ndarray:
    """(U, C) activations from per-vertex blended weights (U, K) (regional poses, Joshi §4 + Smith §4.5).

    All correctives are evaluated together: a few (U, C) array operations, whatever C and the rules.
    """
    W = np.asarray(per_vertex_weights, dtype=np.float64)
    if W.ndim != 2 or W.shape[1] != len(shape_names):
        raise RigInputError(f"Expected weights for {len(shape_names)} shapes, got an array of shape {W.shape}.")
    if not correctives:
        return np.zeros((W.shape[0], 0))
    plan = _plan(_spec(correctives), tuple(shape_names))
    prod = np.ones((W.shape[0], len(correctives)))
    for idx, mask in zip(plan["prod_idx"], plan["prod_mask"]):
        prod *= np.where(mask, W[:, idx], 1.0)
    lowest = W[:, plan["min_idx"][0]]
    for idx in plan["min_idx"][1:]:
        np.minimum(lowest, W[:, idx], out=lowest)
    out = np.where(plan["is_prod"], prod, lowest)
    sm = plan["smooth"]
    if sm.size:
        acc = np.zeros((W.shape[0], sm.size))
        lo = lowest[:, sm]
        pos = lo > 0
        for idx, mask in zip(plan["smooth_idx"], plan["smooth_mask"]):
            v = np.where(pos & mask, W[:, idx], 1.0)
            acc += np.where(mask, v ** -SMOOTH_MIN_POWER, 0.0)
        pm = (acc / plan["smooth_n"]) ** (-1.0 / SMOOTH_MIN_POWER)
        out[:, sm] = np.where(pos, pm, lo)
    return out


def corrective_activation(corrective: Corrective, shape_names, weights) -> float:
    """a_c(w) of one corrective for a global weight vector (K,)."""
    return float(corrective_activations([corrective], shape_names, weights)[0])


def solver_correctives(rig):
    """The rig's live (unmuted) correctives for a solver on plain arrays (``solvers.take_solve.TakeSolver``):
    (activate, E, drivers) with activate (U, K) weights -> (U, C) activations, E (C, V, 3) their deltas and
    drivers the shape indices they depend on; None when the rig has no live corrective."""
    live = [c for c in rig.correctives if not c.muted]
    if not live:
        return None
    names = list(rig.shape_names)

    def activate(weights: np.ndarray) -> np.ndarray:
        return corrective_activations_per_vertex(live, names, weights)
    drivers = sorted({names.index(d) for c in live for d in c.drivers})
    return activate, np.stack([np.asarray(c.delta, dtype=np.float64) for c in live]), drivers


def activation_for(drivers, rule: str, shape_names, weights) -> float:
    """a_c(w) of a (not yet created) corrective on ``drivers`` with ``rule``, for a global pose (K,)."""
    probe = Corrective(drivers=list(drivers), rule=rule, delta=np.zeros((0, 3)))
    return corrective_activation(probe, shape_names, weights)


# --- mirroring ----------------------------------------------------------------------------------
def mirrored_corrective(corrective: Corrective, shape_names, neutral, mirror=None, *, units: str = "") -> Corrective:
    """The other side's version of ``corrective`` (browInnerUp_L+browOuterUp_L → browInnerUp_R+browOuterUp_R):
    drivers renamed left↔right (``model.sides``), delta reflected across x = 0 through the vertex mirror map
    (``solvers.correctives.mirror_delta``), same rule. ``mirror`` is the map if already computed.

    Raises RigInputError (one sentence) when the drivers mirror onto themselves, when the rig lacks a mirrored
    driver, or when the rig is not symmetric where the corrective acts.
    """
    from solvers.symmetry import mirror_delta, mirror_map
    from .sides import check_mirrorable, mirror_drivers, mirror_name

    c = corrective
    drivers = mirror_drivers(c.drivers)
    if set(drivers) == set(c.drivers):
        raise RigInputError(f"{c.name} is its own mirror image: its drivers mirror onto themselves.")
    missing = [d for d in drivers if d not in set(shape_names)]
    if missing:
        raise RigInputError(f"Cannot mirror {c.name}: the rig has no shape named "
                            f"{', '.join(repr(d) for d in missing)}.")
    neutral = np.asarray(neutral, dtype=np.float64)
    m = mirror_map(neutral) if mirror is None else np.asarray(mirror)
    check_mirrorable(c.name, c.delta, neutral, m, units)
    if c.name == "+".join(c.drivers):
        name = "+".join(drivers)
    else:
        name = "+".join(mirror_name(t) for t in c.name.split("+"))
        if name == c.name:
            name = "+".join(drivers)
    return Corrective(name=name, drivers=drivers, rule=c.rule, delta=mirror_delta(c.delta, m))


def why_not_mirrored(corrective: Corrective | None, shape_names) -> tuple[str | None, str | None]:
    """(why Mirror cannot act on ``corrective``, why Symmetrize cannot), each one sentence or None when it can, from
    its drivers alone (the rig's symmetry where it acts is checked when it is done): Mirror needs drivers of one side
    whose other side the rig has, Symmetrize drivers that mirror onto themselves."""
    from .sides import mirror_drivers

    if corrective is None:
        none = "Select a corrective in the list first."
        return none, none
    c = corrective
    drivers = mirror_drivers(c.drivers)
    if set(drivers) == set(c.drivers):
        return (f"{c.name} is its own mirror image (its drivers mirror onto themselves): Symmetrize makes it "
                "symmetric.", None)
    one_side = (f"{c.name} acts on one side: Mirror makes its other side; only a corrective whose drivers mirror "
                "onto themselves can be made symmetric.")
    missing = [d for d in drivers if d not in set(shape_names)]
    if missing:
        return (f"Cannot mirror {c.name}: the rig has no shape named {', '.join(repr(d) for d in missing)}.",
                one_side)
    return None, one_side


def symmetrized_corrective(corrective: Corrective, neutral, mirror=None, *, units: str = "") -> Corrective:
    """A corrective whose drivers mirror onto themselves (browInnerUp_L+browInnerUp_R, mouthFunnel+jawOpen) made
    exactly symmetric across x = 0: e' = (e + M e∘m) / 2, the mean of the shape and its mirror image (Maya's
    Symmetrize Target). Raises RigInputError for a one-sided corrective (use ``mirrored_corrective``) or a rig
    that is not symmetric where the corrective acts."""
    from solvers.symmetry import mirror_delta, mirror_map
    from .sides import check_mirrorable, mirror_drivers

    c = corrective
    if set(mirror_drivers(c.drivers)) != set(c.drivers):
        raise RigInputError(f"{c.name} acts on one side: Mirror makes its other side; only a corrective whose "
                            "drivers mirror onto themselves can be made symmetric.")
    neutral = np.asarray(neutral, dtype=np.float64)
    m = mirror_map(neutral) if mirror is None else np.asarray(mirror)
    check_mirrorable(c.name, c.delta, neutral, m, units)
    return Corrective(name=c.name, drivers=list(c.drivers), rule=c.rule, muted=c.muted,
                      delta=0.5 * (c.delta + mirror_delta(c.delta, m)))
