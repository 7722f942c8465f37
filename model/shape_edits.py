"""Edits of a project's shape list, as Maya's Shape Editor and Blender's shape keys do them: reorder, sort,
group, rename, duplicate, delete (with the correctives that need the shape), mute, solo, slider ranges and
in-betweens. Qt-free: the GUI's undo commands (app.commands) and the tests call these.

What refers to shapes, and how each edit keeps it consistent:
- by index: the shape arrays (``rig.deltas``), the pose (``project.weights``, ``project.region_weights``) and
  the keyed animation (``project.arrays['keyframes/weights']``, last axis one entry per shape): reordered,
  deleted and inserted with the shapes.
- by name: correctives' drivers, presets, in-betweens, mute, solo and ranges: renamed with the shape, and
  their entries for a deleted shape removed (a corrective that needs a deleted shape is deleted with it).
Vertex order never changes. Every edit returns what undoes it exactly (bit for bit).
"""
from __future__ import annotations

import copy
import re
from dataclasses import dataclass, field

import numpy as np

from .errors import RigInputError, shown
from .rig import INBETWEEN_MAX_WEIGHT, MAX_WEIGHT, Inbetween, Rig
from .sides import mirror_name

SHAPE_AXIS_ARRAYS = ("keyframes/weights",)   # project arrays whose last axis has one entry per shape
DEFAULT_RANGE = (0.0, 1.0)

# --- groups and sorting ------------------------------------------------------------------------------------
_SIDES = ("Left", "Right", "Centre")


def shape_side(name: str) -> str:
    """'Left', 'Right' or 'Centre' from the name's side suffix (model.sides: _L/_R, .L/.R, Left/Right...)."""
    twin = mirror_name(name)
    if twin == name:
        return "Centre"
    from .sides import is_left
    return "Left" if is_left(name) else "Right"


def shape_prefix(name: str) -> str:
    """The first word of a shape name, lower case: the face part in ARKit/ICT names (browInnerUp_L → brow,
    eyeBlink_R → eye, mouthSmile_L → mouth, jawOpen → jaw, PupilDilate_L → pupil, brow.raise.L → brow)."""
    m = re.match(r"[A-Z]*[a-z0-9]*", name.lstrip("_.- "))
    word = m.group(0) if m and m.group(0) else name
    return word.lower()


def shape_groups(names: list[str], by: str = "prefix") -> list[tuple[str, list[int]]]:
    """[(group, shape indices in list order)] in order of first appearance (``by``: 'prefix' or 'side';
    sides always Left, Right, Centre)."""
    if by not in ("prefix", "side"):
        raise ValueError(f"unknown grouping {by!r}")
    key = shape_prefix if by == "prefix" else shape_side
    groups: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        groups.setdefault(key(n), []).append(i)
    items = list(groups.items())
    if by == "side":
        items.sort(key=lambda g: _SIDES.index(g[0]))
    return items


def sorted_order(names: list[str], by: str = "name") -> list[int]:
    """The new order (old indices) of the shapes sorted by name (case-insensitive, natural numbers) or by group
    (face part, then name)."""
    def natural(n: str):
        return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", n)]
    if by == "name":
        return sorted(range(len(names)), key=lambda i: natural(names[i]))
    if by == "group":
        return sorted(range(len(names)), key=lambda i: (shape_prefix(names[i]), natural(names[i])))
    raise ValueError(f"unknown sort {by!r}")


def moved_order(n: int, indices: list[int], step: int) -> list[int]:
    """The order after moving the shapes at ``indices`` up (step -1) or down (+1) by one place, keeping their
    relative order; a shape at the end stays (and the block moves as one)."""
    order = list(range(n))
    chosen = sorted(set(indices), reverse=step > 0)
    for i in chosen:
        pos = order.index(i)
        j = pos + step
        if 0 <= j < n and order[j] not in chosen:
            order[pos], order[j] = order[j], order[pos]
        elif not 0 <= j < n:
            return list(range(n))
    return order


