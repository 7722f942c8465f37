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
from solvers.deformation_maps import MAP_KINDS, DeformationMaps, deformation_maps
from solvers.laplacian import mesh_adjacency, mesh_laplacian
from solvers.region_growing import grow_regions

from .errors import RigInputError

METHODS = ("threshold", "region-growing")
LAPLACIANS = ("uniform", "cotangent")


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


@dataclass
class SegmentationSettings:
    """What the user chose for the segmentation (ALGORITHMS.md §3 defaults); saved in the project file.

    t                 threshold quantile in [0, 1] (Joshi used 0.25 and 0.75).
    levels            hierarchy levels, None = halve the region count per level until one region.
    map_kind          'laplacian' (Joshi) or 'displacement' (Acosta).
    min_region_size   regions smaller than this (vertices) are absorbed by a neighbour.
    overlap_rings     rings each region grows into its neighbours [1].
    concavity_rings   rings of the graph closing that reduces concavity (0 = none).
    method            'threshold' (Joshi) or 'region-growing' (Acosta).
    growth_ratio      region growing: neighbours join while value ≥ ratio · seed [0.75].
    max_groups        region growing: number of groups [5].
    laplacian         'uniform' (umbrella, Joshi) or 'cotangent'.
    """

    t: float = 0.75
    levels: int | None = None
    map_kind: str = "laplacian"
    min_region_size: int = 30
    overlap_rings: int = 1
    concavity_rings: int = 2
    method: str = "threshold"
    growth_ratio: float = 0.75
    max_groups: int = 5
    laplacian: str = "uniform"

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise RigInputError with one sentence if a setting is out of range."""
        self.t = _seg.validate_threshold_t(self.t)
        if self.map_kind not in MAP_KINDS:
            raise RigInputError(f"Unknown deformation map '{self.map_kind}': use 'laplacian' or 'displacement'.")
        if self.method not in METHODS:
            raise RigInputError(f"Unknown segmentation method '{self.method}': use 'threshold' or 'region-growing'.")
        if self.laplacian not in LAPLACIANS:
            raise RigInputError(f"Unknown Laplacian '{self.laplacian}': use 'uniform' or 'cotangent'.")
        for name in ("min_region_size", "overlap_rings", "concavity_rings", "max_groups"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise RigInputError(f"The segmentation setting '{name}' must be a whole number ≥ 0; got {value!r}.")
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
        self._sorted: dict[tuple[str, str], np.ndarray] = {}
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
        if deltas.ndim != 3 or deltas.shape[0] == 0:
            raise RigInputError("The rig has no blendshapes, so there is nothing to segment.")
        if deltas.shape[1:] != neutral.shape:
            raise RigInputError(
                f"The shapes have {deltas.shape[1]} vertices but the neutral has {neutral.shape[0]}.")
        if not np.any(deltas):
            raise RigInputError(
                "Every shape equals the neutral (all displacements are zero), so there is nothing to segment.")
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

    def values(self, map_kind: str, laplacian: str = "uniform") -> tuple[np.ndarray, np.ndarray]:
        """(values, sorted values) of the scalar map a segmentation thresholds."""
        vals = self.maps(laplacian).values(map_kind)
        key = (map_kind, laplacian)
        if key not in self._sorted:
            self._sorted[key] = np.sort(vals)
        return vals, self._sorted[key]


def _level(labels: np.ndarray, adjacency: sp.spmatrix, rings: int) -> SegmentationLevel:
    cores, verts, blend = _seg.overlap_and_blend(labels, adjacency, rings)
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
    s = settings if settings is not None else SegmentationSettings()
    s.validate()
    cache = cache if cache is not None else SegmentationCache()
    secs: dict[str, float] = {}
    t_start = time.perf_counter()
    cache.bind(neutral, face_counts, face_indices, deltas)
    secs["graph"] = time.perf_counter() - t_start

    t0 = time.perf_counter()
    values, sorted_values = cache.values(s.map_kind, s.laplacian)
    secs["maps"] = time.perf_counter() - t0
    scale = float(cache.maps(s.laplacian).displacement.max())
    if sorted_values[-1] <= 1e-9 * scale:  # zero up to rounding (e.g. a rig of pure translations)
        raise RigInputError(f"The {s.map_kind} map is zero everywhere: no shape deforms the surface, "
                            "so there is nothing to segment.")
    A = cache.adjacency

    t0 = time.perf_counter()
    if s.method == "threshold":
        labels, thr = _seg.threshold_labels(values, A, s.t, sorted_values=sorted_values)
    else:
        labels, thr = _seg.relabel(grow_regions(values, A, s.growth_ratio, s.max_groups)), None
    secs["threshold"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    labels = _seg.clean_up(labels, A, min_size=s.min_region_size, concavity_rings=s.concavity_rings)
    secs["cleanup"] = time.perf_counter() - t0
    if not (labels >= 0).any():
        raise RigInputError(
            f"The threshold t={s.t:g} leaves no region of at least {s.min_region_size} vertices; "
            "lower the threshold or the minimum region size.")

    t0 = time.perf_counter()
    per_level = [labels] if finest_only else _hier.hierarchy_labels(labels, A, cache.neutral, s.levels)
    secs["hierarchy"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    levels = [_level(lab, A, s.overlap_rings) for lab in per_level]
    secs["overlap"] = time.perf_counter() - t0
    secs["total"] = time.perf_counter() - t_start
    return Segmentation(threshold_t=s.t, threshold_value=thr, levels=levels, map_kind=s.map_kind,
                        min_region_size=s.min_region_size, overlap_rings=s.overlap_rings, method=s.method,
                        seconds=secs)


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
