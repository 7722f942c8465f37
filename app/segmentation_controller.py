"""Connects the Segmentation panel, the document and the viewport; runs segmentation off the GUI thread.

Everything that depends only on the rig (graph, Laplacian, maps, sorted values) lives in one
SegmentationCache, so moving the threshold or the level redraws live (ALGORITHMS.md §2–3).
"""
from __future__ import annotations

import time

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.background import BackgroundRunner
from app.commands import AddShapeCommand, SetEditOffsetCommand, SetSectionCommand, added_shape
from app.map_views import deformation_colormap, region_palette, segmentation_colormap
from model.errors import RigInputError
from model.segmentation import SegmentationCache, SegmentationSettings, region_statistics, segment_rig
from model.wording import count, duration
from solvers.laplacian import mesh_adjacency
from solvers.region_nudge import nudge_region, ring_falloff

SECTION = "segmentation"


def _appended(rig, seen: tuple) -> bool:
    """Whether ``rig`` differs from the (neutral, deltas, names) a segmentation was made of only by shapes added
    at the end of either (the same neutral object and the same shapes before)."""
    neutral, deltas, names = seen
    k = min(len(names), rig.n_shapes)
    return (rig.neutral is neutral and len(names) != rig.n_shapes and list(rig.shape_names[:k]) == names[:k]
            and np.array_equal(rig.deltas[:k], deltas[:k]))