def moved_to_order(n: int, indices: list[int], place: int) -> list[int]:
    """The order after moving the shapes at ``indices`` (keeping their relative order) to just before list
    position ``place`` (0..n, n: the end) of the current list -- a drag and drop in the list."""
    chosen = sorted(set(indices))
    rest = [i for i in range(n) if i not in set(chosen)]
    at = sum(1 for i in rest if i < place)
    return rest[:at] + chosen + rest[at:]


# --- what refers to shapes by index -----------------------------------------------------------------------
def _take(a: np.ndarray | None, idx: np.ndarray, axis: int = -1) -> np.ndarray | None:
    return None if a is None else np.take(a, idx, axis=axis)


def _check_order(order, n: int) -> np.ndarray:
    order = np.asarray(order, dtype=np.int64)
    if order.shape != (n,) or not np.array_equal(np.sort(order), np.arange(n)):
        raise ValueError(f"an order of {n} shapes must list each index once, got {order.tolist()}")
    return order


def hierarchical_conflicts(rig: Rig, order) -> list[str]:
    """Correctives whose surface the new order would change: the hierarchical rule of three or more drivers takes
    them in the rig's shape order (model.correctives), so reordering its drivers changes what it adds."""
    order = list(order)
    new_pos = {rig.shape_names[old]: new for new, old in enumerate(order)}
    bad = []
    for c in rig.correctives:
        if c.rule == "hierarchical" and len(c.drivers) >= 3:
            before = sorted(c.drivers, key=rig.shape_names.index)
            after = sorted(c.drivers, key=new_pos.__getitem__)
            if before != after and before != after[::-1]:   # the binomial exponents are symmetric
                bad.append(c.name)
    return bad


def reorder_check(rig: Rig, order) -> None:
    """Refuse an order that would change a hierarchical three-way corrective (``hierarchical_conflicts``)."""
    bad = hierarchical_conflicts(rig, order)
    if bad:
        raise RigInputError(f"This order would change the corrective {shown(', '.join(bad), 80)}: its hierarchical "
                            "rule takes its three or more drivers in list order. Move them together or keep their order.")


def reorder_shapes(project, order) -> list[int]:
    """Put the shapes in ``order`` (old indices, new position by position). Returns the order that undoes it."""
    rig = project.rig
    order = _check_order(order, rig.n_shapes)
    reorder_check(rig, order)
    rig.shape_names = [rig.shape_names[i] for i in order]
    rig.deltas = np.take(rig.deltas, order, axis=0)   # a new array: whatever kept the old one keeps it whole
    project.weights = project.weights[order]
    if project.region_weights is not None:
        project.region_weights = project.region_weights[:, order]
    for key in SHAPE_AXIS_ARRAYS:
        if key in project.arrays:
            project.arrays[key] = _take(project.arrays[key], order)
    return np.argsort(order).tolist()


# --- rename -----------------------------------------------------------------------------------------------
def check_new_name(rig: Rig, name: str, *, allow: str | None = None) -> str:
    """``name`` stripped, if it can name a new shape: not empty, no line breaks, not taken by a shape or a
    corrective (other than ``allow``)."""
    name = str(name).strip()
    if not name:
        raise RigInputError("A shape needs a name.")
    if any(ch in name for ch in "\r\n\t") or len(name) > 200:
        raise RigInputError(f"'{shown(name, 40)}' cannot name a shape (no line breaks or tabs, at most 200 characters).")
    if name != allow and name in rig.shape_names:
        raise RigInputError(f"The rig already has a shape named '{shown(name, 60)}'.")
    if any(c.name == name for c in rig.correctives):
        raise RigInputError(f"'{shown(name, 60)}' already names a corrective.")
    return name


@dataclass
class RenameRecord:
    old: str
    new: str
    corrective_names: list[tuple[int, str, str]] = field(default_factory=list)   # (index, old name, new name)


