"""The blendshape rig: neutral surface, polygon faces as in the file, named shape deltas, units.

ALGORITHMS.md §1: ``x(w) = b0 + Σ_k w_k d_k + Σ_c a_c(w) e_c``. Vertex identity is the whole contract:
every shape has exactly the neutral's vertex count and order.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solvers.mesh import fan_triangulate

from .errors import RigInputError, repeated, shown
from .units import UNIT_IN_METRES, UNITS, unit_scale  # noqa: F401  (the units of a rig; re-exported)

MAX_COORDINATE = 1e9   # in any unit: no face is a thousand kilometres across; beyond it a file is damaged
MAX_WEIGHT = 1e3       # presets and poses: overdrive and negative weights exist, a weight of 10⁴ does not
INBETWEEN_MAX_WEIGHT = 10.0   # Maya keeps in-between weights within ±10


def finite_range(a: np.ndarray) -> tuple[float, float] | None:
    """(min, max) of a float array when every value is finite, else None; (0, 0) when it is empty. Both reductions
    carry a NaN through and an infinity is one of the extremes, so two passes tell what ``np.isfinite(a).all()``
    does without its (n,) bool array: 270 MB of new memory for a 422k-vertex, 228-shape rig's deltas, 0.5 s of its
    first touch against 0.17 s for the two passes."""
    if a.size == 0:
        return 0.0, 0.0
    lo, hi = float(a.min()), float(a.max())
    return (lo, hi) if np.isfinite(lo) and np.isfinite(hi) else None


def _float_array(a, where: str, what: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.kind not in "fiub":
        raise RigInputError(f"{where}: {what} are not numbers (stored as {a.dtype}).")
    return np.ascontiguousarray(a, dtype=np.float64)


def _index_array(a, where: str, what: str) -> np.ndarray:
    """int32 indices, refusing values that int32 cannot hold (a cast would wrap them silently)."""
    a = np.asarray(a)
    if a.dtype.kind not in "iu":
        if a.dtype.kind == "f" and a.size and np.isfinite(a).all() and (a == np.round(a)).all():
            pass   # whole numbers stored as floats
        elif a.size:
            raise RigInputError(f"{where}: {what} are not whole numbers (stored as {a.dtype}).")
    if a.size and (a.min() < -2**31 or a.max() >= 2**31):
        raise RigInputError(f"{where}: {what} hold numbers beyond 2³¹; the file is damaged.")
    return np.ascontiguousarray(a, dtype=np.int32)


def checked_presets(presets, shape_names, where: str) -> dict[str, dict[str, float]]:
    """Named weight sets {preset: {shape: weight}} with known shapes and finite weights within ±MAX_WEIGHT."""
    if not isinstance(presets, dict):
        raise RigInputError(f"{where}: presets must be an object of name: {{shape: weight}}.")
    names = set(shape_names)
    out: dict[str, dict[str, float]] = {}
    for preset, weights in presets.items():
        if not isinstance(weights, dict):
            raise RigInputError(f"{where}: preset '{shown(preset, 40)}' must be an object of shape: weight.")
        unknown = sorted(set(weights) - names)
        if unknown:
            raise RigInputError(f"{where}: preset '{shown(preset, 40)}' names shapes the rig does not have: "
                                f"{shown(', '.join(unknown), 120)}.")
        clean = {}
        for k, v in weights.items():
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise RigInputError(f"{where}: preset '{shown(preset, 40)}' gives {shown(k, 40)} a weight that "
                                    f"is not a number ({shown(v, 20)}).")
            f = float(v)
            if not np.isfinite(f) or abs(f) > MAX_WEIGHT:
                raise RigInputError(f"{where}: preset '{shown(preset, 40)}' gives {shown(k, 40)} the weight "
                                    f"{shown(v, 20)}, outside ±{MAX_WEIGHT:g}.")
            clean[str(k)] = f
        out[str(preset)] = clean
    return out


@dataclass
class CornerAttributes:
    """What an OBJ holds besides ``v`` and ``f``, kept so UVs, normals and groups survive a round trip.

    uvs, normals    the file's own ``vt`` (T, 2|3) and ``vn`` (N, 3) lists, or None.
    corner_uv/_normal  per polygon corner (parallel to ``Rig.face_indices``), an index into them, -1 for none.
    records         (face number, line): ``g``/``o``/``usemtl``/``s`` lines before that face, ``mtllib`` at 0.
    notes           what a reader left out and why (e.g. UVs that were not numbers), shown with the textures.
    Vertices are never split at UV seams: the corner indices carry the seams.
    """

    uvs: np.ndarray | None = None
    corner_uv: np.ndarray | None = None
    normals: np.ndarray | None = None
    corner_normal: np.ndarray | None = None
    records: list[tuple[int, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


@dataclass(eq=False)   # compared by identity: an undo step keeps the very objects it restores
class Inbetween:
    """An in-between target of a shape (Maya's in-between): the offset ``delta`` (V, 3) from the neutral that the
    shape reaches at ``weight`` (not 0 or 1). The shape's offset is piecewise linear in its weight through
    (0, 0), each in-between (weight, delta) and (1, d_k); ``model.shape_weights`` evaluates it."""

    weight: float
    delta: np.ndarray


@dataclass
class Rig:
    """A blendshape rig.

    neutral      (V, 3) float64, the rest surface ``b0``.
    face_counts  (F,) int32, vertices per polygon, in file order.
    face_indices (sum(face_counts),) int32, polygon vertex indices, in file order (0-based).
    shape_names  K unique names.
    deltas       (K, V, 3) float64, ``d_k = b_k - b0``.
    units        'cm', 'mm' or 'm'.
    correctives  list of ``model.correctives.Corrective`` (drivers, rule, delta).
    presets      named weight sets, e.g. {"happy": {"mouthSmile_L": 1.0, ...}}.
    The Shapes list's per-shape settings, by shape name (Maya's Shape Editor; ``model.shape_weights`` applies
    them in every pose evaluation):
    inbetweens   {shape: [Inbetween, ...]} sorted by weight.
    muted        shapes left out of the pose (their weight counts as 0, for correctives too).
    solo         if any: only these shapes take part (Blender's solo); muted wins over solo.
    ranges       {shape: (min, max)} slider range; the weight is clamped to it (overdrive beyond 1, negative
                 weights where the rig allows). A shape without one has a 0..1 slider and is not clamped.
    materials    {material: (r, g, b) in 0..1}: the diffuse colour of the materials the faces name (the OBJ's
                 ``usemtl`` records in ``corners``; ``model.parts``), from its MTL file or a glTF's materials.
    """

    neutral: np.ndarray
    face_counts: np.ndarray
    face_indices: np.ndarray
    shape_names: list[str]
    deltas: np.ndarray
    units: str = "cm"
    name: str = "rig"
    source: str = ""
    correctives: list = field(default_factory=list)
    presets: dict[str, dict[str, float]] = field(default_factory=dict)
    corners: CornerAttributes | None = None  # the source OBJ's UVs, normals and groups (export only)
    inbetweens: dict[str, list[Inbetween]] = field(default_factory=dict)
    muted: list[str] = field(default_factory=list)
    solo: list[str] = field(default_factory=list)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    materials: dict[str, tuple[float, float, float]] = field(default_factory=dict)   # colours by material name

    def __post_init__(self) -> None:
        where = self.source or self.name
        self.neutral = _float_array(self.neutral, where, "the neutral")
        self.face_counts = _index_array(self.face_counts, where, "the face sizes")
        self.face_indices = _index_array(self.face_indices, where, "the face vertex indices")
        if self.neutral.ndim != 2 or self.neutral.shape[1] != 3:
            raise RigInputError(f"{where}: the neutral must be an array of 3D points.")
        deltas = _float_array(self.deltas, where, "the shapes")
        if deltas.size != len(self.shape_names) * self.neutral.size:
            raise RigInputError(f"{where}: {len(self.shape_names)} shape names but deltas of shape {deltas.shape}.")
        self.deltas = deltas.reshape(-1, self.n_vertices, 3)
        self.shape_names = list(self.shape_names)
        self.validate()

    # --- sizes -----------------------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return int(self.neutral.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.face_counts.shape[0])

    @property
    def n_shapes(self) -> int:
        return len(self.shape_names)

    def validate(self) -> None:
        """Raise RigInputError if the arrays do not describe one consistent rig."""
        where = self.source or self.name
        if self.neutral.ndim != 2 or self.neutral.shape[1] != 3:
            raise RigInputError(f"{where}: the neutral must be an array of 3D points.")
        extent = finite_range(self.neutral)
        if extent is None:
            raise RigInputError(f"{where}: the neutral has NaN or infinite coordinates.")
        if max(extent[1], -extent[0]) > MAX_COORDINATE:
            raise RigInputError(f"{where}: the neutral has coordinates beyond ±{MAX_COORDINATE:g}; "
                                "the file is damaged or not in any length unit.")
        if self.deltas.shape != (len(self.shape_names), self.n_vertices, 3):
            raise RigInputError(
                f"{where}: {len(self.shape_names)} shape names but deltas of shape {self.deltas.shape}.")
        extent = finite_range(self.deltas)
        if extent is None:
            raise RigInputError(f"{where}: a shape has NaN or infinite coordinates.")
        if max(extent[1], -extent[0]) > MAX_COORDINATE:  # no |d| copy
            raise RigInputError(f"{where}: a shape moves a vertex by more than {MAX_COORDINATE:g}; the file is damaged.")
        if self.face_counts.size == 0:
            raise RigInputError(f"{where}: the rig has no faces.")
        if self.face_counts.min() < 3:
            raise RigInputError(f"{where}: a face has {int(self.face_counts.min())} corners; every face needs 3 or more.")
        if int(self.face_counts.sum(dtype=np.int64)) != self.face_indices.size:
            raise RigInputError(f"{where}: the face list is inconsistent (counts do not match indices).")
        if self.face_indices.size and (self.face_indices.min() < 0 or self.face_indices.max() >= self.n_vertices):
            raise RigInputError(f"{where}: a face refers to a vertex that does not exist.")
        if not all(isinstance(n, str) and n for n in self.shape_names):
            raise RigInputError(f"{where}: every shape needs a name (a non-empty text).")
        dup = repeated(self.shape_names)
        if dup:
            raise RigInputError(f"{where}: duplicate shape names: {shown(', '.join(dup), 200)}.")
        if not isinstance(self.units, str) or self.units not in UNITS:
            raise RigInputError(f"{where}: unknown units '{shown(self.units, 20)}'.")
        self.presets = checked_presets(self.presets, self.shape_names, where)
        self._validate_shape_settings(where)
        c = self.corners
        for table, idx in ((None, None),) if c is None else ((c.uvs, c.corner_uv), (c.normals, c.corner_normal)):
            if idx is not None and (idx.shape != self.face_indices.shape or table is None
                                    or (idx.size and (idx.min() < -1 or idx.max() >= len(table)))):
                raise RigInputError(f"{where}: the UV or normal indices of the faces do not fit the rig.")
            if table is not None and (table.ndim != 2 or not 2 <= table.shape[1] <= 3):
                raise RigInputError(f"{where}: the UV or normal list is not a table of 2 or 3 numbers a row.")

    def _validate_shape_settings(self, where: str) -> None:
        """In-betweens, mute, solo and ranges name shapes the rig has and hold sane numbers."""
        names = set(self.shape_names)
        if not isinstance(self.inbetweens, dict) or not isinstance(self.ranges, dict):
            raise RigInputError(f"{where}: the shapes' in-betweens and ranges must be objects keyed by shape name.")
        for what, listed in (("muted", self.muted), ("solo", self.solo)):
            if not isinstance(listed, list) or not all(isinstance(n, str) for n in listed):
                raise RigInputError(f"{where}: the {what} shapes must be a list of shape names.")
            unknown = sorted(set(listed) - names)
            if unknown:
                raise RigInputError(f"{where}: {what} shapes the rig does not have: {shown(', '.join(unknown), 120)}.")
        clean = {}
        for name, rng in self.ranges.items():
            if name not in names:
                raise RigInputError(f"{where}: a slider range for '{shown(name, 40)}', a shape the rig does not have.")
            try:
                lo, hi = (float(x) for x in rng)
            except (TypeError, ValueError):
                raise RigInputError(f"{where}: the slider range of {shown(name, 40)} is not two numbers.") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and -MAX_WEIGHT <= lo < hi <= MAX_WEIGHT):
                raise RigInputError(f"{where}: the slider range of {shown(name, 40)} ({shown(lo, 12)} to "
                                    f"{shown(hi, 12)}) must have min < max within ±{MAX_WEIGHT:g}.")
            clean[name] = (lo, hi)
        self.ranges = clean
        for name, items in self.inbetweens.items():
            if name not in names:
                raise RigInputError(f"{where}: in-betweens for '{shown(name, 40)}', a shape the rig does not have.")
            if not isinstance(items, list) or not all(isinstance(i, Inbetween) for i in items):
                raise RigInputError(f"{where}: the in-betweens of {shown(name, 40)} are not a list of targets.")
            weights = [i.weight for i in items]
            for ib in items:
                w = ib.weight
                if isinstance(w, bool) or not isinstance(w, (int, float, np.floating, np.integer)) \
                        or not np.isfinite(w) or w in (0.0, 1.0) or abs(w) > INBETWEEN_MAX_WEIGHT:
                    raise RigInputError(f"{where}: an in-between of {shown(name, 40)} is at weight {shown(w, 12)}; "
                                        f"it must be a number other than 0 and 1 within ±{INBETWEEN_MAX_WEIGHT:g}.")
                ib.weight = float(w)
                ib.delta = _float_array(ib.delta, where, f"the in-between of {name}")
                if ib.delta.shape != self.neutral.shape:
                    raise RigInputError(f"{where}: the in-between of {shown(name, 40)} at {w:g} has "
                                        f"{ib.delta.size // 3} vertices, the rig has {self.n_vertices}.")
                if not np.isfinite(ib.delta).all() or (ib.delta.size and np.abs(ib.delta).max() > MAX_COORDINATE):
                    raise RigInputError(f"{where}: the in-between of {shown(name, 40)} at {w:g} has NaN, infinite "
                                        "or absurd coordinates.")
            if len(set(weights)) != len(weights):
                raise RigInputError(f"{where}: {shown(name, 40)} has two in-betweens at the same weight.")
            items.sort(key=lambda i: i.weight)
        self.inbetweens = {k: v for k, v in self.inbetweens.items() if v}

    # --- names and weights -----------------------------------------------------------------------
    def shape_index(self, name: str) -> int:
        try:
            return self.shape_names.index(name)
        except ValueError:
            raise RigInputError(f"The rig has no shape named '{name}'.") from None

    def weights_from_dict(self, named: dict[str, float]) -> np.ndarray:
        """A (K,) weight vector from {shape name: weight}; unknown names raise RigInputError."""
        w = np.zeros(self.n_shapes)
        for name, value in named.items():
            w[self.shape_index(name)] = float(value)
        return w

    def weights_to_dict(self, weights: np.ndarray, *, nonzero: bool = True) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.shape_names, weights) if v != 0 or not nonzero}

    # --- geometry --------------------------------------------------------------------------------
    def polygons(self) -> list[np.ndarray]:
        """The faces as a list of index arrays (slow; for export and tests)."""
        return np.split(self.face_indices, np.cumsum(self.face_counts)[:-1])

    def triangles(self) -> np.ndarray:
        """(T, 3) fan triangulation of the polygons, for display and per-triangle operators."""
        return fan_triangulate(self.face_counts, self.face_indices)

    def edges(self) -> np.ndarray:
        """(E, 2) unique undirected polygon edges (i < j), sorted."""
        starts = np.concatenate(([0], np.cumsum(self.face_counts)[:-1]))
        nxt = np.arange(self.face_indices.size) + 1
        ends = starts + self.face_counts
        nxt[ends - 1] = starts  # wrap each polygon
        a, b = self.face_indices, self.face_indices[nxt]
        e = np.sort(np.stack([a, b], axis=1), axis=1)
        return np.unique(e, axis=0)

    def shape(self, name: str) -> np.ndarray:
        """The full target surface of a shape, ``b0 + d_k``."""
        return self.neutral + self.deltas[self.shape_index(name)]

    def copy(self) -> "Rig":
        import copy
        return copy.deepcopy(self)

    def snapshot(self) -> "Rig":
        """The rig as it is now, for a job that runs beside the window (an export, a batch, a personalisation) while
        the user goes on editing: its own Rig object and its own lists, dicts and correctives, sharing the numpy
        arrays. The application's edits never change an array in place, they replace it (``model.shape_edits``,
        ``model.project.DetachedEdit``), so the snapshot's arrays stay what they were. A deep copy made the window
        wait for 2.15 GiB of deltas to be copied (11 s for the 422k-vertex, 228-shape rig) and doubled its memory."""
        import copy
        return copy.deepcopy(self, memo=self.shared_arrays())   # every array is "already copied" as itself

    def shared_arrays(self) -> dict[int, np.ndarray]:
        """The rig's numpy arrays (its own, its in-betweens' and correctives', its corner attributes'), by id: what a
        snapshot shares (``snapshot``, ``model.recovery.recovery_snapshot``), as a ``copy.deepcopy`` memo."""
        arrays: dict[int, np.ndarray] = {}
        _collect_arrays(self, arrays, depth=4)
        return arrays


def _collect_arrays(value, into: dict[int, np.ndarray], depth: int) -> None:
    """The numpy arrays reachable from ``value`` through attributes, lists, tuples and dicts, ``depth`` levels deep,
    by id (``Rig.snapshot``'s memo: ``copy.deepcopy`` takes each of them as its own copy)."""
    if isinstance(value, np.ndarray):
        into[id(value)] = value
        return
    if depth <= 0 or isinstance(value, (str, bytes, int, float, bool, type(None))):
        return
    if isinstance(value, dict):
        items = list(value.values())
    elif isinstance(value, (list, tuple, set, frozenset)):
        items = list(value)
    else:
        items = list(getattr(value, "__dict__", {}).values())
    for item in items:
        _collect_arrays(item, into, depth - 1)
