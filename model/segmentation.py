"""Segmentation of a rig into regions and its hierarchy (ALGORITHMS.md §2–3; Joshi et al. 2003, §2, §4).

Plain data: ``Region`` (vertex sets), ``SegmentationLevel`` (regions, background, partition-of-unity blend
weights), ``Segmentation`` (all levels plus the settings that made them), ``SegmentationSettings`` (kept in
the project file). ``segment_rig`` runs the solvers in ``solvers/``; a ``SegmentationCache`` keeps what
depends only on the rig (graph, Laplacian, maps, sorted values) so the GUI can re-threshold live.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, fields

import numpy as np
import scipy.sparse as sp

from solvers import hierarchy as _hier
from solvers import segmentation as _seg
from solvers.deformation_maps import (MAP_KINDS, DeformationMaps, deformation_maps, normalised_map, shape_moves,
                                      shape_scales, smooth_map)
from solvers.laplacian import mesh_adjacency, mesh_laplacian
from solvers.parallel import Background
from solvers.region_growing import grow_regions

from .errors import RigInputError
from .pages import small_pages

METHODS = ("threshold", "region-growing")
LAPLACIANS = ("uniform", "cotangent")
SEPARATE_MESHES = ("follow", "background")


@dataclass
class Region:
    """One region: ``vertices`` = core plus overlap rings (sorted), ``core`` = the vertices it owns."""

    vertices: np.ndarray
    core: np.ndarray


@dataclass
class SegmentationLevel:
    """One level: regions, background vertices, blend weights (V, R+1) CSR (last column = background)."""

    regions: list[Region]
    background: np.ndarray
    blend: sp.csr_matrix

    @property
    def n_regions(self) -> int:
        return len(self.regions)

    def core_labels(self, n_vertices: int | None = None) -> np.ndarray:
        """(V,) region index of every vertex's core, -1 for the background."""
        n = self.blend.shape[0] if n_vertices is None else n_vertices
        lab = np.full(n, -1, dtype=np.int64)
        for r, reg in enumerate(self.regions):
            lab[reg.core] = r
        return lab


@dataclass
class Segmentation:
    """A segmentation and its hierarchy: ``levels[0]`` finest, ``levels[-1]`` one region (the global solve).

    ``threshold_value`` is the map value the threshold quantile ``threshold_t`` selected (None for region
    growing); ``seconds`` the time of each stage of this run.
    """

    threshold_t: float
    threshold_value: float | None
    levels: list[SegmentationLevel]
    map_kind: str
    min_region_size: int
    overlap_rings: int
    method: str
    seconds: dict[str, float] = field(default_factory=dict)


# Settings counted in rounds over the mesh (rings, smoothing passes): more than this reaches across any face many
# times over, and each round is a pass over the mesh (`segment --smoothing 100000000` still ran after 5 minutes, 10⁴
# took 0.6 s on the sample face; a project file may say anything)
ROUNDS_SETTINGS, MAX_ROUNDS = ("overlap_rings", "concavity_rings", "smoothing"), 1000


