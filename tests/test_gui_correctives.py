"""Corrective shapes in the GUI (pytest-qt, sample rig): a real sculpt stroke saved as a corrective,
undo, a corrective from a scan, the live activation list, the interference heat map, bad input."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from model.obj_io import write_obj
from model.pose import PoseEvaluator
from tests.gui_helpers import combo_text_shown_whole, key_on_shape_name, make_window, mouse

PAIR = ["browInnerUp_L", "browInnerUp_R"]


@pytest.fixture
def win(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    ctrl = w.correctives
    ctrl.dock.show()
    ctrl.dock.raise_()
    QtCore.QCoreApplication.processEvents()
    return w, ctrl


def _settle(qtbot, w):
    qtbot.waitUntil(lambda: not w.redraw_pending)
    QtCore.QCoreApplication.processEvents()


def _display_xy(w, point):
    """Qt widget coordinates of a world point on the viewport (VTK display y is flipped, device pixels)."""
    xd, yd, _ = w.viewport.world_to_display(point)[0]
    return w.viewport.display_to_qt(xd, yd), (xd, yd)


def _forehead_vertex(rig, surface):
    """A front-facing vertex between the brows that both drivers move."""
    a, b = (np.linalg.norm(rig.deltas[rig.shape_index(n)], axis=1) for n in PAIR)
    both = np.flatnonzero((a > 0.2 * a.max()) & (b > 0.2 * b.max()))
    assert both.size > 0
    return int(both[np.argmax(surface[both, 2] - 0.5 * np.abs(surface[both, 0]))])


def _pose(w, weights):
    w.document.set_weights(weights)
    return w.document.surface().copy()


def test_real_sculpt_stroke_saved_as_corrective_and_undone(qtbot, win):
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    ctrl.panel.set_ticked(PAIR)
    ctrl.panel.new_button.click()
    _settle(qtbot, w)
    assert ctrl.sculpting and ctrl.authoring == PAIR
    scroll = ctrl.panel.parentWidget()
    while not isinstance(scroll, QtWidgets.QScrollArea):
        scroll = scroll.parentWidget()
    view = scroll.viewport()                             # the Save button has been scrolled into view
    save = ctrl.panel.save_button
    qtbot.waitUntil(lambda: view.rect().contains(QtCore.QRect(save.mapTo(view, QtCore.QPoint(0, 0)), save.size())))
    full = np.zeros(rig.n_shapes)
    full[[rig.shape_index(n) for n in PAIR]] = 1
    np.testing.assert_array_equal(doc.weights, full)   # the drivers at 1: one undoable pose change
    steps = doc.undo_stack.count()
    before = doc.surface().copy()
    ctrl.set_brush("grab")
    ctrl.panel.radius.setValue(2.0)
    ctrl.panel.symmetric.setChecked(True)
    v = _forehead_vertex(rig, before)
    start, (xd, yd) = _display_xy(w, before[v])
    hit = w.viewport.pick(int(round(xd)), int(round(yd)))
    assert hit is not None and np.linalg.norm(rig.neutral[hit.vertex] - rig.neutral[v]) < 1.0
    widget = w.viewport.canvas
    camera_before = w.viewport.camera_frame().position
    mouse(widget, "press", start)
    for dy in (8, 16, 24, 32, 40):
        mouse(widget, "move", start + QtCore.QPointF(0, -dy))
    mouse(widget, "release", start + QtCore.QPointF(0, -40))
    _settle(qtbot, w)
    np.testing.assert_array_equal(w.viewport.camera_frame().position, camera_before)  # no rotation
    assert doc.undo_stack.count() == steps + 1          # one stroke, one undo step
    moved = np.linalg.norm(doc.edit_offset, axis=1)
    assert moved[hit.vertex] > 0.2 and moved.max() < 10.0   # the brow was pulled up by the drag
    assert doc.edit_offset[hit.vertex, 1] > 0.2             # upwards on screen is +y from the front camera
    centre = np.asarray(hit.position)
    far = (np.linalg.norm(before - centre, axis=1) > 2.4) & \
        (np.linalg.norm(before * [-1, 1, 1] - centre, axis=1) > 2.4)   # outside the brush and its mirror
    assert far.sum() > rig.n_vertices // 2 and np.all(moved[far] == 0)
    np.testing.assert_allclose(w.viewport.points(), doc.surface())
    sculpted = doc.surface().copy()

    assert ctrl.save()
    _settle(qtbot, w)
    assert doc.undo_stack.count() == steps + 2 and doc.edit_offset is None and not ctrl.sculpting
    assert [c.name for c in rig.correctives] == ["browInnerUp_L+browInnerUp_R"]
    assert ctrl.panel.names() == ["browInnerUp_L+browInnerUp_R"]
    np.testing.assert_allclose(doc.surface(), sculpted, atol=1e-5)       # drivers at 1: the sculpt
    np.testing.assert_allclose(w.viewport.points(), sculpted, atol=1e-5)
    # one driver at 0: the corrective adds exactly nothing
    one = full.copy()
    one[rig.shape_index(PAIR[1])] = 0
    with_corr = _pose(w, one)
    bare = rig.copy()
    bare.correctives = []
    assert PoseEvaluator(rig).activations(one)[0] == 0.0
    np.testing.assert_array_equal(with_corr, PoseEvaluator(bare).evaluate(one))
    doc.set_weights(full)
    # undo the save, then the stroke: exact restoration
    doc.undo_stack.undo()
    assert rig.correctives == [] and doc.edit_offset is not None
    np.testing.assert_array_equal(doc.surface(), sculpted)
    doc.undo_stack.undo()
    assert doc.edit_offset is None
    np.testing.assert_array_equal(doc.surface(), before)
    _settle(qtbot, w)
    np.testing.assert_array_equal(w.viewport.points(), before)


def _sculpting_the_pair(qtbot, w, ctrl):
    """Sculpt the browInnerUp pair: (the Qt position of a forehead vertex, the viewport's canvas)."""
    doc = w.document
    assert ctrl.start_authoring(PAIR)
    _settle(qtbot, w)
    v = _forehead_vertex(doc.rig, doc.surface())
    start, _ = _display_xy(w, doc.surface()[v])
    return start, w.viewport.canvas


def test_smooth_and_inflate_strokes_are_one_step_each(qtbot, win):
    w, ctrl = win
    doc = w.document
    start, widget = _sculpting_the_pair(qtbot, w, ctrl)
    n0 = doc.undo_stack.count()
    ctrl.set_brush("inflate")
    mouse(widget, "press", start)
    mouse(widget, "move", start + QtCore.QPointF(4, 0))
    mouse(widget, "release", start + QtCore.QPointF(4, 0))
    assert doc.undo_stack.count() == n0 + 1
    grown = np.linalg.norm(doc.edit_offset, axis=1).max()
    assert grown > 0
    ctrl.set_brush("smooth")
    mouse(widget, "press", start)
    mouse(widget, "release", start)
    assert doc.undo_stack.count() == n0 + 2
    doc.undo_stack.undo()
    assert np.linalg.norm(doc.edit_offset, axis=1).max() == grown
    # dragging off the face turns the view instead of sculpting
    corner = QtCore.QPointF(5, 5)
    mouse(widget, "press", corner)
    mouse(widget, "move", corner + QtCore.QPointF(30, 30))
    mouse(widget, "release", corner + QtCore.QPointF(30, 30))
    assert doc.undo_stack.count() == n0 + 2 and doc.undo_stack.index() == n0 + 1   # no new step
    ctrl.stop_sculpting()
    assert not w.viewport.has_tool(ctrl.sculpt)  # the brushes leave the viewport outside sculpt mode


def test_corrective_from_scan_reproduces_the_scan(qtbot, win, tmp_path):
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    x_pair = PoseEvaluator(rig, dtype=np.float64).evaluate(np.where(
        np.isin(rig.shape_names, PAIR), 1.0, 0.0))
    centre = x_pair[_forehead_vertex(rig, x_pair)]
    r = np.linalg.norm(x_pair - centre, axis=1) / 2.0
    bump = (np.clip(1 - r, 0, None) ** 2 * 0.4)[:, None] * np.array([0.0, 0.3, 1.0])
    scan = x_pair + bump
    path = tmp_path / "scan.obj"
    write_obj(path, scan, rig.face_counts, rig.face_indices)
    ctrl.panel.set_ticked(PAIR)
    n0 = doc.undo_stack.count()
    qtbot.waitUntil(lambda: w.segmentation.segmentation is not None, timeout=30000)
    segmentation = w.segmentation.segmentation
    assert ctrl.from_scan(path, mode="drivers")
    _settle(qtbot, w)
    assert doc.undo_stack.count() == n0 + 1
    assert w.segmentation.segmentation is segmentation  # a corrective leaves the shapes' segmentation alone
    np.testing.assert_allclose(doc.surface(), scan, atol=1e-5)
    np.testing.assert_allclose(w.viewport.points(), scan, atol=1e-5)
    assert ctrl.panel.activation_texts() == ["1.000"]
    doc.undo_stack.undo()
    assert rig.correctives == []
    # fitting the weights: the fit finds the pair, the residual over the drivers' region is kept
    assert ctrl.from_scan(path, mode="fit")
    w_fit = doc.weights
    assert w_fit[[rig.shape_index(n) for n in PAIR]].min() > 0.5
    from solvers.correctives import driver_region
    region = driver_region(rig.deltas[[rig.shape_index(n) for n in PAIR]])
    posed = PoseEvaluator(rig, dtype=np.float64).evaluate(w_fit)
    from model.obj_io import read_obj
    on_file = read_obj(path).vertices.astype(np.float64)   # the scan as written (6 decimals)
    assert np.abs(posed[region == 1] - on_file[region == 1]).max() < 1e-9
    assert np.abs(posed - on_file).max() < 0.5 * np.abs(bump).max()


def test_bad_input_is_refused_with_one_clear_sentence(qtbot, win, tmp_path):
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    path = tmp_path / "small.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert not ctrl.from_scan(path, drivers=PAIR)
    assert w.last_error == (f"small.obj has 3 vertices but the rig has {rig.n_vertices}; a scan must have the "
                            "rig's vertices in the same order.")
    assert rig.correctives == [] and doc.undo_stack.count() == 0
    assert not ctrl.start_authoring(["browInnerUp_L"])
    assert "two or more driver shapes" in w.last_error
    assert not ctrl.start_authoring(["browInnerUp_L", "browSideways_L"])
    assert "no shape named 'browSideways_L'" in w.last_error
    assert not ctrl.sculpting and doc.undo_stack.count() == 0
    ctrl.panel.set_ticked([])
    ctrl.panel.new_button.click()                    # nothing ticked and nothing posed
    assert "two or more" in w.last_error
    # a cycle: drivers naming a corrective
    assert ctrl.start_authoring(PAIR)
    ctrl.panel.radius.setValue(1.0)
    doc.set_edit_offset(np.full((doc.rig.n_vertices, 3), 0.01))
    assert ctrl.save()
    name = doc.rig.correctives[0].name
    assert not ctrl.edit_drivers(name, [name, "browOuterUp_L"])
    assert w.last_error == (f"'{name}' is a corrective, not a shape: a corrective driven by a corrective "
                            "would make the hierarchy a cycle.")
    assert not ctrl.start_authoring([name, "browOuterUp_L"])
    assert "cycle" in w.last_error
    assert not ctrl.rename(name, "jawOpen")
    assert "same name as a shape" in w.last_error
    assert [c.drivers for c in doc.rig.correctives] == [PAIR]


def test_panel_lists_correctives_with_live_activation_and_undoable_edits(qtbot, win):
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    assert ctrl.start_authoring(PAIR, "product")
    doc.set_edit_offset(np.where(np.arange(rig.n_vertices)[:, None] % 7 == 0, 0.02, 0.0) * np.ones(3))
    assert ctrl.save()
    ctrl.panel.set_ticked(["browOuterUp_L", "browOuterUp_R"])
    ctrl.panel.new_button.click()
    doc.set_edit_offset(np.full((rig.n_vertices, 3), 0.01))
    assert ctrl.save()
    assert sorted(ctrl.panel.names()) == ["browInnerUp_L+browInnerUp_R", "browOuterUp_L+browOuterUp_R"]
    row = ctrl.panel.names().index("browInnerUp_L+browInnerUp_R")
    w_ = np.zeros(rig.n_shapes)
    w_[rig.shape_index(PAIR[0])], w_[rig.shape_index(PAIR[1])] = 0.5, 0.8
    w.set_pose(w_, "test pose")                              # pose_changed updates the activations
    assert ctrl.panel.activation_texts()[row] == "0.400"
    assert ctrl.panel.activation_texts()[1 - row] == "0.000"
    n = doc.undo_stack.count()
    ctrl.panel.select("browInnerUp_L+browInnerUp_R")
    ctrl.panel.rule.setCurrentIndex(ctrl.panel.rule.findData("min"))   # rule edit from the panel
    assert doc.undo_stack.count() == n + 1
    assert ctrl.panel.activation_texts()[ctrl.panel.names().index("browInnerUp_L+browInnerUp_R")] == "0.500"
    assert ctrl.rename("browInnerUp_L+browInnerUp_R", "innerBrows")
    assert "innerBrows" in ctrl.panel.names()
    ctrl.panel.select("innerBrows")
    w.activateWindow()
    ctrl.panel.table.setFocus()
    qtbot.waitUntil(ctrl.panel.table.hasFocus)
    qtbot.keyClick(ctrl.panel.table, QtCore.Qt.Key_Delete)      # the Delete key in the list
    assert ctrl.panel.names() == ["browOuterUp_L+browOuterUp_R"]
    for _ in range(3):
        doc.undo_stack.undo()
    c = next(c for c in rig.correctives if c.drivers == PAIR)
    assert c.name == "browInnerUp_L+browInnerUp_R" and c.rule == "product"
    assert ctrl.panel.activation_texts()[ctrl.panel.names().index(c.name)] == "0.400"


def _pixels_of_vertices(w, h, wd):
    """(column, row, inside the picture) of each vertex of the viewport's surface in its (h, wd) picture now."""
    d = w.viewport.world_to_display(np.asarray(w.viewport.mesh.points))
    col, row = np.round(d[:, 0]).astype(int), np.round(h - 1 - d[:, 1]).astype(int)
    return col, row, (col >= 0) & (col < wd) & (row >= 0) & (row < h)


def _assert_heat_picture(w, heat_img, heat, heat_pixels):
    """The picture shows the heat where it is: the pixels at the hottest front-facing vertices (``heat_pixels``:
    ``_pixels_of_vertices`` as the heat map was shown) changed from the same vertices' in the shaded view (shown
    again after it, framed again without the heat map's bar) and are coloured far from those where the pair does
    not interfere."""
    from tests.image_compare import LEVELS
    shaded_img = w.viewport.picture()
    mesh = w.viewport.mesh.compute_normals(point_normals=True, cell_normals=False, auto_orient_normals=False)
    front = np.asarray(mesh.point_data["Normals"])[:, 2] > 0.7
    h, wd = heat_img.shape[:2]
    col, row, seen = heat_pixels
    s_col, s_row, s_seen = _pixels_of_vertices(w, h, wd)
    inside = front & seen & s_seen
    hot, cold = inside & (heat >= 0.5 * heat.max()), inside & (heat == 0)
    changed = np.abs(heat_img[row % h, col % wd].astype(int)
                     - shaded_img[s_row % h, s_col % wd].astype(int)).max(axis=1)
    assert hot.sum() >= 20 and cold.sum() >= 500                     # measured: 48 and 1,756 vertices
    assert (changed[hot] > LEVELS).mean() > 0.9                      # coloured where the pair interferes (98 %)
    hot_colour, cold_colour = (np.median(heat_img[row[m], col[m]].astype(float), axis=0) for m in (hot, cold))
    assert np.abs(hot_colour - cold_colour).max() > 80               # dark red against pale yellow


def test_interference_heat_map_and_pair_authoring(qtbot, win, tmp_path):
    w, ctrl = win
    rig = w.document.rig
    ctrl.panel.tabs.setCurrentIndex(1)
    pairs = ctrl.finder.find_pairs()
    assert len(pairs) == ctrl.panel.top.value() and ctrl.panel.pairs.topLevelItemCount() == len(pairs)
    scores = [s for _, _, s in pairs]
    assert scores == sorted(scores, reverse=True) and 0 < scores[0] <= 1
    # the default measure, overshoot: the heat map is how far the pair's sum goes beyond the larger shape
    assert ctrl.finder.measure == "overshoot"
    ctrl.panel.select_pair(0)
    def excess(i, j):
        d_i, d_j = rig.deltas[i], rig.deltas[j]
        larger = np.maximum(np.linalg.norm(d_i, axis=1), np.linalg.norm(d_j, axis=1))
        return np.maximum(np.linalg.norm(d_i + d_j, axis=1) - larger, 0.0)
    i, j, _ = pairs[0]
    mirror = ctrl.finder.pair_mirrors[0]            # the row stands for both sides: so does its heat map
    expected = excess(i, j) if mirror is None else np.maximum(excess(i, j), excess(*mirror[:2]))
    np.testing.assert_allclose(w.viewport.colormap.scalars, expected, atol=1e-12)
    assert w.viewport.colormap.title.startswith("overshoot") and w.viewport.colormap.scalars.max() > 0
    # the partners of one shape: the other inner brow first, as Smith's brow example has it
    ctrl.panel.partner_of.setCurrentIndex(ctrl.panel.partner_of.findData("browInnerUp_L"))
    partners = ctrl.finder.find_pairs()
    assert [rig.shape_names[j] for _, j, _ in partners[:2]] == ["browInnerUp_R", "browOuterUp_L"]
    first = ctrl.panel.pairs.topLevelItem(0)
    assert (first.text(2), first.text(3)) == ("browInnerUp_L", "browInnerUp_R")
    ctrl.panel.select_pair(0)     # the summary gives the hot area in rig units²
    assert f"{rig.units}²)" in ctrl.panel.pair_info.text() and "vertices (" in ctrl.panel.pair_info.text()
    # a replaced shape is scored afresh: browInnerUp_R flattened (undoably) is no partner any more
    from app.commands import SetShapeDeltaCommand
    k = rig.shape_index("browInnerUp_R")
    w.document.undo_stack.push(SetShapeDeltaCommand(w.document, "browInnerUp_R", 0.0 * rig.deltas[k], "Flatten"))
    assert "browInnerUp_R" not in [rig.shape_names[j] for _, j, _ in ctrl.finder.find_pairs()[:2]]
    w.document.undo_stack.undo()
    assert [rig.shape_names[j] for _, j, _ in ctrl.finder.find_pairs()[:2]] == ["browInnerUp_R", "browOuterUp_L"]
    ctrl.panel.partner_of.setCurrentIndex(0)
    ctrl.panel.measure.setCurrentIndex(ctrl.panel.measure.findData("directional"))
    directional = ctrl.finder.find_pairs()
    w2 = make_window(qtbot, tmp_path)  # the next session (same settings folder) starts on the chosen measure
    assert w2.correctives.finder.measure == "directional"
    w2.close()
    assert all(s <= 1 for *_, s in directional)
    ctrl.panel.select_pair(0)
    i, j, _ = directional[0]
    cm = w.viewport.colormap
    assert cm is not None and rig.units in cm.title
    def overlap(i, j):
        return np.minimum(np.linalg.norm(rig.deltas[i], axis=1), np.linalg.norm(rig.deltas[j], axis=1))
    mirror = ctrl.finder.pair_mirrors[0]
    np.testing.assert_allclose(cm.scalars, overlap(i, j) if mirror is None else
                               np.maximum(overlap(i, j), overlap(*mirror[:2])))
    assert w.viewport.plotter.scalar_bars
    heat = w.viewport.colormap
    with qtbot.waitSignal(w.segmentation.segmentation_ready, timeout=30000):
        w.segmentation.recompute(w.segmentation.settings())   # a finished segmentation repaints the face...
    assert w.viewport.colormap is heat                       # ...but the heat map stays on top
    heat_img = w.viewport.picture()
    heat_pixels = _pixels_of_vertices(w, *heat_img.shape[:2])
    ctrl.panel.tabs.setCurrentIndex(0)                     # leaving restores the previous (shaded) view
    assert w.viewport.colormap is None
    _assert_heat_picture(w, heat_img, heat.scalars, heat_pixels)
    ctrl.panel.tabs.setCurrentIndex(1)
    ctrl.panel.select_pair(0)
    assert w.viewport.colormap is not None
    ctrl.panel.create_pair_button.click()
    assert w.viewport.colormap is None and ctrl.sculpting
    assert set(ctrl.authoring) == {rig.shape_names[i], rig.shape_names[j]}
    assert w.document.weights[[i, j]].tolist() == [1.0, 1.0] and w.document.weights.sum() == 2.0


def test_mirror_corrective_makes_the_other_side_and_undoes(qtbot, win):
    from solvers.symmetry import mirror_delta, mirror_map
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    left = ["browInnerUp_L", "browOuterUp_L"]
    assert ctrl.start_authoring(left, "min")
    x = rig.neutral
    fix = np.where((x[:, 0] > 0.5)[:, None], np.array([0.0, 0.05, 0.02]), 0.0)  # a fix on one side only
    doc.set_edit_offset(fix)
    assert ctrl.save()
    assert w.statusBar().currentMessage() == ("Saved corrective browInnerUp_L+browOuterUp_L. Mirror (Ctrl+Shift+M) "
                                              "makes the other side's.")
    src = rig.correctives[0]
    n = doc.undo_stack.count()
    ctrl.panel.select(src.name)
    ctrl.panel.mirror_button.click()
    assert doc.undo_stack.count() == n + 1
    made = next(c for c in rig.correctives if c is not src and c.name != src.name)
    assert made.name == "browInnerUp_R+browOuterUp_R" and made.drivers == ["browInnerUp_R", "browOuterUp_R"]
    assert made.rule == "min"
    np.testing.assert_allclose(made.delta, mirror_delta(src.delta, mirror_map(rig.neutral)))
    assert np.abs(made.delta[x[:, 0] > 0.5]).max() == 0 and np.abs(made.delta).max() > 0   # on the other side
    assert "the mirror image of browInnerUp_L+browOuterUp_L" in w.statusBar().currentMessage()
    # posing the right-side drivers fires it; the left one stays off
    weights = np.zeros(rig.n_shapes)
    weights[[rig.shape_index(d) for d in made.drivers]] = 1.0
    w.set_pose(weights, "right brows")
    assert ctrl.panel.activation_texts()[ctrl.panel.names().index(made.name)] == "1.000"
    assert ctrl.panel.activation_texts()[ctrl.panel.names().index(src.name)] == "0.000"
    np.testing.assert_allclose(doc.surface(), PoseEvaluator(rig, dtype=np.float64).evaluate(weights), atol=1e-5)
    # mirroring again replaces the right-side corrective instead of adding a second one
    assert ctrl.mirror(src.name)
    assert len(rig.correctives) == 2
    doc.undo_stack.undo()
    doc.undo_stack.undo()
    doc.undo_stack.undo()
    assert [c.name for c in rig.correctives] == [src.name]
    doc.undo_stack.redo()
    assert sorted(c.name for c in rig.correctives) == sorted([src.name, made.name])
    # a corrective whose drivers mirror onto themselves cannot be mirrored
    assert ctrl.start_authoring(PAIR)
    doc.set_edit_offset(np.full((rig.n_vertices, 3), 0.01))
    assert ctrl.save()
    count = doc.undo_stack.count()
    assert not ctrl.mirror("browInnerUp_L+browInnerUp_R")
    assert w.last_error == "browInnerUp_L+browInnerUp_R is its own mirror image: its drivers mirror onto themselves."
    assert doc.undo_stack.count() == count


def test_finder_lists_a_pair_and_its_mirror_as_one_row(qtbot, win):
    from model.sides import mirror_name
    w, ctrl = win
    names = w.document.rig.shape_names
    ctrl.panel.tabs.setCurrentIndex(1)
    assert ctrl.panel.merge_mirrored.isChecked()
    rows = ctrl.finder.find_pairs()
    listed = {frozenset((names[i], names[j])) for i, j, _ in rows}
    mirrored = [m for m in ctrl.finder.pair_mirrors if m is not None]
    assert mirrored, "the sample rig has left/right shapes: some rows stand for both sides"
    for (i, j, _), m in zip(rows, ctrl.finder.pair_mirrors):
        twin = frozenset((mirror_name(names[i]), mirror_name(names[j])))
        assert twin == frozenset((names[i], names[j])) or twin not in listed    # never both sides as rows
        if m is not None:
            assert frozenset((names[m[0]], names[m[1]])) == twin
    row = next(r for r, m in enumerate(ctrl.finder.pair_mirrors) if m is not None)
    item = ctrl.panel.pairs.topLevelItem(row)
    assert item.text(4) == "both"
    assert item.toolTip(2).endswith(f"its mirror image {names[ctrl.finder.pair_mirrors[row][0]]} × "
                                    f"{names[ctrl.finder.pair_mirrors[row][1]]}")
    ctrl.panel.select_pair(row)          # the heat map shows both sides
    heat = w.viewport.colormap.scalars
    x = w.document.rig.neutral
    assert heat[x[:, 0] > 0.5].max() > 0 and heat[x[:, 0] < -0.5].max() > 0
    ctrl.panel.merge_mirrored.setChecked(False)   # re-ranks: both sides as rows again
    flat = ctrl.finder.pairs
    assert not any(ctrl.finder.pair_mirrors) and len(flat) == len(rows)
    assert any(frozenset((mirror_name(names[i]), mirror_name(names[j]))) in
               {frozenset((names[a], names[b])) for a, b, _ in flat} - {frozenset((names[i], names[j]))}
               for i, j, _ in flat)


def test_mirror_refuses_an_asymmetric_rig(qtbot, win):
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    assert ctrl.start_authoring(["browInnerUp_L", "browOuterUp_L"])
    doc.set_edit_offset(np.full((rig.n_vertices, 3), 0.01))
    assert ctrl.save()
    rig.neutral[rig.neutral[:, 0] > 0, 0] *= 1.2            # the left half widened: no mirror image there
    count = doc.undo_stack.count()
    assert not ctrl.mirror("browInnerUp_L+browOuterUp_L")
    assert w.last_error.startswith("Cannot mirror browInnerUp_L+browOuterUp_L: the rig is not symmetric across "
                                   "x = 0 where it acts (")
    assert doc.undo_stack.count() == count and len(rig.correctives) == 1


def test_mirror_all_adds_each_missing_side_once(qtbot, win):
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    for drivers in (["browInnerUp_L", "browOuterUp_L"], ["cheekPuff_R", "mouthSmile_R"], PAIR):
        assert ctrl.start_authoring(drivers)
        doc.set_edit_offset(np.full((rig.n_vertices, 3), 0.01))
        assert ctrl.save()
    assert ctrl.mirror("browInnerUp_L+browOuterUp_L")           # this one already has its other side
    n = doc.undo_stack.count()
    assert ctrl.mirror_all() == 1
    assert doc.undo_stack.count() == n + 1
    assert sorted(c.name for c in rig.correctives) == sorted([
        "browInnerUp_L+browOuterUp_L", "browInnerUp_R+browOuterUp_R", "cheekPuff_R+mouthSmile_R",
        "cheekPuff_L+mouthSmile_L", "browInnerUp_L+browInnerUp_R"])
    assert ctrl.mirror_all() == 0 and doc.undo_stack.count() == n + 1
    assert w.statusBar().currentMessage() == "Every corrective already has its other side."
    doc.undo_stack.undo()
    assert "cheekPuff_L+mouthSmile_L" not in [c.name for c in rig.correctives] and len(rig.correctives) == 4


def test_unticking_a_corrective_mutes_it_and_undo_brings_it_back(qtbot, win, tmp_path):
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    assert ctrl.start_authoring(PAIR)
    fix = np.where((np.abs(rig.neutral[:, 0]) < 2.0)[:, None], np.array([0.0, 0.0, 0.05]), 0.0)
    doc.set_edit_offset(fix)
    assert ctrl.save()
    _settle(qtbot, w)
    with_fix = doc.surface().copy()
    item = ctrl.panel.table.topLevelItem(0)
    assert item.checkState(0) == QtCore.Qt.Checked
    n = doc.undo_stack.count()
    item.setCheckState(0, QtCore.Qt.Unchecked)               # the user unticks it
    qtbot.waitUntil(lambda: rig.correctives[0].muted)         # (the edit runs once the tick's signal returns)
    _settle(qtbot, w)
    assert rig.correctives[0].muted and doc.undo_stack.count() == n + 1
    assert w.undo_action.text().endswith("Mute corrective browInnerUp_L+browInnerUp_R")
    np.testing.assert_allclose(doc.surface(), with_fix - fix, atol=1e-5)     # the face without it
    np.testing.assert_allclose(w.viewport.points(), with_fix - fix, atol=1e-5)
    assert ctrl.panel.muted_names() == ["browInnerUp_L+browInnerUp_R"]
    assert ctrl.panel.activation_texts() == ["1.000"]         # its activation is still shown
    assert w.save_to(tmp_path / "muted.bsproj")
    from model.project import load_project
    assert load_project(tmp_path / "muted.bsproj").rig.correctives[0].muted
    doc.undo_stack.undo()
    _settle(qtbot, w)
    assert not rig.correctives[0].muted and ctrl.panel.muted_names() == []
    np.testing.assert_allclose(doc.surface(), with_fix, atol=1e-5)


def test_symmetrize_a_two_sided_corrective(qtbot, win):
    from solvers.symmetry import mirror_delta, mirror_map
    w, ctrl = win
    doc, rig = w.document, w.document.rig
    assert ctrl.start_authoring(PAIR)
    lopsided = np.where((rig.neutral[:, 0] > 0.5)[:, None], np.array([0.0, 0.04, 0.02]), 0.0)
    doc.set_edit_offset(lopsided)
    assert ctrl.save()
    before = rig.correctives[0].delta.copy()
    n = doc.undo_stack.count()
    assert ctrl.symmetrize(PAIR[0] + "+" + PAIR[1])
    made = rig.correctives[0]
    m = mirror_map(rig.neutral)
    np.testing.assert_allclose(made.delta, 0.5 * (before + mirror_delta(before, m)))
    np.testing.assert_allclose(mirror_delta(made.delta, m), made.delta, atol=1e-12)   # now its own mirror image
    assert doc.undo_stack.count() == n + 1
    doc.undo_stack.undo()
    np.testing.assert_array_equal(rig.correctives[0].delta, before)
    # a one-sided corrective is mirrored, not symmetrized
    assert ctrl.start_authoring(["browInnerUp_L", "browOuterUp_L"])
    doc.set_edit_offset(lopsided)
    assert ctrl.save()
    assert not ctrl.symmetrize("browInnerUp_L+browOuterUp_L")
    assert w.last_error.startswith("browInnerUp_L+browOuterUp_L acts on one side: Mirror makes its other side")


def test_finder_marks_the_pairs_that_have_a_corrective(qtbot, win):
    """A rigger works down the list: the Corrective column says which rows are done, one side or both."""
    w, ctrl = win
    doc, names = w.document, w.document.rig.shape_names
    ctrl.panel.tabs.setCurrentIndex(1)
    ctrl.panel.top.setValue(200)
    rows = ctrl.finder.find_pairs()
    column = lambda r: ctrl.panel.pairs.topLevelItem(r).text(5)   # noqa: E731
    assert ctrl.panel.pairs.headerItem().text(5) == "Fixed"
    assert all(column(r) == "" for r in range(len(rows)))
    row = next(r for r, m in enumerate(ctrl.finder.pair_mirrors) if m is not None)
    i, j, _ = rows[row]
    drivers = [names[i], names[j]]
    assert ctrl.start_authoring(drivers)
    doc.set_edit_offset(np.full((doc.rig.n_vertices, 3), 0.01))
    rows = list(w.shapes_panel.rows)
    assert ctrl.save()
    assert w.shapes_panel.rows == rows                   # a corrective edit does not rebuild the sliders
    assert column(row) == "1/2"                       # one side of a mirrored row
    assert ctrl.mirror("+".join(drivers))
    assert column(row) == "✓"
    doc.undo_stack.undo()
    assert column(row) == "1/2"
    ctrl.panel.select_pair(row)                          # the column does not disturb the selection
    assert ctrl.panel.selected_pair_row() == row and w.viewport.colormap is not None
    assert ctrl.panel.create_pair_button.text() == "Edit the corrective of this pair"
    doc.undo_stack.undo()
    assert column(row) == "" and ctrl.panel.create_pair_button.text() == "Create corrective for this pair"


def test_sculpt_symmetry_follows_the_drivers_sides(qtbot, win):
    """A two-sided (or midline) corrective is sculpted symmetrically, a one-sided one is not: a symmetric
    stroke would also change the other side, where a one-sided corrective must add nothing of its own."""
    w, ctrl = win
    for drivers, symmetric in ((PAIR, True), (["browInnerUp_L", "browOuterUp_L"], False),
                               (["jawOpen", "mouthClose"], True)):
        assert ctrl.start_authoring(drivers)
        assert ctrl.panel.symmetric.isChecked() is symmetric, drivers
        assert ("symmetric strokes on" in w.statusBar().currentMessage()) is symmetric
        ctrl.stop_sculpting()


def test_find_pairs_ranks_the_shapes_off_the_gui_thread(qtbot, win, monkeypatch):
    """The Find pairs button ranks every pair of shapes (``pair_scores``: 0.3-0.5 s on ICT, the window frozen
    under a wait cursor before) on a worker, the button off and the panel saying so meanwhile; the list then
    fills as ``find_pairs`` lists it, and a second click lists the kept scores at once."""
    import app.interference_finder as finder_module
    from tests.gui_helpers import calls_on_gui_thread
    threads = calls_on_gui_thread(monkeypatch, finder_module, "pair_scores")
    w, ctrl = win
    panel = ctrl.panel
    panel.tabs.setCurrentIndex(1)
    qtbot.mouseClick(panel.find_button, QtCore.Qt.LeftButton)
    assert not panel.find_button.isEnabled() and panel.pair_info.text().startswith("Ranking")
    qtbot.waitUntil(lambda: panel.pairs.topLevelItemCount() > 0, timeout=30000)
    assert threads == [False] and panel.find_button.isEnabled()
    listed = [panel.pairs.topLevelItem(i).text(2) for i in range(panel.pairs.topLevelItemCount())]
    assert listed == [w.document.rig.shape_names[i] for i, _, _ in ctrl.finder.pairs]
    qtbot.mouseClick(panel.find_button, QtCore.Qt.LeftButton)
    assert threads == [False] and panel.pairs.topLevelItemCount() == len(listed)


def test_the_pairs_listed_stay_the_shapes_they_name_after_shape_list_edits(qtbot, win):
    """The Interference list names pairs by their shapes' places in the list. After a shape was deleted (Delete on
    its name) the rows stayed, naming the old shapes: selecting one showed another pair's heat map, or failed
    (KeyError) for a row standing for both sides, and Create corrective took the wrong drivers. The list is now
    emptied with a sentence to find the pairs again; a rename relabels the rows in place."""
    w, ctrl = win
    panel = ctrl.panel
    w.activateWindow()
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is w, timeout=5000)
    panel.tabs.setCurrentIndex(1)

    def find():
        qtbot.mouseClick(panel.find_button, QtCore.Qt.LeftButton)
        qtbot.waitUntil(lambda: panel.pairs.topLevelItemCount() > 0, timeout=30000)

    def listed():
        return [(panel.pairs.topLevelItem(i).text(2), panel.pairs.topLevelItem(i).text(3))
                for i in range(panel.pairs.topLevelItemCount())]

    def rows_named():
        names = w.document.rig.shape_names
        return [(names[i], names[j]) for i, j, _ in ctrl.finder.pairs]

    find()
    assert listed() == rows_named()
    a, b = listed()[0]
    key_on_shape_name(qtbot, w, a, QtCore.Qt.Key_F2, "renamedShape")
    assert listed()[0] == ("renamedShape", b) and listed() == rows_named()
    first = w.document.rig.shape_names[0]
    key_on_shape_name(qtbot, w, first, QtCore.Qt.Key_Delete)
    assert first not in w.document.rig.shape_names
    assert listed() == rows_named()
    assert panel.pairs.topLevelItemCount() == 0 and "Find Pairs" in panel.pair_info.text()
    find()
    assert listed() == rows_named()
    item = panel.pairs.topLevelItem(0)
    qtbot.mouseClick(panel.pairs.viewport(), QtCore.Qt.LeftButton, pos=panel.pairs.visualItemRect(item).center())
    assert panel.selected_pair_row() == 0 and "×" in panel.pair_info.text()
    a, b = listed()[0]
    assert panel.pair_info.text().startswith(f"{a} × {b}")