def rename_shape(project, old: str, new: str) -> RenameRecord:
    """Rename a shape everywhere it is named: the list, correctives' drivers (and a corrective's default name
    'A+B'), presets, in-betweens, mute, solo and ranges. Undo with ``undo_rename``."""
    rig = project.rig
    k = rig.shape_index(old)
    new = check_new_name(rig, new, allow=old)
    rec = RenameRecord(old, new)
    if new == old:
        return rec
    _rename(rig, k, old, new)
    _rename_pairs(project, old, new)
    for i, c in enumerate(rig.correctives):
        if old in c.drivers:
            default = "+".join(c.drivers)
            c.drivers = [new if d == old else d for d in c.drivers]
            if c.name == default:
                renamed = "+".join(c.drivers)
                rec.corrective_names.append((i, c.name, renamed))
                c.name = renamed
    return rec


def _rename(rig: Rig, k: int, old: str, new: str) -> None:
    rig.shape_names = rig.shape_names[:k] + [new] + rig.shape_names[k + 1:]
    rig.presets = {p: {(new if n == old else n): v for n, v in w.items()} for p, w in rig.presets.items()}
    rig.inbetweens = {(new if n == old else n): v for n, v in rig.inbetweens.items()}
    rig.ranges = {(new if n == old else n): v for n, v in rig.ranges.items()}
    rig.muted = [new if n == old else n for n in rig.muted]
    rig.solo = [new if n == old else n for n in rig.solo]


def _rename_pairs(project, old: str, new: str) -> None:
    """The project's edited antagonist pairs follow a rename (None: the rig's own pairs, found by index)."""
    pairs = getattr(project, "antagonists", None)
    if pairs is not None:
        project.antagonists = [tuple(new if n == old else n for n in pair) for pair in pairs]


def undo_rename(project, rec: RenameRecord) -> None:
    rig = project.rig
    if rec.new == rec.old:
        return
    _rename(rig, rig.shape_index(rec.new), rec.new, rec.old)
    _rename_pairs(project, rec.new, rec.old)
    for c in rig.correctives:
        c.drivers = [rec.old if d == rec.new else d for d in c.drivers]
    for i, old_name, _ in rec.corrective_names:
        rig.correctives[i].name = old_name


# --- delete and insert ------------------------------------------------------------------------------------
@dataclass
class RemovedShapes:
    """Everything a delete took away, to put back exactly: per removed shape (ascending original index) its
    name, delta and index columns; the removed correctives with their places; the name-keyed settings."""

    indices: list[int]
    names: list[str]
    deltas: np.ndarray                 # (n, V, 3)
    weights: np.ndarray                # (n,)
    region_columns: np.ndarray | None  # (R+1, n)
    array_columns: dict[str, np.ndarray]
    correctives: list[tuple[int, object]]   # (index in rig.correctives before the delete, Corrective)
    presets: dict[str, dict[str, float]]    # every preset's full weights before the delete
    inbetweens: dict[str, list[Inbetween]]
    ranges: dict[str, tuple[float, float]]
    muted: list[str]
    solo: list[str]
    antagonists: list | None = None         # the project's edited antagonist pairs before the delete


def correctives_needing(rig: Rig, names) -> list[str]:
    """The correctives that have one of ``names`` among their drivers (deleted with those shapes)."""
    names = set(names)
    return [c.name for c in rig.correctives if names & set(c.drivers)]