@dataclass
class SegmentationSettings:
    """What the user chose for the segmentation (ALGORITHMS.md §3 defaults); saved in the project file.

    t                 threshold quantile in [0, 1] over the skin that moves (Joshi used 0.25 and 0.75 over
                      the whole mesh; 0.5 over the moving skin of ICT FaceKit keeps about as many vertices
                      as 0.75 over its whole head, and is the measured default, see the README).
    levels            hierarchy levels, None = halve the region count per level until one region.
    map_kind          'laplacian' (Joshi: where the skin bends), 'displacement' (Acosta: where it moves) or
                      'laplacian+displacement' (the larger of the two normalised maps: bends or moves).
    min_region_size   regions smaller than this (vertices) are absorbed by a neighbour.
    overlap_rings     rings each region grows into its neighbours [1].
    concavity_rings   rings of the graph closing that reduces concavity (0 = none).
    method            'threshold' (Joshi) or 'region-growing' (Acosta).
    growth_ratio      region growing: neighbours join while value ≥ ratio · seed [0.75].
    max_groups        region growing: number of groups [5].
    laplacian         'uniform' (umbrella, Joshi) or 'cotangent'.
    normalise         True: each shape's map is divided by its 99% quantile over the vertices it moves before
                      the maximum (every shape has its say); False: Joshi's raw maximum.
    smoothing         rounds of 1-ring averaging of the map (0 = none; only with ``normalise``).
    split_by_shapes   regions are cut where the group of shapes that moves the skin most changes.
    separate_meshes   'follow': a separate mesh (eyeball, teeth) joins the skin region whose shapes move it;
                      'background': it stays in the background.
    """

    t: float = 0.5
    levels: int | None = None
    map_kind: str = "laplacian+displacement"
    min_region_size: int = 30
    overlap_rings: int = 1
    concavity_rings: int = 2
    method: str = "threshold"
    growth_ratio: float = 0.75
    max_groups: int = 5
    laplacian: str = "uniform"
    normalise: bool = True
    smoothing: int = 1
    split_by_shapes: bool = True
    separate_meshes: str = "follow"

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise RigInputError with one sentence if a setting is out of range."""
        self.t = _seg.validate_threshold_t(self.t)
        if self.map_kind not in MAP_KINDS:
            raise RigInputError(f"Unknown deformation map '{self.map_kind}': use one of {', '.join(MAP_KINDS)}.")
        if self.method not in METHODS:
            raise RigInputError(f"Unknown segmentation method '{self.method}': use 'threshold' or 'region-growing'.")
        if self.laplacian not in LAPLACIANS:
            raise RigInputError(f"Unknown Laplacian '{self.laplacian}': use 'uniform' or 'cotangent'.")
        if self.separate_meshes not in SEPARATE_MESHES:
            raise RigInputError(f"Unknown choice for separate meshes '{self.separate_meshes}': "
                                "use 'follow' or 'background'.")
        for name in ("normalise", "split_by_shapes"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise RigInputError(f"The segmentation setting '{name}' must be true or false; "
                                    f"got {getattr(self, name)!r}.")
            setattr(self, name, bool(getattr(self, name)))
        for name in ("min_region_size", "overlap_rings", "concavity_rings", "max_groups", "smoothing"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise RigInputError(f"The segmentation setting '{name}' must be a whole number ≥ 0; got {value!r}.")
            if name in ROUNDS_SETTINGS and value > MAX_ROUNDS:   # each round is one more pass over the mesh
                raise RigInputError(f"The segmentation setting '{name}' must be at most {MAX_ROUNDS}; got {value!r}.")
            setattr(self, name, int(value))
        if self.max_groups < 1:
            raise RigInputError("Region growing needs at least one group (max_groups ≥ 1).")
        if self.levels is not None:
            if isinstance(self.levels, bool) or not isinstance(self.levels, (int, np.integer)) or self.levels < 1:
                raise RigInputError(f"The number of hierarchy levels must be a whole number ≥ 1; got {self.levels!r}.")
            self.levels = int(self.levels)
        try:
            self.growth_ratio = float(self.growth_ratio)
        except (TypeError, ValueError):
            raise RigInputError(f"The region-growing ratio must be a number; got {self.growth_ratio!r}.") from None
        if not (0.0 < self.growth_ratio <= 1.0):
            raise RigInputError(f"The region-growing ratio must lie in (0, 1]; got {self.growth_ratio:g}.")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "SegmentationSettings":
        """Settings from a project-file dict; unknown keys are ignored, missing ones take the defaults."""
        if not isinstance(data, dict):
            raise RigInputError("The segmentation settings in the project file are not a JSON object.")
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})


def segmentation_to_json(seg: Segmentation) -> dict:
    """The ``segment`` command's JSON (DESIGN.md): threshold, levels (regions with vertices/core, background),
    seconds. Level 0 is the finest."""
    return {
        "threshold": float(seg.threshold_t),
        "levels": [
            {"level": i,
             "regions": [{"vertices": [int(v) for v in r.vertices], "core": [int(v) for v in r.core]}
                         for r in lvl.regions],
             "background": [int(v) for v in lvl.background]}
            for i, lvl in enumerate(seg.levels)],
        "seconds": {k: float(v) for k, v in seg.seconds.items()},
    }


def check_rig_deforms(deltas: np.ndarray, so: str = "there is nothing to segment") -> None:
    """RigInputError, one sentence ending "so ``so``.", for a rig whose shapes (K, V, 3) move nothing: none at all,
    or every one equal to the neutral (a deformation view says "there is no deformation to show")."""
    if deltas.ndim != 3 or deltas.shape[0] == 0:
        raise RigInputError(f"The rig has no blendshapes, so {so}.")
    if not _any_nonzero(deltas):
        raise RigInputError(f"Every shape equals the neutral (all displacements are zero), so {so}.")


def _any_nonzero(a: np.ndarray, chunk: int = 1 << 16) -> bool:
    """``np.any(a)``, stopping at the first chunk that holds a nonzero (a rig's first shape, as a rule)."""
    flat = a.reshape(-1)
    return any(np.any(flat[i:i + chunk]) for i in range(0, flat.size, chunk))


class SegmentationCache:
    """Everything a segmentation needs that depends only on the rig: graph, Laplacian, maps, sorted maps.

    It keeps references to the rig arrays it was built from and rebuilds when ``segment_rig`` is called
    with different array objects. After editing arrays in place, call ``clear()``.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self._key: tuple | None = None
        self.adjacency: sp.csr_matrix | None = None
        self._laplacians: dict[str, sp.csr_matrix] = {}
        self._maps: dict[str, DeformationMaps] = {}
        self._values: dict[tuple, np.ndarray] = {}
        self._sorted: dict[tuple, np.ndarray] = {}
        self._derived: dict[str, object] = {}
        self.map_seconds = 0.0

    def bind(self, neutral, face_counts, face_indices, deltas) -> None:
        """Use this rig; drops everything cached for another rig (identity of the arrays decides)."""
        key = (neutral, face_counts, face_indices, deltas)
        if self._key is not None and all(a is b for a, b in zip(self._key, key)):
            return
        self.clear()
        neutral = np.asarray(neutral, dtype=np.float64)
        deltas = np.asarray(deltas, dtype=np.float64)
        if neutral.ndim != 2 or neutral.shape[1] != 3:
            raise RigInputError("The neutral must be a (V, 3) array of points.")
        if deltas.ndim == 3 and deltas.shape[0] and deltas.shape[1:] != neutral.shape:
            raise RigInputError(
                f"The shapes have {deltas.shape[1]} vertices but the neutral has {neutral.shape[0]}.")
        check_rig_deforms(deltas)
        self._key = key
        self._neutral, self._counts, self._indices, self._deltas = neutral, face_counts, face_indices, deltas
        self.adjacency = mesh_adjacency(neutral.shape[0], face_counts, face_indices)

    @property
    def neutral(self) -> np.ndarray:
        return self._neutral

    def laplacian(self, kind: str = "uniform") -> sp.csr_matrix:
        if kind not in self._laplacians:
            self._laplacians[kind] = mesh_laplacian(self._neutral, self._counts, self._indices, kind,
                                                    adjacency=self.adjacency)
        return self._laplacians[kind]

    def maps(self, laplacian: str = "uniform") -> DeformationMaps:
        """The deformation maps (computed once per Laplacian kind)."""
        if laplacian not in self._maps:
            t0 = time.perf_counter()
            self._maps[laplacian] = deformation_maps(self.laplacian(laplacian), self._deltas)
            self.map_seconds = time.perf_counter() - t0
        return self._maps[laplacian]

    def _get(self, name: str, make):
        if name not in self._derived:
            self._derived[name] = make()
        return self._derived[name]

    def pieces(self) -> tuple[np.ndarray, np.ndarray]:
        """(piece, main): connected component of every vertex and the main surface (the skin)."""
        return self._get("pieces", lambda: _seg.mesh_pieces(self.adjacency))

    def moves(self) -> np.ndarray:
        """(V, K) bool: shape k moves vertex v (more than 1% of its largest displacement)."""
        return self._get("moves", lambda: shape_moves(self.maps().per_shape_displacement))

    def domain(self) -> np.ndarray:
        """(V,) bool: the skin that moves, where the threshold quantile is taken and regions can form."""
        return self._get("domain", lambda: self.pieces()[1] & self.moves().any(axis=1))

    def scales(self, kind: str, laplacian: str = "uniform") -> np.ndarray:
        """(K,) each shape's 99% quantile of its ``kind`` map over the vertices it moves."""
        return self._get(f"scales-{kind}-{laplacian}", lambda: shape_scales(
            self.maps(laplacian).per_shape_values(kind), self.moves()))

    def support(self) -> _seg.ShapeSupport:
        """(V, K) where each shape acts: its displacement over its own 99% quantile, at most 1 (read shape by
        shape: ``solvers.segmentation.ShapeSupport``)."""
        return self._get("support", lambda: _seg.ShapeSupport(self.maps().per_shape_displacement,
                                                                self.scales("displacement")))

    def shape_groups(self) -> np.ndarray:
        """(K,) groups of shapes that act on the same part of the face."""
        return self._get("groups", lambda: _seg.shape_groups(self.support()))

    def split_graph(self) -> sp.csr_matrix:
        """The mesh graph cut where the dominant shape group changes."""
        def make():
            return _seg.split_graph(self.adjacency, _seg.dominant_group(self.support(), self.shape_groups()))
        return self._get("split", make)

    def vertex_mirror(self, vertices: np.ndarray) -> np.ndarray:
        """(V,) each vertex's mirror image across x = 0 (``solvers.symmetry.mirror_map``), looked up for
        ``vertices`` (and any asked for before) only: -1 at the others. The k-d tree is built once per rig."""
        lookup = self.start_mirror_lookup().result()
        mirror = self._get("mirror", lambda: np.full(self._neutral.shape[0], -1, dtype=np.int64))
        todo = vertices[mirror[vertices] < 0]
        if todo.size:
            mirror[todo] = lookup(todo)[1]
        return mirror

    def start_mirror_lookup(self) -> Background:
        """The mirror lookup (``solvers.symmetry.MirrorLookup`` of the neutral, its k-d tree built), started once per
        rig on another core: it needs only the neutral, and its tree's build runs outside the GIL, so it overlaps
        the threshold and clean-up stages (~5 ms on ICT FaceKit)."""
        def make():
            from solvers.symmetry import MirrorLookup
            lookup = MirrorLookup(self._neutral)
            lookup.tree   # noqa: B018  (built here, not on the first lookup)
            return lookup
        return self._get("mirror-lookup-started", lambda: Background(make))

    def mirror_partners(self) -> np.ndarray:
        return self._get("partners", lambda: _hier.mirror_partners(self._neutral, self.maps().per_shape_displacement))

    def values(self, map_kind: str, laplacian: str = "uniform", normalise: bool = False,
               smoothing: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(values, sorted values over ``domain()``) of the scalar map a segmentation thresholds: Joshi's raw
        maximum, or with ``normalise`` every shape's map over its own scale, smoothed ``smoothing`` rounds."""
        key = (map_kind, laplacian, bool(normalise), int(smoothing) if normalise else 0)
        if key not in self._values:
            maps = self.maps(laplacian)
            if normalise:
                kinds = ("laplacian", "displacement") if map_kind == "laplacian+displacement" else (map_kind,)
                parts = []
                for kind in kinds:
                    parts.append(normalised_map(maps.per_shape_values(kind), self.scales(kind, laplacian)))
                vals = smooth_map(np.max(parts, axis=0), self.adjacency, smoothing)
            else:
                vals = maps.values(map_kind)
            self._values[key] = vals
            self._sorted[key] = np.sort(vals[self.domain()])
        return self._values[key], self._sorted[key]


def _level(labels: np.ndarray, adjacency: sp.spmatrix, rings: int, edges=None) -> SegmentationLevel:
    cores, verts, blend = _seg.overlap_and_blend(labels, adjacency, rings, edges)
    return SegmentationLevel(regions=[Region(vertices=v, core=c) for c, v in zip(cores, verts)],
                             background=np.flatnonzero(labels < 0), blend=blend)


def segment_rig(neutral: np.ndarray, face_counts: np.ndarray, face_indices: np.ndarray, deltas: np.ndarray,
                settings: SegmentationSettings | None = None,
                cache: SegmentationCache | None = None, *, finest_only: bool = False) -> Segmentation:
    """Segment a rig and build its hierarchy (ALGORITHMS.md §2–3; Joshi et al. 2003, §2, §4; Acosta 2015).

    Threshold method: ``threshold = D[⌊n·t⌋]`` of the sorted map, regions = connected components of the
    vertices above it, then clean-up, overlap rings and partition-of-unity blend weights per level.
    Region growing: Acosta's groups on the chosen map take the place of the components. Pass the same
    ``cache`` on every call for the same rig to reuse the graph, Laplacian and maps. ``finest_only`` skips
    the hierarchy (level 0 only), for a live preview while a threshold slider moves.
    """
    with small_pages():   # its fresh (K, V) maps are written once and streamed through (model.pages)
        return _segment_rig(neutral, face_counts, face_indices, deltas, settings, cache, finest_only)


def _segment_rig(neutral, face_counts, face_indices, deltas, settings, cache, finest_only) -> Segmentation:
    s = settings if settings is not None else SegmentationSettings()
    s.validate()
    cache = cache if cache is not None else SegmentationCache()
    secs: dict[str, float] = {}
    t_start = time.perf_counter()
    cache.bind(neutral, face_counts, face_indices, deltas)
    secs["graph"] = time.perf_counter() - t_start

    t0 = time.perf_counter()
    maps = cache.maps(s.laplacian)
    kind = "displacement" if s.map_kind == "displacement" else "laplacian"  # what must not vanish
    if maps.values(kind).max() <= 1e-9 * float(maps.displacement.max()):  # zero up to rounding
        raise RigInputError(f"The {kind} map is zero everywhere: no shape deforms the surface, "
                            "so there is nothing to segment.")
    split = None
    if s.method == "threshold" and s.split_by_shapes:
        # the graph cut by shape groups needs the maps only: made on another core while this one makes the
        # thresholded map (and the shape scales both use, made first)
        cache.scales("displacement")
        split = Background(cache.split_graph)
    values, sorted_values = cache.values(s.map_kind, s.laplacian, s.normalise, s.smoothing)
    if not finest_only:
        cache.mirror_partners()
    secs["maps"] = time.perf_counter() - t0
    A = cache.adjacency
    if not finest_only:
        cache.start_mirror_lookup()    # the hierarchy's mirror images, on another core while the regions form
    piece, main = cache.pieces()

    def regions_at(t: float, min_size: int) -> tuple[np.ndarray, float | None]:   # the finest level and its threshold
        if s.method == "threshold":
            lab, thr_t = _seg.threshold_labels(values, A, t, sorted_values=sorted_values, domain=cache.domain(),
                                               split=split.result() if split is not None else None)
        else:
            lab, thr_t = _seg.relabel(grow_regions(values, A, s.growth_ratio, s.max_groups)), None
        secs["threshold"] = time.perf_counter() - t0
        lab = _seg.clean_up(lab, A, min_size=min_size, concavity_rings=s.concavity_rings)
        if not main.all():  # separate meshes: never by proximity; they follow the region that moves like them
            lab = np.where(main, lab, _seg.BACKGROUND)
            if s.separate_meshes == "follow":
                lab = _seg.attach_separate_meshes(lab, piece, main, cache.support())
            lab = _seg.relabel(lab)
        return lab, thr_t

    t0 = time.perf_counter()
    labels, thr = regions_at(s.t, s.min_region_size)
    secs["cleanup"] = time.perf_counter() - t0 - secs["threshold"]
    if not (labels >= 0).any():
        raise RigInputError(_no_region(s, lambda t, size: bool((regions_at(t, size)[0] >= 0).any()),
                                       int(cache.domain().sum())))

    t0 = time.perf_counter()
    if finest_only:
        per_level = [labels]
    else:
        activity = _hier.region_activity(labels, cache.support(), cache.mirror_partners())
        mirrors = _hier.region_mirrors(labels, cache.vertex_mirror(np.flatnonzero(labels >= 0)))
        per_level = _hier.hierarchy_labels(labels, A, cache.neutral, s.levels, activity, mirrors)
    secs["hierarchy"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    edges = _seg.leaving_edges(per_level[0], A)  # every level's core boundaries are among the finest level's
    levels = [_level(lab, A, s.overlap_rings, edges) for lab in per_level]
    secs["overlap"] = time.perf_counter() - t0
    secs["total"] = time.perf_counter() - t_start
    return Segmentation(threshold_t=s.t, threshold_value=thr, levels=levels, map_kind=s.map_kind,
                        min_region_size=s.min_region_size, overlap_rings=s.overlap_rings, method=s.method,
                        seconds=secs)


def _no_region(s: SegmentationSettings, leaves_one, moving: int) -> str:
    """Why no region was left, with only the advice that helps: ``leaves_one(t, min_size)`` says whether the
    rig's segmentation at those settings would leave one (a lower threshold, then a smaller minimum size, tried)."""
    from .wording import count
    threshold = s.method == "threshold"
    lowest = 0.0 if threshold else s.t
    size = count(s.min_region_size, "vertex", "vertices")
    if threshold and s.t > 0 and leaves_one(lowest, s.min_region_size):
        return (f"The threshold t={s.t:g} leaves no region of at least {size}; "
                f"lower the threshold{' or the minimum region size' if s.min_region_size > 1 else ''}.")
    skin = f"its shapes move {count(moving, 'vertex', 'vertices')} of the skin"
    if s.min_region_size > 1 and leaves_one(lowest, 1):
        return (f"{'No threshold leaves a' if threshold else 'Region growing leaves no'} region of at least "
                f"{size} on this rig ({skin}); lower the minimum region size.")
    return (f"This rig cannot be segmented: {skin}, too few for a region at any threshold or minimum region "
            "size.")


def region_statistics(seg: Segmentation, maps: DeformationMaps, shape_names: list[str], level: int = 0,
                      top: int = 5) -> list[dict]:
    """Per region of a level: core and total vertex counts and the most active shapes
    (``Σ_{v∈core} m_k(v)``, as shares of the region's total), for the region panel."""
    lvl = seg.levels[level]
    cores = [r.core for r in lvl.regions]
    act = _seg.region_shape_activity(maps.per_shape, cores)
    best = _seg.most_active_shapes(act, shape_names, top)
    return [{"region": r, "core_vertices": int(reg.core.size), "vertices": int(reg.vertices.size),
             "shapes": best[r]} for r, reg in enumerate(lvl.regions)]