class SegmentationController(QtCore.QObject):
    segmentation_ready = QtCore.Signal()   # a new segmentation is shown (tests wait on it)

    def __init__(self, window, panel, parent=None) -> None:
        super().__init__(parent or window)
        self.window, self.panel = window, panel
        self.document, self.viewport = window.document, window.viewport
        self.cache = SegmentationCache()
        self.runner = BackgroundRunner(self)
        self.segmentation = None
        self.maps = None
        self.map_kind = SegmentationSettings().map_kind   # the map thresholded by the last segmentation asked for
        self.level = 0
        self.view = "shaded"
        self.shape_map = -1
        self.view_override = None   # a callable giving the colour map shown instead (the personalisation heat map)
        self.highlight: int | None = None
        self._last_nudge: tuple[int, str] | None = None   # (region, direction): names a saved nudge
        self.last_seconds = 0.0
        self._segmented: tuple | None = None  # (neutral, deltas, shape names) the segmentation is of
        self._start_pending = False   # a new rig's segmentation waits for its first render (``_on_rig_change``)
        d = self.document
        d.rig_changed.connect(self._on_rig_change)
        d.shapes_changed.connect(self._on_shapes_change)
        d.section_changed.connect(self._on_section_change)
        p = panel
        p.view_changed.connect(self._on_view_change)
        p.shape_map_changed.connect(self._on_shape_map_change)
        p.settings_previewed.connect(self.recompute)
        p.settings_committed.connect(self.commit_settings)
        p.level_changed.connect(self._on_level_change)
        p.region_selected.connect(self._on_region_selected)
        p.nudge_requested.connect(self.nudge)
        p.save_nudge_requested.connect(self.save_nudge_as_shape)
        self.viewport.picked.connect(self._on_picked)

    # --- settings ----------------------------------------------------------------------------------
    def settings(self) -> dict:
        stored = self.document.section(SECTION) if self.document.project else None
        try:
            return SegmentationSettings.from_dict(stored or {}).to_dict()
        except RigInputError:
            return SegmentationSettings().to_dict()

    def commit_settings(self, new: dict) -> None:
        try:
            SegmentationSettings.from_dict(new)
        except RigInputError as exc:
            self.panel.set_status(str(exc))
            return
        old = self.document.section(SECTION)
        if old != new:
            self.document.undo_stack.push(SetSectionCommand(self.document, SECTION, old, new, "Segmentation settings"))

    def _on_section_change(self, name: str) -> None:
        if name == SECTION:
            self.panel.set_settings(self.settings())
            self.recompute(self.settings())

    def _on_shapes_change(self) -> None:
        """Shapes or correctives edited: the segmentation depends on the neutral and the shapes only (edits
        always replace those arrays), so a corrective edit keeps it instead of recomputing it."""
        rig, seen = self.document.rig, self._segmented
        if (rig is not None and seen is not None and self.segmentation is not None and rig.neutral is seen[0]
                and rig.deltas is seen[1] and list(rig.shape_names) == seen[2]):
            return
        if (rig is not None and seen is not None and self.segmentation is not None and rig.neutral is seen[0]
                and rig.deltas is seen[1] and len(rig.shape_names) == len(seen[2])):
            # shapes renamed (the Shapes list): the same arrays, so the same regions and maps; the region list names
            # each region's most active shapes by their new names (it kept the old ones)
            renamed = dict(zip(seen[2], rig.shape_names))
            self._segmented = (rig.neutral, rig.deltas, list(rig.shape_names))
            self.stats = [[dict(row, shapes=[(renamed.get(n, n), share) for n, share in row["shapes"]]) for row in rows]
                          for rows in self.stats]
            self._show_regions()
            if self.highlight is not None:
                self.panel.select_region(self.highlight)
            self._follow_shape_choice(rig.shape_names)
            return
        if rig is not None and seen is not None and self.segmentation is not None and _appended(rig, seen):
            # a shape added at the end (Save as new shape, Mirror to a new side) or its undo: the regions stay,
            # with the selection (re-segmenting changed 39 regions to 29 and dropped the region being nudged)
            self._segmented = (rig.neutral, rig.deltas, list(rig.shape_names))
            self._follow_shape_choice(rig.shape_names)
            return
        self._on_rig_change()

    def _follow_shape_choice(self, names: list[str]) -> None:
        """The same shapes renamed, or one added or taken off at the end: the map shown stays the chosen shape's
        (its place, its colour bar under its new name), or, when that shape is gone, the combined map, as the Shape
        choice says."""
        self.panel.set_shapes(names, keep_place=True)
        k = self.panel.shape_choice()
        if k != self.shape_map or (k >= 0 and self.view == "deformation"):
            self.shape_map = k
            self.refresh_view()

    def _on_rig_change(self) -> None:
        rig = self.document.rig
        # the arrays themselves (not their ids, which a new array may reuse): what this segmentation is of
        self._segmented = None if rig is None else (rig.neutral, rig.deltas, list(rig.shape_names))
        self.cache = SegmentationCache()  # the old one may still be in use by a running job
        self.segmentation = None
        self.maps = None
        self.highlight = None
        self.panel.set_shapes(self.document.rig.shape_names)
        # the shape whose map is shown is the one the Shape choice names (kept by its name, else the combined
        # map): its index was kept, and showed another shape's map, or failed on a rig with fewer shapes
        self.shape_map = self.panel.shape_choice()
        self.panel.set_units(self.document.rig.units)
        self.panel.set_settings(self.settings())
        self.panel.set_levels([], 0)          # the last rig's regions are not this one's
        self.panel.set_regions([], [])
        self.panel.set_status("segmenting…")
        # Started once the window has taken the new rig in (the layout and paint events the change posted are
        # handled before a zero timer fires) and drawn it (``when_drawn``): a segmentation running meanwhile made
        # each of the hundreds of Python calls those events make wait for the interpreter, ~3 s more of a frozen
        # window on a 422k-vertex rig, and the rig's first render 0.04-0.15 s more
        arrays = self._segmented
        self._start_pending = True

        def start() -> None:
            if self._segmented is arrays:
                self._start_pending = False
                self.recompute(self.settings())
        QtCore.QTimer.singleShot(0, self, lambda: self.window.when_drawn(start))

    # --- background work ---------------------------------------------------------------------------
    def recompute(self, settings: dict) -> None:
        rig = self.document.rig
        if rig is None:
            return
        cache = self.cache
        s = SegmentationSettings.from_dict(settings)
        arrays = (rig.neutral, rig.face_counts, rig.face_indices, rig.deltas)
        names = list(rig.shape_names)
        self.map_kind = s.map_kind

        def job():
            t0 = time.perf_counter()
            cache.bind(*arrays)            # a rig with nothing to map raises here: no maps, no segmentation
            try:
                seg = segment_rig(*arrays, s, cache=cache)
            except RigInputError as exc:   # no region (a small mesh, a high threshold): the maps still show
                return None, cache.maps(s.laplacian), str(exc), 0.0
            maps = cache.maps(s.laplacian)
            stats = [region_statistics(seg, maps, names, level=i) for i in range(len(seg.levels))]
            seconds = time.perf_counter() - t0
            # the vector view's vectors, made here rather than when the view is chosen: 0.1-0.2 s of a frozen
            # window on the 422k-vertex studio rig (``deformation_colormap`` reads the uniform Laplacian's maps)
            cache.maps().vector
            return seg, maps, stats, seconds

        self.panel.set_status("segmenting…")
        self.runner.submit(job, self._on_done, self._on_failed)

    def _on_done(self, result) -> None:
        if result[0] is None:
            self.maps = result[1]
            self._on_failed(result[2])
            return
        self.segmentation, self.maps, self.stats, self.last_seconds = result
        counts = [lvl.n_regions for lvl in self.segmentation.levels]
        self.level = min(self.level, len(counts) - 1)
        self.panel.set_levels(counts, self.level)
        self.highlight = None
        self._show_regions()
        self.refresh_view()
        self.segmentation_ready.emit()

    def _on_failed(self, message: str) -> None:
        self.segmentation = None
        self.panel.set_status(f"No segmentation: {message}")
        self.panel.set_levels([], 0)   # no level count of the last segmentation beside it
        self.panel.set_regions([], [])
        if self.view != "shaded":
            self.refresh_view()
        self.segmentation_ready.emit()

    # --- view --------------------------------------------------------------------------------------
    def _show_regions(self) -> None:
        if self.segmentation is None:
            return
        rows = self.stats[self.level]
        self.panel.set_regions(rows, region_palette(len(rows)))
        levels = self.segmentation.levels
        self.panel.set_status(f"{count(levels[self.level].n_regions, 'region')} at level {self.level} · "
                              f"{count(len(levels), 'level')} · {duration(self.last_seconds)}")

    def _on_view_change(self, view: str) -> None:
        self.view = view
        self.refresh_view()

    def _on_shape_map_change(self, k: int) -> None:
        self.shape_map = k
        self.refresh_view()

    def set_level(self, level: int) -> None:
        """Show hierarchy level ``level`` (clamped to the segmentation's levels when it is ready)."""
        if self.segmentation is None:
            self.level = level      # taken when the segmentation in progress arrives
            return
        self.panel.set_levels([lvl.n_regions for lvl in self.segmentation.levels], level)
        self._on_level_change(self.panel.level.value())

    def _on_level_change(self, level: int) -> None:
        self.level = level
        self.highlight = None
        self._show_regions()
        self.refresh_view()

    def _on_region_selected(self, region: int) -> None:
        self.highlight = region if region >= 0 else None
        if self.view == "segmentation":
            self.refresh_view()

    def _on_picked(self, vertex: int, point) -> None:
        if self.segmentation is None or self.view != "segmentation":
            return
        labels = self.segmentation.levels[self.level].core_labels()
        region = int(labels[vertex])
        self.highlight = region if region >= 0 else None
        self.panel.select_region(region)
        self.refresh_view()

    def colormap(self):
        """The colour map of the chosen view. The deformation maps need no regions: they show when the threshold
        (or a mesh smaller than the minimum region) leaves none, which is when they are needed to choose another."""
        rig = self.document.rig
        if self.view in ("deformation", "deformation-rgb"):
            if self.maps is None:
                return None
            k = self.shape_map if self.shape_map >= 0 else None
            kind = self.segmentation.map_kind if self.segmentation is not None else self.map_kind
            return deformation_colormap(self.cache, rig, self.view, k, kind)
        if self.view == "shaded" or self.segmentation is None:
            return None
        return segmentation_colormap(self.segmentation, self.level, self.highlight)

    def refresh_view(self) -> None:
        override = self.view_override
        self.viewport.set_colormap(override() if override is not None else self.colormap())

    def wait(self, msecs: int = 60000) -> None:
        """Wait for the segmentation of the current rig (started, or still to start once the window has drawn the
        rig) and deliver it (tests, benchmarks)."""
        deadline = QtCore.QDeadlineTimer(msecs)
        while self._start_pending and not deadline.hasExpired():
            QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.AllEvents, 5)
            QtCore.QThread.msleep(1)
        self.runner.wait(max(0, deadline.remainingTime()))

    # --- nudge (Acosta) ----------------------------------------------------------------------------
    def nudge(self, direction: str, amount: float) -> None:
        if self.segmentation is None or self.highlight is None:
            self.window.show_status("Select a region to nudge (click it in the list or the viewport).")
            return
        rig, doc = self.document.rig, self.document
        lvl = self.segmentation.levels[self.level]
        region = lvl.regions[self.highlight]
        adjacency = self.cache.adjacency
        if adjacency is None:
            adjacency = mesh_adjacency(rig.n_vertices, rig.face_counts, rig.face_indices)
        phi = ring_falloff(adjacency, region.core, region.vertices)   # smooth over the overlap rings
        if direction in ("out", "in"):
            vec = direction
        else:
            cam = self.viewport.camera_frame()
            vec = {"up": cam.up, "down": -cam.up, "right": cam.right, "left": -cam.right}[direction]
        current = doc.surface().astype(np.float64)
        moved = nudge_region(current, region.vertices, amount, direction=vec, weights=phi,
                             face_counts=rig.face_counts, face_indices=rig.face_indices)
        old = doc.edit_offset
        new = (np.zeros_like(current) if old is None else old) + (moved - current)
        doc.undo_stack.push(SetEditOffsetCommand(doc, old, new, f"Nudge region {self.highlight} {direction}"))
        self._last_nudge = (self.highlight, direction)

    def nudge_shape_name(self) -> str:
        """The name Save as New Shape suggests: the region and direction of the last nudge (``region12_out``),
        made unique (``region12_out_2``)."""
        region, direction = self._last_nudge or (self.highlight, "nudge")
        base = f"region{region}_{direction}"
        names, name, i = set(self.document.rig.shape_names), base, 2
        while name in names:
            name, i = f"{base}_{i}", i + 1
        return name

    def save_nudge_as_shape(self, name: str | None = None) -> None:
        """Store the pending nudge as a new shape, set to 1 so the face stays as it is; one undo step. The
        shape is the nudge alone (the pose stays in the other weights)."""
        doc = self.document
        if doc.edit_offset is None:
            self.window.show_status("Nothing to save: nudge a region first.")
            return
        rig = doc.rig
        if name is None:
            name, ok = QtWidgets.QInputDialog.getText(self.window, "Save as New Shape", "Shape name:",
                                                      text=self.nudge_shape_name())
            if not ok or not name.strip():
                return
        name = name.strip()
        if name in rig.shape_names:
            self.window.show_error("Could not add the shape", f"A shape named '{name}' already exists.")
            return
        delta = np.asarray(doc.edit_offset, dtype=np.float64)
        version, offset = doc.rig_version, doc.edit_offset

        def add(prepared) -> None:   # back on the GUI thread
            if doc.rig_version != version or doc.edit_offset is not offset or name in doc.rig.shape_names:
                self.window.show_status(f"The rig or the nudge changed meanwhile: {name} was not added.")
                return
            doc.undo_stack.push(AddShapeCommand(doc, name, delta, f"Save nudge as shape {name}", weight=1.0,
                                                prepared=prepared))
            self.window.show_status(f"Added shape {name}, set to 1.")
        # the new rig's deltas and evaluator (a studio rig's hundreds of MB) are made off the GUI thread; the edit is
        # applied when they are ready
        self.window.run_in_background(f"Adding shape {name}…", lambda: added_shape(doc, name, delta), add)