def delete_shapes(project, names: list[str]) -> RemovedShapes:
    """Delete shapes and the correctives that need them; ``restore_shapes`` puts everything back exactly."""
    rig = project.rig
    idx = sorted({rig.shape_index(n) for n in names})
    gone = set(rig.shape_names[i] for i in idx)
    keep = np.array([i for i in range(rig.n_shapes) if i not in set(idx)], dtype=np.int64)
    sel = np.array(idx, dtype=np.int64)
    rec = RemovedShapes(
        indices=idx, names=[rig.shape_names[i] for i in idx], deltas=rig.deltas[sel].copy(),
        weights=project.weights[sel].copy(),
        region_columns=None if project.region_weights is None else project.region_weights[:, sel].copy(),
        array_columns={k: np.take(project.arrays[k], sel, axis=-1).copy() for k in SHAPE_AXIS_ARRAYS
                       if k in project.arrays},
        correctives=[(i, c) for i, c in enumerate(rig.correctives) if gone & set(c.drivers)],
        presets=copy.deepcopy(rig.presets),
        inbetweens={n: rig.inbetweens[n] for n in gone if n in rig.inbetweens},
        ranges={n: rig.ranges[n] for n in gone if n in rig.ranges},
        muted=list(rig.muted), solo=list(rig.solo),
        antagonists=None if getattr(project, "antagonists", None) is None else list(project.antagonists))
    if rec.antagonists is not None:          # a pair that names a deleted shape goes with it
        project.antagonists = [pair for pair in rec.antagonists if not gone & set(pair)]
    rig.correctives = [c for c in rig.correctives if not gone & set(c.drivers)]
    rig.shape_names = [rig.shape_names[i] for i in keep]
    rig.deltas = rig.deltas[keep]
    project.weights = project.weights[keep]
    if project.region_weights is not None:
        project.region_weights = project.region_weights[:, keep]
    for k in rec.array_columns:
        project.arrays[k] = np.take(project.arrays[k], keep, axis=-1)
    rig.presets = {p: {n: v for n, v in w.items() if n not in gone} for p, w in rig.presets.items()}
    rig.inbetweens = {n: v for n, v in rig.inbetweens.items() if n not in gone}
    rig.ranges = {n: v for n, v in rig.ranges.items() if n not in gone}
    rig.muted = [n for n in rig.muted if n not in gone]
    rig.solo = [n for n in rig.solo if n not in gone]
    return rec


def _insert_columns(a: np.ndarray, indices: list[int], cols: np.ndarray) -> np.ndarray:
    """``a`` with ``cols`` (..., n) put back at ``indices`` (ascending, positions in the result) on the last axis."""
    out_n = a.shape[-1] + len(indices)
    out = np.empty(a.shape[:-1] + (out_n,), dtype=np.result_type(a, cols))
    mask = np.ones(out_n, bool)
    mask[indices] = False
    out[..., mask] = a
    out[..., ~mask] = cols
    return out


def restore_shapes(project, rec: RemovedShapes) -> None:
    """Undo ``delete_shapes``: the shapes back at their places with their deltas, weights, keyed columns,
    correctives and settings, bit for bit."""
    rig = project.rig
    names = list(rig.shape_names)
    for i, n in zip(rec.indices, rec.names):
        names.insert(i, n)
    D = np.moveaxis(_insert_columns(np.moveaxis(rig.deltas, 0, -1), rec.indices, np.moveaxis(rec.deltas, 0, -1)), -1, 0)
    rig.deltas = np.ascontiguousarray(D)
    rig.shape_names = names
    project.weights = _insert_columns(project.weights, rec.indices, rec.weights)
    if project.region_weights is not None and rec.region_columns is not None:
        project.region_weights = _insert_columns(project.region_weights, rec.indices, rec.region_columns)
    for k, cols in rec.array_columns.items():
        if k in project.arrays:
            project.arrays[k] = _insert_columns(project.arrays[k], rec.indices, cols)
    correctives = list(rig.correctives)
    for i, c in rec.correctives:
        correctives.insert(i, c)
    rig.correctives = correctives
    rig.presets = copy.deepcopy(rec.presets)
    rig.inbetweens = {n: rig.inbetweens.get(n) or rec.inbetweens.get(n) for n in rig.shape_names
                      if rig.inbetweens.get(n) or rec.inbetweens.get(n)}
    rig.ranges = {**rig.ranges, **rec.ranges}
    rig.muted, rig.solo = list(rec.muted), list(rec.solo)
    if rec.antagonists is not None:
        project.antagonists = list(rec.antagonists)


