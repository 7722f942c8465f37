"""Markers: named points on the rig surface that the user drags (ALGORITHMS.md §8) or a take tracks (§4).

A ``Marker`` sits on a vertex, or on a face point: ``face`` indexes ``Rig.triangles()`` (the fan
triangulation of the polygons) and ``bary`` holds the three barycentric weights of that triangle's corners.
A ``MarkerSet`` turns its markers into one sparse (M, V) sampling matrix ``S`` so that marker positions on
any posed surface X (V, 3) are ``S @ X`` and the marker rows of the shape deltas are one sparse product
(the A matrix (3M, K) of the weight solve, ``solvers.weight_solve``).

Marker map JSON (DESIGN.md, Readers) is ``{"rig_units": "cm", "markers": {"M00": 1234, "M01": {"face": f,
"bary": [a, b, c]}}}``. In the file, as in ``model.marker_map`` (which reads the same files for takes),
``face`` is a polygon index in file order and ``bary`` has one weight per polygon corner (or three, for
the polygon's first three corners); ``read_marker_json``/``write_marker_json`` convert to and from the
triangle form used here, so both readers give every marker the same surface point.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .errors import RigInputError, repeated
from .rig import UNITS, Rig

BARY_TOL = 1e-3
DRAG_LAM_REG = 1e-3   # a drag's λ_r toward the pose at the press, cm² (Markers panel, "Stay near pose")


@dataclass(frozen=True)
class Marker:
    """A named surface point: ``vertex`` or (``face`` into ``Rig.triangles()``, ``bary`` (3,))."""

    name: str
    vertex: int | None = None
    face: int | None = None
    bary: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise RigInputError("A marker needs a non-empty name.")
        if (self.vertex is None) == (self.face is None):
            raise RigInputError(f"Marker {self.name} must sit on either a vertex or a face point (not both, not neither).")
        if self.vertex is not None:
            if isinstance(self.vertex, bool) or not isinstance(self.vertex, (int, np.integer)) or self.vertex < 0:
                raise RigInputError(f"Marker {self.name}: the vertex must be a non-negative integer, not {self.vertex!r}.")
            object.__setattr__(self, "vertex", int(self.vertex))
        else:
            if isinstance(self.face, bool) or not isinstance(self.face, (int, np.integer)) or self.face < 0:
                raise RigInputError(f"Marker {self.name}: the face must be a non-negative integer, not {self.face!r}.")
            b = np.asarray(self.bary if self.bary is not None else (), dtype=np.float64).reshape(-1)
            if b.size != 3 or not np.isfinite(b).all():
                raise RigInputError(f"Marker {self.name}: a face point needs three finite barycentric weights.")
            if (b < -BARY_TOL).any() or abs(b.sum() - 1.0) > BARY_TOL:
                raise RigInputError(f"Marker {self.name}: barycentric weights must be ≥ 0 and sum to 1, not {b.tolist()}.")
            object.__setattr__(self, "face", int(self.face))
            object.__setattr__(self, "bary", tuple(float(x) for x in b))

    def to_dict(self) -> dict:
        if self.vertex is not None:
            return {"name": self.name, "vertex": self.vertex}
        return {"name": self.name, "face": self.face, "bary": list(self.bary)}

    @staticmethod
    def from_dict(d: dict) -> "Marker":
        if not isinstance(d, dict) or "name" not in d:
            raise RigInputError("A marker entry needs a name and a vertex or a face point.")
        return Marker(d["name"], vertex=d.get("vertex"), face=d.get("face"),
                      bary=tuple(d["bary"]) if d.get("bary") is not None else None)


class MarkerSet:
    """Markers bound to one rig's vertex count and triangles, with their sparse sampling matrix.

    ``S`` (M, V) CSR: row i samples marker i (one 1 for a vertex marker, three barycentric weights for a
    face point). ``positions(X) = S @ X``; ``delta_rows(deltas)`` is the (3M, K) A matrix of the weight
    solve (row 3i + c is coordinate c of marker i). ``warnings`` lists markers on the background (no shape
    moves them); such markers are allowed: they pin the solve but cannot be moved by it.
    Duplicate names, and two markers on the same vertex or surface point, raise RigInputError.
    """

    def __init__(self, markers: list[Marker], n_vertices: int, triangles: np.ndarray | None = None,
                 moving: np.ndarray | None = None, source: str = "") -> None:
        self.markers = list(markers)
        self.n_vertices = int(n_vertices)
        self.triangles = None if triangles is None else np.asarray(triangles)
        self.source = source
        self.moving = None if moving is None else np.asarray(moving, dtype=np.int64)
        where = f"{source}: " if source else ""
        names = [m.name for m in self.markers]
        dup = repeated(names)
        if dup:
            raise RigInputError(f"{where}duplicate marker names: {', '.join(dup)}.")
        rows, cols, vals = [], [], []
        for i, m in enumerate(self.markers):
            if m.vertex is not None:
                if m.vertex >= self.n_vertices:
                    raise RigInputError(f"{where}marker {m.name} is on vertex {m.vertex}, "
                                        f"but the rig has {self.n_vertices} vertices.")
                rows.append(i), cols.append(m.vertex), vals.append(1.0)
            else:
                if self.triangles is None:
                    raise RigInputError(f"{where}marker {m.name} is on a face point, but no triangles were given.")
                if m.face >= len(self.triangles):
                    raise RigInputError(f"{where}marker {m.name} is on triangle {m.face}, "
                                        f"but the rig has {len(self.triangles)} triangles.")
                b = np.asarray(m.bary) / sum(m.bary)
                for v, wv in zip(self.triangles[m.face], b):
                    if wv != 0.0:
                        rows.append(i), cols.append(int(v)), vals.append(float(wv))
        self.S = sp.csr_matrix((vals, (rows, cols)), shape=(len(self.markers), self.n_vertices))
        self.S.sum_duplicates()
        self._check_duplicate_points(where)
        self.background: list[str] = []
        self.warnings: list[str] = []
        if moving is not None:
            moves = np.zeros(self.n_vertices, bool)
            moves[np.asarray(moving, dtype=np.int64)] = True
            # A marker is on the background when no vertex it samples (with weight) is moved by any shape.
            touched = np.asarray(abs(self.S) @ moves.astype(np.float64)).reshape(-1) > 0
            self.background = [m.name for m, t in zip(self.markers, touched) if not t]
            if self.background:
                self.warnings.append(f"{len(self.background)} marker(s) on the background, where no shape moves the "
                                     f"surface (they stay pinned): {', '.join(self.background)}.")

    def _check_duplicate_points(self, where: str) -> None:
        seen: dict[tuple, str] = {}
        S = self.S
        for i, m in enumerate(self.markers):
            lo, hi = S.indptr[i], S.indptr[i + 1]
            key = tuple(sorted((int(c), round(float(v), 6)) for c, v in zip(S.indices[lo:hi], S.data[lo:hi]) if v > 1e-9))
            if key in seen:
                raise RigInputError(f"{where}markers {seen[key]} and {m.name} sit on the same surface point.")
            seen[key] = m.name

    @classmethod
    def for_rig(cls, rig: Rig, markers: list[Marker], source: str = "", *, triangles: np.ndarray | None = None,
                moving: np.ndarray | None = None) -> "MarkerSet":
        """A marker set on ``rig`` (triangles from ``rig.triangles()``, background from the shapes). ``triangles``
        and ``moving`` (the vertices some shape moves) when the caller has them already: on a studio rig the
        search for the moving vertices is a pass over every shape's deltas."""
        if moving is None:
            moving = (np.flatnonzero((rig.deltas.reshape(rig.n_shapes, -1) != 0).any(axis=0).reshape(-1, 3).any(axis=1))
                      if rig.n_shapes else np.zeros(0, int))
        return cls(markers, rig.n_vertices, rig.triangles() if triangles is None else triangles, moving=moving,
                   source=source)

    # --- sizes and lookups -----------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.markers)

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.markers]

    def index(self, name: str) -> int:
        for i, m in enumerate(self.markers):
            if m.name == name:
                return i
        raise RigInputError(f"There is no marker named '{name}'.")

    # --- sampling --------------------------------------------------------------------------------
    def positions(self, X: np.ndarray) -> np.ndarray:
        """(M, 3) marker positions on a posed surface X (V, 3) — one sparse product."""
        X = np.asarray(X)
        if X.shape != (self.n_vertices, 3):
            raise RigInputError(f"Marker positions need a surface of {self.n_vertices} points, not shape {X.shape}.")
        return np.asarray(self.S @ X)

    def delta_rows(self, deltas: np.ndarray, shapes: np.ndarray | None = None) -> np.ndarray:
        """(3M, K) marker rows of the shape deltas (K, V, 3) (optionally only ``shapes``): the weight solve's A."""
        D = np.asarray(deltas)
        if shapes is not None:
            D = D[np.asarray(shapes)]
        K = D.shape[0]
        cols = np.unique(self.S.indices)
        Ssub = self.S[:, cols]
        sampled = np.asarray(Ssub @ D[:, cols, :].transpose(1, 0, 2).reshape(cols.size, K * 3))  # (M, K*3)
        return np.ascontiguousarray(sampled.reshape(-1, K, 3).transpose(0, 2, 1).reshape(-1, K))

    def drag_solver(self, rig: Rig, regions: list[np.ndarray], region_max: np.ndarray, *,
                    lam_reg: float = DRAG_LAM_REG, antagonists=None, background: np.ndarray | None = None,
                    dragged: tuple[int, np.ndarray] | None = None):
        """The regional solver a drag of these markers re-solves at each mouse move (``solvers.regional_solve``;
        ALGORITHMS.md §8): ``regions`` of the chosen level (none: one global solve), ``region_max`` their
        per-shape displacement, ``background`` the level's vertices its background blends into (its row is solved
        from the markers there), ``lam_reg`` the pull toward the pose at the press in cm² (a physical weight,
        converted to the rig's units by ``model.units``, so a drag poses a face in m, cm or mm alike). A region no
        marker sits on follows the markers with its own shapes (``unmarked="follow"``). ``dragged`` (marker index,
        the camera's forward direction): that marker is held in the view plane only (``in_view_plane``); give its
        targets through ``in_view_plane`` too."""
        from solvers.regional_solve import RegionalSolver
        from .shape_weights import live_mask       # a muted shape does not follow the markers
        from .units import area
        rows = self.delta_rows(rig.deltas) * live_mask(rig)
        if dragged is not None:
            rows = in_view_plane(rows, *dragged)
        return RegionalSolver(regions, self.S, rows, region_max=region_max, solve_background=True,
                              background=background, lam_reg=area(lam_reg, rig.units), antagonists=antagonists,
                              unmarked="follow")

    # --- editing (returns new sets; markers are immutable) ----------------------------------------
    def with_marker(self, marker: Marker) -> "MarkerSet":
        return MarkerSet(self.markers + [marker], self.n_vertices, self.triangles, self.moving, self.source)

    def without(self, name: str) -> "MarkerSet":
        i = self.index(name)
        return MarkerSet(self.markers[:i] + self.markers[i + 1:], self.n_vertices, self.triangles, self.moving,
                         self.source)

    # --- project file ----------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"markers": [m.to_dict() for m in self.markers]}

    @classmethod
    def from_dict(cls, d: dict, rig: Rig, source: str = "", *, triangles: np.ndarray | None = None,
                  moving: np.ndarray | None = None) -> "MarkerSet":
        """The markers of a project's section on ``rig`` (``triangles``, ``moving``: as ``for_rig``)."""
        if not isinstance(d, dict) or not isinstance(d.get("markers"), list):
            raise RigInputError(f"{source or 'project'}: the markers entry must be a list of markers.")
        return cls.for_rig(rig, [Marker.from_dict(m) for m in d["markers"]], source=source, triangles=triangles,
                           moving=moving)


