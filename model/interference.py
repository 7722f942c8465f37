"""Which shape pairs of a rig need a corrective (ALGORITHMS.md §6; Smith 2006 §4.5): the interference finder's
ranking, shared by the Correctives panel and ``blendshape-studio pairs``.

Every measure is taken over the surface (vertex areas of the neutral), so the ranking does not depend on how
densely each part of the face is modelled. A pair and its mirror image can share one row.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from model.correctives import find_corrective
from model.errors import RigInputError
from model.sides import is_left, mirror_indices
from solvers.correctives import (interference_heat, merge_mirrored_pairs, overshoot_heat, rank_interference,
                                 rank_partners, shape_overlap, shape_overshoot)
from solvers.laplacian import vertex_areas

MEASURES = ("overshoot", "overlap", "directional")   # overshoot of the sum (the default); Smith's overlap; by direction


@dataclass
class PairRow:
    """One row of the ranking: shapes ``i`` and ``j`` (indices), the row's score (the better side's for a
    mirrored couple) and the mirror pair folded into it, (i', j', score') or None."""
    i: int
    j: int
    score: float
    mirror: tuple[int, int, float] | None = None

    def shapes(self) -> list[tuple[int, int]]:
        """The pair, and its mirror image when the row stands for both sides."""
        return [(self.i, self.j)] + ([] if self.mirror is None else [self.mirror[:2]])


def rig_vertex_areas(rig) -> np.ndarray:
    """(V,) the neutral's vertex areas in rig units² (``solvers.laplacian.vertex_areas``)."""
    return vertex_areas(rig.neutral, rig.triangles())


def pair_scores(rig, measure: str = "overshoot", areas: np.ndarray | None = None) -> np.ndarray:
    """(K, K) the measure for every pair of the rig's shapes, weighted by the vertex areas (computed if not
    given): ``shape_overshoot`` or ``shape_overlap`` (plain or directional)."""
    if measure not in MEASURES:
        raise RigInputError(f"Unknown interference measure '{measure}': use one of {', '.join(MEASURES)}.")
    areas = rig_vertex_areas(rig) if areas is None else areas
    if measure == "overshoot":
        return shape_overshoot(rig.deltas, areas=areas)
    return shape_overlap(rig.deltas, directional=measure == "directional", areas=areas)


def ranked_pairs(scores: np.ndarray, shape_names: list[str], top: int = 20, *, merge_mirrored: bool = True,
                 partner_of: str | None = None) -> list[PairRow]:
    """The ``top`` rows, best first: the partners of one shape (``partner_of``), else every pair, with a pair
    and its mirror image as one row named by its left side (``merge_mirrored``)."""
    names = list(shape_names)
    if partner_of is not None:
        if partner_of not in names:
            raise RigInputError(f"The rig has no shape named '{partner_of}'.")
        k = names.index(partner_of)
        return [PairRow(k, j, s) for j, s in rank_partners(scores, k, top)]
    if not merge_mirrored:
        return [PairRow(i, j, s) for i, j, s in rank_interference(None, top=top, overlap=scores)]
    every = rank_interference(None, top=len(names) ** 2, overlap=scores)
    rows = merge_mirrored_pairs(every, mirror_indices(names), [is_left(n) for n in names])[:top]
    return [PairRow(i, j, s if m is None else max(s, m[2]), m) for i, j, s, m in rows]


def row_correctives(rig, row: PairRow) -> list[str]:
    """The names of the rig's correctives on the row's pair and on its mirror pair (those that exist)."""
    names = rig.shape_names
    found = (find_corrective(rig.correctives, [names[i], names[j]]) for i, j in row.shapes())
    return [c.name for c in found if c is not None]


def corrective_status(rig, row: PairRow) -> str:
    """What the finder shows of a row's correctives: "" none, "✓" every side has one, "1/2" one side of two."""
    have, sides = len(row_correctives(rig, row)), len(row.shapes())
    return "" if have == 0 else "✓" if have == sides else f"{have}/{sides}"


def pair_heat(rig, row: PairRow, measure: str = "overshoot") -> np.ndarray:
    """(V,) where the row's pair interferes, in rig units, both sides for a mirrored row: the overshoot of
    the sum, ‖d_i + d_j‖ − max(‖d_i‖, ‖d_j‖) clipped at 0, for the overshoot measure, else min(‖d_i‖, ‖d_j‖)."""
    heat_of = overshoot_heat if measure == "overshoot" else interference_heat
    heat = None
    for i, j in row.shapes():
        h = heat_of(rig.deltas[i], rig.deltas[j])
        heat = h if heat is None else np.maximum(heat, h)
    return heat


def hot_vertices(heat: np.ndarray, fraction: float = 0.1) -> np.ndarray:
    """The vertices where ``heat`` is above ``fraction`` of its peak (none when it is nowhere above 0)."""
    top = float(heat.max()) if heat.size else 0.0
    return np.flatnonzero(heat > fraction * top) if top > 0 else np.zeros(0, dtype=np.intp)


def hot_area(heat: np.ndarray, areas: np.ndarray, fraction: float = 0.1) -> tuple[int, float]:
    """(vertices, area) where ``heat`` is above ``fraction`` of its peak: how large the problem is."""
    hot = hot_vertices(heat, fraction)
    return int(hot.size), float(areas[hot].sum())