def unique_name(rig: Rig, base: str) -> str:
    """``base`` if free, else base_copy, base_copy2, ... (free among shapes and correctives)."""
    taken = set(rig.shape_names) | {c.name for c in rig.correctives}
    if base not in taken:
        return base
    name, i = f"{base}_copy", 2
    while name in taken:
        name, i = f"{base}_copy{i}", i + 1
    return name


def duplicate_shape(project, name: str, new_name: str | None = None) -> str:
    """A copy of shape ``name`` (its delta, in-betweens and range) right after it, at weight 0; returns its name.
    Undo with ``delete_shapes(project, [new])``."""
    rig = project.rig
    k = rig.shape_index(name)
    new = check_new_name(rig, new_name) if new_name else unique_name(rig, name)
    rec = RemovedShapes(indices=[k + 1], names=[new], deltas=rig.deltas[k:k + 1].copy(), weights=np.zeros(1),
                        region_columns=None if project.region_weights is None
                        else np.zeros((project.region_weights.shape[0], 1)),
                        array_columns={key: np.zeros(project.arrays[key].shape[:-1] + (1,))
                                       for key in SHAPE_AXIS_ARRAYS if key in project.arrays},
                        correctives=[], presets=copy.deepcopy(rig.presets),
                        inbetweens={new: [Inbetween(i.weight, i.delta.copy()) for i in rig.inbetweens.get(name, [])]},
                        ranges={new: rig.ranges[name]} if name in rig.ranges else {},
                        muted=list(rig.muted), solo=list(rig.solo))
    restore_shapes(project, rec)
    return new


# --- per-shape settings -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShapeSettings:
    """The name-keyed settings of a rig's shapes, as one value an undo command stores and puts back."""

    inbetweens: dict
    ranges: dict
    muted: tuple
    solo: tuple

    @staticmethod
    def of(rig: Rig) -> "ShapeSettings":
        return ShapeSettings({n: list(v) for n, v in rig.inbetweens.items()}, dict(rig.ranges),
                             tuple(rig.muted), tuple(rig.solo))

    def apply(self, rig: Rig) -> None:
        rig.inbetweens = {n: list(v) for n, v in self.inbetweens.items()}
        rig.ranges = dict(self.ranges)
        rig.muted, rig.solo = list(self.muted), list(self.solo)


def with_mute(rig: Rig, name: str, on: bool) -> ShapeSettings:
    """The settings with shape ``name`` muted (or not)."""
    rig.shape_index(name)
    s = ShapeSettings.of(rig)
    muted = [n for n in s.muted if n != name] + ([name] if on else [])
    return ShapeSettings(s.inbetweens, s.ranges, tuple(muted), s.solo)


def with_solo(rig: Rig, name: str, on: bool, *, exclusive: bool = False) -> ShapeSettings:
    """The settings with shape ``name`` soloed (or not); ``exclusive``: the only soloed shape."""
    rig.shape_index(name)
    s = ShapeSettings.of(rig)
    solo = [] if exclusive else [n for n in s.solo if n != name]
    return ShapeSettings(s.inbetweens, s.ranges, s.muted, tuple(solo + ([name] if on else [])))


def with_range(rig: Rig, name: str, lo: float, hi: float) -> ShapeSettings:
    """The settings with shape ``name``'s slider range lo..hi (0..1 removes the range: the default)."""
    rig.shape_index(name)
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and -MAX_WEIGHT <= lo < hi <= MAX_WEIGHT):
        raise RigInputError(f"The range of {shown(name, 40)} needs min < max within ±{MAX_WEIGHT:g}, "
                            f"not {lo:g} to {hi:g}.")
    s = ShapeSettings.of(rig)
    ranges = {n: v for n, v in s.ranges.items() if n != name}
    if (lo, hi) != DEFAULT_RANGE:
        ranges[name] = (lo, hi)
    return ShapeSettings(s.inbetweens, ranges, s.muted, s.solo)