def in_view_plane(rows: np.ndarray, index: int, forward: np.ndarray, axis: int = 0) -> np.ndarray:
    """A copy of ``rows`` (marker j's x, y, z at 3j, 3j+1, 3j+2 along ``axis``: marker rows of the deltas, targets,
    a corrective's displacements) with marker ``index``'s three projected onto the plane facing ``forward``
    (``P = I − f fᵀ``, f the unit view direction). A drag holds the marker it pulls where the user sees it and
    leaves its depth free: a chin dragged down on screen opens the jaw (jawOpen moves the chin down and back),
    where a target fixed in depth took jawForward at 0.86 to bring the chin forward again, and the face folded."""
    f = np.asarray(forward, dtype=np.float64).reshape(3)
    f = f / np.linalg.norm(f)
    P = np.eye(3) - np.outer(f, f)
    out = np.array(rows, dtype=np.float64)
    block = np.moveaxis(out, axis, 0)        # a view: writing it writes ``out``
    block[3 * index:3 * index + 3] = np.tensordot(P, block[3 * index:3 * index + 3], axes=(1, 0))
    return out


# --- marker map JSON (polygon + per-corner bary in the file, triangle + bary here) ----------------
def _fan_tables(rig: Rig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    counts = rig.face_counts.astype(np.int64)
    ntri = np.maximum(counts - 2, 0)
    tri_start = np.concatenate(([0], np.cumsum(ntri)[:-1]))
    face_of_tri = np.repeat(np.arange(counts.size), ntri)
    k_of_tri = np.arange(int(ntri.sum())) - np.repeat(tri_start, ntri)
    return tri_start, face_of_tri, k_of_tri


def markers_to_json(markers: MarkerSet, rig: Rig) -> dict:
    """The marker map JSON for ``markers`` (face points written as polygon + per-corner weights)."""
    _, face_of_tri, k_of_tri = _fan_tables(rig)
    out: dict[str, int | dict] = {}
    for m in markers.markers:
        if m.vertex is not None:
            out[m.name] = m.vertex
            continue
        f, k = int(face_of_tri[m.face]), int(k_of_tri[m.face])
        n = int(rig.face_counts[f])
        b = [0.0] * n
        b[0] += m.bary[0]
        b[k + 1] += m.bary[1]
        b[k + 2] += m.bary[2]
        out[m.name] = {"face": f, "bary": b}
    return {"rig_units": rig.units, "markers": out}


def markers_from_json(d: dict, rig: Rig, source: str = "marker map") -> MarkerSet:
    """A MarkerSet from marker map JSON, validated against ``rig`` (names, vertices, faces, weights)."""
    if not isinstance(d, dict) or not isinstance(d.get("markers"), dict):
        raise RigInputError(f"{source}: a marker map needs a 'markers' object of name: vertex.")
    units = d.get("rig_units", rig.units)
    if units not in UNITS:
        raise RigInputError(f"{source}: unknown rig_units '{units}' (use mm, cm or m).")
    if units != rig.units:
        raise RigInputError(f"{source}: the map is for a rig in {units}, but this rig is in {rig.units}.")
    if not d["markers"]:
        raise RigInputError(f"{source}: maps no markers.")
    tri_start, _, _ = _fan_tables(rig)
    counts = rig.face_counts
    markers = []
    for name, v in d["markers"].items():
        if not isinstance(name, str) or not name.strip():
            raise RigInputError(f"{source}: a marker has an empty name.")
        if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
            if not 0 <= int(v) < rig.n_vertices:
                raise RigInputError(f"{source}: marker {name} is on vertex {int(v)}, "
                                    f"but the rig has {rig.n_vertices} vertices (0–{rig.n_vertices - 1}).")
            markers.append(Marker(name, vertex=int(v)))
        elif isinstance(v, dict) and "face" in v and "bary" in v:
            f = v["face"]
            if isinstance(f, bool) or not isinstance(f, (int, np.integer)) or not 0 <= int(f) < rig.n_faces:
                raise RigInputError(f"{source}: marker {name} is on face {f!r}, but the rig has {rig.n_faces} faces.")
            f = int(f)
            n = int(counts[f])
            try:
                b = np.asarray(v["bary"], dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                raise RigInputError(f"{source}: marker {name}'s barycentric weights are not numbers.") from None
            if b.size not in (3, n) or not np.isfinite(b).all():
                raise RigInputError(f"{source}: marker {name} needs 3 or {n} finite barycentric weights.")
            full = np.zeros(n)
            full[:b.size] = b
            # Find the fan triangle (corners 0, k+1, k+2) that holds every non-zero weight.
            nz = set(np.flatnonzero(np.abs(full) > 1e-12).tolist()) - {0}
            k = next((k for k in range(n - 2) if nz <= {k + 1, k + 2}), None)
            if k is None:
                raise RigInputError(f"{source}: marker {name}'s weights span more than one triangle of face {f}.")
            markers.append(Marker(name, face=int(tri_start[f] + k), bary=(full[0], full[k + 1], full[k + 2])))
        else:
            raise RigInputError(f"{source}: marker {name} must map to a vertex index or {{\"face\": f, \"bary\": [a, b, c]}}.")
    return MarkerSet.for_rig(rig, markers, source=source)


def read_marker_json(path: str | Path, rig: Rig) -> MarkerSet:
    """Read a marker map JSON file for ``rig``; bad files raise RigInputError naming the file."""
    from .json_file import read_json_file
    return markers_from_json(read_json_file(path), rig, source=str(path))


def write_marker_json(path: str | Path, markers: MarkerSet, rig: Rig) -> None:
    """Write ``markers`` as a marker map JSON file (atomically)."""
    from .atomic import atomic_write
    atomic_write(path, (json.dumps(markers_to_json(markers, rig), indent=1) + "\n").encode())


__all__ = ["Marker", "MarkerSet", "markers_to_json", "markers_from_json", "read_marker_json",
           "write_marker_json"]
