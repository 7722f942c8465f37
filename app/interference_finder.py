"""The interference finder of the Correctives panel (ALGORITHMS.md §6; Smith 2006 §4.5): rank shape pairs by
how their displacements interfere, list the best (a pair and its mirror image as one row, or the partners of
one shape), colour the face by where the selected pair interferes, and start a corrective for it.

The scores come from ``solvers.correctives`` (one (K, K) matrix per measure, kept until the shapes change);
this module only wires them to the panel and the viewport.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from model.sides import is_left, mirror_indices
from solvers.correctives import (interference_heat, merge_mirrored_pairs, overshoot_heat, rank_interference,
                                 rank_partners, shape_overlap, shape_overshoot)
from solvers.laplacian import vertex_areas
from widgets.correctives_panel import INTERFERENCE_TAB, PAIR_HINT, CorrectivesPanel
from widgets.scene import ColorMap

_UNSET = object()


class InterferenceFinder:
    """Owned by the CorrectiveController; ``start_authoring(drivers, rule)`` enters sculpt mode on a pair."""

    def __init__(self, window, panel: CorrectivesPanel, start_authoring) -> None:
        self.window, self.panel, self._start_authoring = window, panel, start_authoring
        self.document, self.viewport = window.document, window.viewport
        self._overlap: dict[str, np.ndarray] = {}  # (K, K) scores by measure, until the shapes change
        self._scored_deltas: np.ndarray | None = None   # the rig.deltas array the scores were computed from
        self._areas: np.ndarray | None = None      # the neutral's vertex areas, until the rig changes
        self.pairs: list[tuple[int, int, float]] = []
        self.pair_mirrors: list[tuple[int, int, float] | None] = []  # each row's mirror pair, when folded in
        self._pairs_measure = "overshoot"  # the measure self.pairs were ranked by
        self._saved_colormap = _UNSET
        self.heat: np.ndarray | None = None
        self._heat_colormap: ColorMap | None = None
        panel.find_requested.connect(self.find_pairs)
        panel.pair_selected.connect(self.show_pair)
        panel.create_pair_requested.connect(self.create_for_pair)

    def reset(self) -> None:
        """A new rig: nothing ranked, no heat map."""
        self.leave_heat_map()
        self._overlap.clear()
        self._areas = None
        self.pairs, self.pair_mirrors = [], []
        self.panel.set_pairs([])

    def vertex_areas(self) -> np.ndarray:
        """(V,) the neutral's vertex areas in rig units² (``solvers.laplacian.vertex_areas``), once per rig."""
        if self._areas is None:
            rig = self.document.rig
            self._areas = vertex_areas(rig.neutral, rig.triangles())
        return self._areas

    def shapes_changed(self) -> None:
        """Shapes or correctives were edited: if the shapes' deltas changed (the commands replace the array,
        never write into it), the scores are recomputed on the next search."""
        if self.document.rig is None or self.document.rig.deltas is not self._scored_deltas:
            self._overlap.clear()

    def find_pairs(self) -> list[tuple[int, int, float]]:
        """Rank the pairs by the panel's measure (computed once per measure until the shapes change) and list
        the top ones: every pair, mirrored couples as one row, or one shape's partners. Returns the rows as
        (i, j, score)."""
        rig = self.document.rig
        if rig is None:
            return []
        measure = self.measure
        self.shapes_changed()
        if measure not in self._overlap:
            QtWidgets.QApplication.setOverrideCursor(QtCore.Qt.WaitCursor)
            try:   # surface-weighted: a densely modelled eyelid does not outweigh the forehead
                areas = self.vertex_areas()
                self._overlap[measure] = shape_overshoot(rig.deltas, areas=areas) if measure == "overshoot" else \
                    shape_overlap(rig.deltas, directional=measure == "directional", areas=areas)
                self._scored_deltas = rig.deltas
            finally:
                QtWidgets.QApplication.restoreOverrideCursor()
        self._pairs_measure = measure
        O, top = self._overlap[measure], self.panel.top.value()
        shape = self.panel.partner_of.currentData()
        names = rig.shape_names
        self.pair_mirrors = []
        if shape in names:   # the partners of one shape, as (shape, partner, score)
            k = names.index(shape)
            self.pairs = [(k, j, s) for j, s in rank_partners(O, k, top)]
        elif self.panel.merge_mirrored.isChecked():
            every = rank_interference(None, top=len(names) ** 2, overlap=O)
            rows = merge_mirrored_pairs(every, mirror_indices(names), [is_left(n) for n in names])[:top]
            self.pairs = [(i, j, s if m is None else max(s, m[2])) for i, j, s, m in rows]   # a row's score
            self.pair_mirrors = [m for *_, m in rows]
        else:
            self.pairs = rank_interference(None, top=top, overlap=O)
        mirrors = self.pair_mirrors or [None] * len(self.pairs)
        self.panel.set_pairs([(names[i], names[j], s, "" if m is None else f"{names[m[0]]} × {names[m[1]]}")
                              for (i, j, s), m in zip(self.pairs, mirrors)])
        self.leave_heat_map()
        return self.pairs

    @property
    def measure(self) -> str:
        """The finder's measure: "overshoot" (default), "plain" or "directional" overlap."""
        return self.panel.measure.currentData()

    def show_pair(self, row: int) -> None:
        """Colour the face by where the selected pair interferes (a colour bar in rig units): the overshoot of
        their sum for the overshoot measure, else min(‖d_i‖, ‖d_j‖)."""
        if row < 0 or row >= len(self.pairs):
            self.leave_heat_map()
            return
        rig = self.document.rig
        i, j, score = self.pairs[row]
        mirror = self.pair_mirrors[row] if row < len(self.pair_mirrors) else None
        overshoot = self._pairs_measure == "overshoot"
        heat_of = overshoot_heat if overshoot else interference_heat
        self.heat = heat_of(rig.deltas[i], rig.deltas[j])
        if mirror is not None:   # both sides of a mirrored couple
            self.heat = np.maximum(self.heat, heat_of(rig.deltas[mirror[0]], rig.deltas[mirror[1]]))
        if self._saved_colormap is _UNSET:
            self._saved_colormap = self.viewport.colormap
        top = float(self.heat.max())
        title = f"overshoot ({rig.units})" if overshoot else f"interference ({rig.units})"
        self._heat_colormap = ColorMap(self.heat, title=title, cmap="YlOrRd", clim=(0.0, top if top > 0 else 1.0))
        self.viewport.set_colormap(self._heat_colormap)
        hot = self.heat > 0.1 * top if top > 0 else np.zeros(self.heat.shape, dtype=bool)
        n, area = int(hot.sum()), float(self.vertex_areas()[hot].sum())
        what = "‖d_i + d_j‖ − max(‖d_i‖, ‖d_j‖)" if overshoot else "min(‖d_i‖, ‖d_j‖)"
        names = rig.shape_names
        if mirror is not None:
            own = float(self._overlap[self._pairs_measure][i, j])
            score_text = (f"{names[i]} × {names[j]} and {names[mirror[0]]} × {names[mirror[1]]}: scores "
                          f"{own:.3f} and {mirror[2]:.3f}")
        else:
            score_text = f"{names[i]} × {names[j]}: score {score:.3f}"
        self.panel.pair_info.setText(f"{score_text}; "
                                     f"{what} up to {top:.3g} {rig.units}, above 10% on {n:,} vertices "
                                     f"({area:.3g} {rig.units}²).")

    def reapply_heat_map(self) -> None:
        """Put the heat map back on top after another view repainted the face (a finished segmentation)."""
        if self._saved_colormap is not _UNSET and self.viewport.colormap is not self._heat_colormap:
            self._saved_colormap = self.viewport.colormap
            self.viewport.set_colormap(self._heat_colormap)

    def leave_heat_map(self) -> None:
        """Restore the view that was shown before the heat map."""
        if self._saved_colormap is not _UNSET:
            saved, self._saved_colormap = self._saved_colormap, _UNSET
            self.heat = None
            self.viewport.set_colormap(saved)
            self.panel.pair_info.setText(PAIR_HINT)

    def on_tab_change(self, index: int) -> None:
        if index != INTERFERENCE_TAB:
            self.leave_heat_map()
        elif self.panel.selected_pair_row() >= 0:
            self.show_pair(self.panel.selected_pair_row())

    def create_for_pair(self) -> None:
        row = self.panel.selected_pair_row()
        if row < 0 or row >= len(self.pairs):
            return
        i, j, _ = self.pairs[row]
        names = self.document.rig.shape_names
        self.leave_heat_map()
        self._start_authoring([names[i], names[j]], self.panel.current_rule())
