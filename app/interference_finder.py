"""The interference finder of the Correctives panel (ALGORITHMS.md §6; Smith 2006 §4.5): rank shape pairs by
how their displacements interfere, list the best (a pair and its mirror image as one row, or the partners of
one shape), colour the face by where the selected pair interferes, and start a corrective for it.

The ranking is ``model.interference`` (one (K, K) score matrix per measure, kept here until the shapes
change); this module only wires it to the panel and the viewport.
"""
from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from model.correctives import find_corrective
from model.interference import (PairRow, corrective_status, hot_area, hot_vertices, pair_heat, pair_scores,
                                ranked_pairs, rig_vertex_areas)
from app.background import BackgroundRunner
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
        self.rows: list[PairRow] = []     # the listed rows, best first
        self._pairs_measure = "overshoot"  # the measure self.pairs were ranked by
        self._saved_colormap = _UNSET
        self.heat: np.ndarray | None = None
        self._heat_colormap: ColorMap | None = None
        self._runner = BackgroundRunner(panel)      # the ranking's pass over the shapes, off the GUI thread
        panel.find_requested.connect(self.find_pairs_in_background)
        panel.pair_selected.connect(self.show_pair)
        panel.create_pair_requested.connect(self.create_for_pair)

    def reset(self) -> None:
        """A new rig: nothing ranked, no heat map."""
        self.leave_heat_map()
        self._overlap.clear()
        self._areas = None
        self.rows = []
        self.panel.set_pairs([])

    def vertex_areas(self) -> np.ndarray:
        """(V,) the neutral's vertex areas in rig units² (``solvers.laplacian.vertex_areas``), once per rig."""
        if self._areas is None:
            self._areas = rig_vertex_areas(self.document.rig)
        return self._areas

    def shapes_changed(self) -> None:
        """Shapes or correctives were edited: if the shapes' deltas changed (the commands replace the array,
        never write into it), the scores are recomputed on the next search."""
        if self.document.rig is None or self.document.rig.deltas is not self._scored_deltas:
            self._overlap.clear()
            if self.rows:
                # the rows name shapes by their place in the list before the edit: after a shape deleted, moved or
                # duplicated they were other pairs (the heat map and Create corrective took the wrong shapes, a
                # mirrored row failed with KeyError), and their scores are the old shapes'
                self.leave_heat_map()
                self.rows = []
                self.panel.set_pairs([])
                self.panel.pair_info.setText("The shapes changed: Find Pairs to rank them again.")
        elif self.rows:       # a corrective saved, mirrored or deleted, a shape renamed: the listed rows say so
            rig = self.document.rig
            self.panel.set_pair_names([_row_names(rig.shape_names, r) for r in self.rows])
            self.panel.set_pair_correctives([corrective_status(rig, r) for r in self.rows])
            row = self.panel.selected_pair_row()
            if 0 <= row < len(self.rows):
                pair = [rig.shape_names[self.rows[row].i], rig.shape_names[self.rows[row].j]]
                self.panel.set_pair_action(find_corrective(rig.correctives, pair) is not None)

    @property
    def pairs(self) -> list[tuple[int, int, float]]:
        """The listed rows as (i, j, score)."""
        return [(r.i, r.j, r.score) for r in self.rows]

    @property
    def pair_mirrors(self) -> list[tuple[int, int, float] | None]:
        """Each listed row's mirror pair, when it stands for both sides."""
        return [r.mirror for r in self.rows]

    def find_pairs_in_background(self) -> None:
        """Find Pairs (the panel's button, Ctrl+Shift+F): the scores of the panel's measure are computed on a worker
        (``pair_scores``: 0.3-0.5 s on ICT, a pass over every pair of shapes; the window froze for it), the panel
        saying so, then listed by ``find_pairs``; scores already computed for these shapes are listed at once."""
        rig = self.document.rig
        if rig is None:
            return
        measure = self.measure
        self.shapes_changed()
        if measure in self._overlap:
            self.find_pairs()
            return
        deltas = rig.deltas
        areas = self._areas

        def job():
            return pair_scores(rig, measure, rig_vertex_areas(rig) if areas is None else areas)

        def done(scores) -> None:
            self.panel.find_button.setEnabled(True)
            self.panel.pair_info.setText(PAIR_HINT)
            if self.document.rig is rig and rig.deltas is deltas:   # else the shapes changed meanwhile: stale
                self._overlap[measure] = scores
                self._scored_deltas = deltas
                self.find_pairs()

        def failed(message: str) -> None:
            self.panel.find_button.setEnabled(True)
            self.panel.pair_info.setText(PAIR_HINT)
            self.window.show_error("Find Interfering Pairs", message)

        self.panel.find_button.setEnabled(False)
        self.panel.set_pairs([])
        self.panel.pair_info.setText("Ranking the shape pairs…")
        self._runner.submit(job, done, failed)

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
            try:
                self._overlap[measure] = pair_scores(rig, measure, self.vertex_areas())
                self._scored_deltas = rig.deltas
            finally:
                QtWidgets.QApplication.restoreOverrideCursor()
        self._pairs_measure = measure
        names = rig.shape_names
        self.rows = ranked_pairs(self._overlap[measure], names, self.panel.top.value(),
                                 merge_mirrored=self.panel.merge_mirrored.isChecked(),
                                 partner_of=self.panel.partner_of.currentData())
        listed = []
        for r in self.rows:
            a, b, twin = _row_names(names, r)
            listed.append((a, b, r.score, twin, corrective_status(rig, r)))
        self.panel.set_pairs(listed)
        self.leave_heat_map()
        return self.pairs

    @property
    def measure(self) -> str:
        """The finder's measure, one of ``model.interference.MEASURES``: "overshoot" (default), "overlap", "directional"."""
        return self.panel.measure.currentData()

    def show_pair(self, row: int) -> None:
        """Colour the face by where the selected pair interferes (a colour bar in rig units): the overshoot of
        their sum for the overshoot measure, else min(‖d_i‖, ‖d_j‖)."""
        if row < 0 or row >= len(self.rows):
            self.leave_heat_map()
            return
        rig = self.document.rig
        pair = self.rows[row]
        overshoot = self._pairs_measure == "overshoot"
        self.heat = pair_heat(rig, pair, self._pairs_measure)
        if self._saved_colormap is _UNSET:
            self._saved_colormap = self.viewport.colormap
        top = float(self.heat.max())
        title = f"overshoot ({rig.units})" if overshoot else f"interference ({rig.units})"
        # framed with the face (the camera presets, F, a framing made again beside the colour bar): the brows'
        # overshoot runs up the forehead, above where the shapes act most, and was cut by the view's top edge
        self._heat_colormap = ColorMap(self.heat, title=title, cmap="YlOrRd", clim=(0.0, top if top > 0 else 1.0),
                                       marked=hot_vertices(self.heat))
        self.viewport.set_colormap(self._heat_colormap)
        n, area = hot_area(self.heat, self.vertex_areas())
        what = "‖d_i + d_j‖ − max(‖d_i‖, ‖d_j‖)" if overshoot else "min(‖d_i‖, ‖d_j‖)"
        names = rig.shape_names
        i, j, mirror = pair.i, pair.j, pair.mirror
        if mirror is not None:
            own = float(self._overlap[self._pairs_measure][i, j])
            score_text = (f"{names[i]} × {names[j]} and {names[mirror[0]]} × {names[mirror[1]]}: scores "
                          f"{own:.3f} and {mirror[2]:.3f}")
        else:
            score_text = f"{names[i]} × {names[j]}: score {pair.score:.3f}"
        self.panel.set_pair_action(find_corrective(rig.correctives, [names[i], names[j]]) is not None)
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
        if row < 0 or row >= len(self.rows):
            return
        i, j = self.rows[row].i, self.rows[row].j
        names = self.document.rig.shape_names
        self.leave_heat_map()
        self._start_authoring([names[i], names[j]], self.panel.current_rule())


def _row_names(names: list[str], row) -> tuple[str, str, str]:
    """A listed row's (shape, shape, its mirror pair as text or "") by the shapes' names now."""
    return names[row.i], names[row.j], "" if row.mirror is None else f"{names[row.mirror[0]]} × {names[row.mirror[1]]}"