def test_the_sculpt_menu_actions_are_enabled_only_when_they_can_act(qtbot, win):
    """Correctives ▸ Save Corrective, Discard Sculpt and Stop Sculpting are enabled as the panel's Save corrective,
    Discard sculpt and Stop buttons are: they were enabled with nothing to save, discard or stop, and then did
    nothing and said nothing (Save, an error box)."""
    w, ctrl = win
    doc = w.document
    actions = {a.text().replace("&", ""): a for a in w.actions()}
    discard, stop, save = actions["Discard Sculpt"], actions["Stop Sculpting"], actions["Save Corrective"]
    assert not discard.isEnabled() and not stop.isEnabled()
    assert not save.isEnabled() and not ctrl.panel.save_button.isEnabled()   # it was, and said "Start a corrective"
    ctrl.panel.set_ticked(PAIR)
    qtbot.mouseClick(ctrl.panel.new_button, QtCore.Qt.LeftButton)
    _settle(qtbot, w)
    assert stop.isEnabled() and not discard.isEnabled() and ctrl.panel.cancel_button.isEnabled()
    assert save.isEnabled() == ctrl.panel.save_button.isEnabled() is True
    from app.commands import SetEditOffsetCommand      # what a brush stroke pushes
    doc.undo_stack.push(SetEditOffsetCommand(doc, None, np.full((doc.rig.n_vertices, 3), 0.01), "stroke"))
    assert discard.isEnabled() == ctrl.panel.discard_button.isEnabled() is True
    discard.trigger()
    assert doc.edit_offset is None and not discard.isEnabled() and stop.isEnabled()
    stop.trigger()
    assert not ctrl.sculpting and not stop.isEnabled() and not discard.isEnabled() and not save.isEnabled()