def shape_range(rig: Rig, name: str) -> tuple[float, float]:
    """The slider range of a shape (0..1 when it has none)."""
    return rig.ranges.get(name, DEFAULT_RANGE)


def with_inbetween(rig: Rig, name: str, weight: float, delta: np.ndarray) -> ShapeSettings:
    """The settings with an in-between of ``name`` at ``weight`` (replacing one at that weight)."""
    rig.shape_index(name)
    w = float(weight)
    if not np.isfinite(w) or w in (0.0, 1.0) or abs(w) > INBETWEEN_MAX_WEIGHT:
        raise RigInputError(f"An in-between of {shown(name, 40)} needs a weight other than 0 and 1 within "
                            f"±{INBETWEEN_MAX_WEIGHT:g}, not {w:g}.")
    delta = np.asarray(delta, dtype=np.float64)
    if delta.shape != rig.neutral.shape:
        raise RigInputError(f"The in-between of {shown(name, 40)} has {delta.size // 3} vertices; the rig has "
                            f"{rig.n_vertices} (vertex order and count must match the neutral).")
    if not np.isfinite(delta).all():
        raise RigInputError(f"The in-between of {shown(name, 40)} has NaN or infinite coordinates.")
    s = ShapeSettings.of(rig)
    items = [i for i in s.inbetweens.get(name, []) if i.weight != w] + [Inbetween(w, delta.copy())]
    inb = dict(s.inbetweens)
    inb[name] = sorted(items, key=lambda i: i.weight)
    return ShapeSettings(inb, s.ranges, s.muted, s.solo)


def with_mirrored_inbetweens(rig: Rig, name: str, twin: str, mirror_map: np.ndarray) -> ShapeSettings:
    """The settings with ``twin``'s in-betweens the mirror images (``mirror_map``: vertex -> its mirror vertex) of
    ``name``'s, at the same weights; none when ``name`` has none (Maya's Mirror Target mirrors them too)."""
    from solvers.symmetry import mirror_delta
    rig.shape_index(name)
    s = ShapeSettings.of(rig)
    inb = dict(s.inbetweens)
    items = [Inbetween(i.weight, mirror_delta(i.delta, mirror_map)) for i in s.inbetweens.get(name, [])]
    if items:
        inb[twin] = items
    else:
        inb.pop(twin, None)
    return ShapeSettings(inb, s.ranges, s.muted, s.solo)


def without_inbetweens(rig: Rig, name: str, weight: float | None = None) -> ShapeSettings:
    """The settings without ``name``'s in-between at ``weight`` (all of them when None)."""
    rig.shape_index(name)
    s = ShapeSettings.of(rig)
    inb = dict(s.inbetweens)
    items = [i for i in inb.pop(name, []) if weight is not None and i.weight != float(weight)]
    if items:
        inb[name] = items
    return ShapeSettings(inb, s.ranges, s.muted, s.solo)


def inbetween_from_surface(rig: Rig, surface: np.ndarray) -> np.ndarray:
    """The in-between offset of a target surface (V, 3) in the rig's vertex order: surface − neutral."""
    surface = np.asarray(surface, dtype=np.float64)
    if surface.shape != rig.neutral.shape:
        raise RigInputError(f"The target has {surface.size // 3} vertices; the rig has {rig.n_vertices} "
                            "(vertex order and count must match the neutral).")
    return surface - rig.neutral


def inbetween_from_obj(rig: Rig, path) -> np.ndarray:
    """The in-between offset of an OBJ target (read in file order, no re-indexing) against the rig's neutral."""
    from .obj_io import read_obj
    mesh = read_obj(path)
    if mesh.vertices.shape != rig.neutral.shape:
        raise RigInputError(f"{path}: has {mesh.vertices.shape[0]} vertices; the rig has {rig.n_vertices} "
                            "(an in-between must share the neutral's vertex order and count).")
    return mesh.vertices - rig.neutral