def test_the_interference_measure_is_shown_whole_at_the_default_window_size(qtbot, tmp_path):
    """In the Interference tab at 1400x900 the measure's name beside Top and Find pairs read "Overshoot where
    both a"; every measure's name is shown whole, and Top and Find pairs stay in view."""
    w = make_window(qtbot, tmp_path, (1400, 900))
    panel = w.correctives.panel
    w.correctives.dock.show()
    w.correctives.dock.raise_()
    panel.tabs.setCurrentIndex(1)
    qtbot.waitUntil(lambda: panel.measure.isVisible())
    for i in range(panel.measure.count()):
        panel.measure.setCurrentIndex(i)
        assert combo_text_shown_whole(panel.measure), panel.measure.currentText()
    page = panel.tabs.currentWidget()
    for widget in (panel.top, panel.find_button, panel.partner_of):
        corner = widget.mapTo(page, QtCore.QPoint(widget.width(), 0))
        assert widget.isVisible() and corner.x() <= page.width()


def test_the_interference_heat_map_is_framed_whole(qtbot, tmp_path, ict_dir):
    """On ICT FaceKit the window frames where the shapes act most; Smith's inner-brow pair overshoots up the
    forehead's midline, above that, and its heat map was cut by the view's top edge. Every vertex it paints (above
    10% of its peak: the area the summary counts) is in view, and so after the front camera (1)."""
    from model.interference import hot_vertices
    from tests.gui_helpers import open_and_wait
    w = make_window(qtbot, tmp_path, (1400, 900))
    open_and_wait(qtbot, w, ict_dir)
    panel = w.correctives.panel
    w.correctives.dock.show()
    w.correctives.dock.raise_()
    panel.tabs.setCurrentIndex(1)
    qtbot.mouseClick(panel.find_button, QtCore.Qt.LeftButton)
    qtbot.waitUntil(lambda: panel.pairs.topLevelItemCount() > 0, timeout=60000)
    row = next(i for i in range(panel.pairs.topLevelItemCount())
               if {panel.pairs.topLevelItem(i).text(2), panel.pairs.topLevelItem(i).text(3)} == set(PAIR))
    panel.pairs.setCurrentItem(panel.pairs.topLevelItem(row))
    _settle(qtbot, w)
    heat = w.viewport.colormap.scalars
    hot = hot_vertices(np.asarray(heat))
    assert hot.size > 100

    def in_view() -> bool:
        xy = w.viewport.world_to_display(w.viewport.points()[hot])[:, :2]
        width, height = w.viewport.plotter.window_size
        return bool(np.all((xy >= 0) & (xy <= [width, height])))
    assert in_view()
    qtbot.keyClick(w.viewport.canvas, QtCore.Qt.Key_1)                # the front camera
    _settle(qtbot, w)
    assert in_view()


def test_use_posed_shapes_shows_the_drivers_it_ticked(qtbot, win):
    """"Use posed shapes" ticked shapes far down the drivers list and left it scrolled at its top: none of the
    ticked drivers was in view, and the user could not see what the new corrective would be of."""
    w, ctrl = win
    rig = w.document.rig
    weights = np.zeros(rig.n_shapes)
    late = sorted(rig.shape_names[rig.n_shapes // 2:])[:2]                 # two shapes past the list's first rows
    weights[[rig.shape_index(n) for n in late]] = 0.6
    w.set_pose(weights, "pose")
    drivers = ctrl.panel.drivers
    drivers.scrollToTop()
    qtbot.mouseClick(ctrl.panel.use_pose_button, QtCore.Qt.LeftButton)
    assert sorted(ctrl.panel.ticked_drivers()) == late
    first = next(drivers.item(i) for i in range(drivers.count()) if drivers.item(i).text() in late)
    assert drivers.viewport().rect().contains(drivers.visualItemRect(first))


def test_mirror_and_symmetrize_are_enabled_only_for_a_corrective_they_can_act_on(qtbot, win):
    """Correctives ▸ Mirror Corrective, Symmetrize Corrective and the panel's Mirror were enabled with no corrective
    selected, or one they cannot act on, and answered with an error box: they are enabled only when they can act,
    and their tooltips say why not. Selected by clicks in the list; Ctrl+Shift+M on a two-sided corrective does
    nothing (no box)."""
    w, ctrl = win
    doc, panel = w.document, ctrl.panel
    mirror, symmetrize = (next(a for a in w.actions() if a.text() == t)       # the Correctives menu's
                          for t in ("&Mirror Corrective", "Symmetri&ze Corrective"))
    button = panel.mirror_button

    def state():
        return mirror.isEnabled(), symmetrize.isEnabled(), button.isEnabled()
    assert state() == (False, False, False)                 # no corrective yet
    assert mirror.toolTip() == symmetrize.toolTip() == "Select a corrective in the list first."
    two_sided, one_sided = "+".join(PAIR), "browInnerUp_L+browOuterUp_L"
    for drivers in (PAIR, one_sided.split("+")):
        assert ctrl.start_authoring(drivers)
        doc.set_edit_offset(np.full((doc.rig.n_vertices, 3), 0.01))
        assert ctrl.save()
    table = panel.table

    def click_row(name):
        item = next(table.topLevelItem(i) for i in range(table.topLevelItemCount())
                    if table.topLevelItem(i).data(0, QtCore.Qt.UserRole) == name)
        rect = table.visualItemRect(item)
        qtbot.mouseClick(table.viewport(), QtCore.Qt.LeftButton, pos=rect.center())
        QtWidgets.QApplication.processEvents()
        assert panel.selected_name() == name
    click_row(two_sided)
    assert state() == (False, True, False)
    assert mirror.toolTip() == button.toolTip() == (f"{two_sided} is its own mirror image (its drivers mirror onto "
                                                    "themselves): Symmetrize makes it symmetric.")
    assert symmetrize.toolTip() == ("Make the selected two-sided corrective (drivers that mirror onto themselves) "
                                    "exactly symmetric")
    w.activateWindow()
    qtbot.waitUntil(lambda: QtWidgets.QApplication.activeWindow() is w, timeout=5000)
    steps, w.last_error = doc.undo_stack.count(), None
    qtbot.keyClick(table, QtCore.Qt.Key_M, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)
    QtWidgets.QApplication.processEvents()
    assert doc.undo_stack.count() == steps and w.last_error is None
    click_row(one_sided)
    assert state() == (True, False, True)
    assert mirror.toolTip().startswith("Add the other side's version of the selected corrective")
    assert symmetrize.toolTip().startswith(f"{one_sided} acts on one side: Mirror makes its other side")
    qtbot.keyClick(table, QtCore.Qt.Key_M, QtCore.Qt.ControlModifier | QtCore.Qt.ShiftModifier)   # Mirror: acts
    assert doc.undo_stack.count() == steps + 1 and doc.undo_stack.undoText().startswith("Mirror corrective")
    # the other side exists now; undone, the corrective is mirrorable again
    doc.undo_stack.undo()
    click_row(one_sided)
    assert state() == (True, False, True)


def test_every_interference_column_fits_the_list_at_the_default_window_size(qtbot, tmp_path, ict_dir):
    """At the default window size (1400x900) on ICT FaceKit, the Interference list's Sides and Fixed columns sat past
    its right edge (sized to their contents: 409 px of columns in a 338 px list), behind a horizontal scroll bar:
    every column now ends within the list, the shape names elided in the middle with the pair whole in the tooltip."""
    from tests.gui_helpers import open_and_wait
    w = make_window(qtbot, tmp_path, size=(1400, 900), sample=False)
    open_and_wait(qtbot, w, ict_dir)
    ctrl = w.correctives
    ctrl.dock.show()
    ctrl.dock.raise_()
    tabs = ctrl.panel.tabs
    qtbot.mouseClick(tabs.tabBar(), QtCore.Qt.LeftButton, pos=tabs.tabBar().tabRect(1).center())   # Interference
    assert tabs.currentIndex() == 1
    qtbot.mouseClick(ctrl.panel.find_button, QtCore.Qt.LeftButton)
    table = ctrl.panel.pairs
    qtbot.waitUntil(lambda: table.topLevelItemCount() > 0, timeout=60000)
    qtbot.wait(50)
    header, width = table.header(), table.viewport().width()
    edges = [header.sectionViewportPosition(c) + header.sectionSize(c) for c in range(table.columnCount())]
    assert all(e <= width for e in edges), (edges, width)
    assert not table.horizontalScrollBar().isVisible()
    for c in (0, 1, 4, 5):      # the numbers and marks are shown whole
        assert header.sectionSize(c) >= table.sizeHintForColumn(c), c
    item = table.topLevelItem(0)
    assert item.toolTip(2).startswith(f"{item.text(2)} × {item.text(3)}")


def test_each_stroke_move_draws_one_frame_and_a_hover_one(qtbot, win):
    """A dab or a grab move changes the surface and moves the brush cursor: one frame shows both (the window's
    redraw). The cursor drew its own frame first, of the surface before the move: two renders a move (0.1-0.16 s
    more at 422k vertices, and a full and a proxy frame in turn with the level of detail)."""
    import vtk
    w, ctrl = win
    doc = w.document
    start, widget = _sculpting_the_pair(qtbot, w, ctrl)
    frames = []
    w.viewport.plotter.ren_win.AddObserver(vtk.vtkCommand.EndEvent, lambda *_: frames.append(1))
    for brush in ("inflate", "grab"):
        ctrl.set_brush(brush)
        mouse(widget, "press", start)
        _settle(qtbot, w)
        per_move = []
        for dx in (2, 4, 6, 8):
            n = len(frames)
            mouse(widget, "move", start + QtCore.QPointF(dx, -dx), buttons=QtCore.Qt.LeftButton)
            _settle(qtbot, w)
            per_move.append(len(frames) - n)
        mouse(widget, "release", start + QtCore.QPointF(8, -8))
        _settle(qtbot, w)
        assert per_move == [1, 1, 1, 1], (brush, per_move)
    np.testing.assert_allclose(w.viewport.points(), doc.surface())     # the last frame drew the last move
    # a hover moves the cursor alone: drawn at once, one frame
    n = len(frames)
    mouse(widget, "move", start + QtCore.QPointF(-6, 3), buttons=QtCore.Qt.NoButton)
    assert len(frames) == n + 1
    cursor = w.viewport.plotter.actors["brush_cursor"]
    assert cursor.GetVisibility()
