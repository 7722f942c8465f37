"""Units that do not change results (issue 16, item 5): the rig's units only say how its numbers are written. The
same face written in metres, centimetres and millimetres solves the shared marker take to the same weights (global
and per region), with the dense result and the marker errors scaled by the unit, and a marker drag poses it alike;
every length the application chooses is physical and converted in one place (``model.units``)."""
from __future__ import annotations

import numpy as np
import pytest

from model.marker_map import load_marker_map
from model.markers import Marker, MarkerSet
from model.rig import Rig
from model.segmentation import SegmentationSettings, segment_rig
from model.take_c3d import read_c3d
from model.take_workspace import regional_solve_options, solve_take
from model.units import area, length, take_solver_options, unit_scale
from solvers.regional_solve import shape_region_max
from solvers.take_solve import DEFAULTS

UNITS = ("m", "cm", "mm")


def written_in(rig: Rig, units: str) -> Rig:
    """The same face with its numbers written in ``units``: neutral and shapes scaled, nothing else."""
    f = unit_scale(rig.units, units)
    return Rig(rig.neutral * f, rig.face_counts, rig.face_indices, rig.shape_names, rig.deltas * f, units=units,
               name=f"{rig.name} in {units}")


@pytest.fixture(scope="module")
def rigs(ict_rig):
    return {u: ict_rig if u == ict_rig.units else written_in(ict_rig, u) for u in UNITS}


@pytest.fixture(scope="module")
def take(take_dir):
    return read_c3d(take_dir / "take.c3d"), load_marker_map(take_dir / "marker_map.json")


@pytest.fixture(scope="module")
def segmentations(rigs):
    return {u: segment_rig(r.neutral, r.face_counts, r.face_indices, r.deltas, SegmentationSettings())
            for u, r in rigs.items()}


def test_the_segmentation_is_the_same_in_m_cm_mm(segmentations):
    """A per-region solve segments the rig it is given: the face's regions do not depend on its units."""
    ref = segmentations["cm"]
    for u in ("m", "mm"):
        seg = segmentations[u]
        assert [lvl.n_regions for lvl in seg.levels] == [lvl.n_regions for lvl in ref.levels]
        for a, b in zip(seg.levels, ref.levels):
            assert all(np.array_equal(x.vertices, y.vertices) for x, y in zip(a.regions, b.regions))


def test_physical_defaults_convert_in_one_place():
    """A length default is in cm, a λ of squared lengths in cm², a frame count or a ratio is unchanged; the
    multiquadric kernel is a length, so its λ is one too."""
    assert length(2.0, "m") == pytest.approx(0.02) and length(2.0, "mm") == pytest.approx(20.0)
    assert area(1.0, "m") == pytest.approx(1e-4) and area(1.0, "mm") == pytest.approx(100.0)
    m = take_solver_options({"lam_temporal": 2.0}, "m")
    assert m["lam_temporal"] == pytest.approx(2e-4) and m["rbf_scale"] == pytest.approx(DEFAULTS["rbf_scale"] / 100)
    assert m["phantom_distance"] == pytest.approx(0.02) and m["rigid_noise"] == pytest.approx(5e-4)
    assert m["lam_antagonist"] == pytest.approx(0.15e-4) and m["rbf_lambda"] == DEFAULTS["rbf_lambda"]
    assert "marker_smoothing" not in m and "rigid_weighting" not in m
    assert take_solver_options({"residual": "multiquadric", "rbf_lambda": 0.5}, "mm")["rbf_lambda"] == 5.0
    assert take_solver_options({}, "cm") == {k: DEFAULTS[k] for k in m}


@pytest.mark.parametrize("mode", ["global", "regional"])
def test_the_same_take_on_a_rig_in_m_cm_mm_gives_the_same_weights(rigs, take, segmentations, mode):
    take_, mm = take
    options = {u: regional_solve_options(segmentations[u], 2) if mode == "regional" else {} for u in UNITS}
    sols = {u: solve_take(rigs[u], take_, mm, **options[u]) for u in UNITS}
    ref = sols["cm"]
    W = "region_weights" if mode == "regional" else "weights"
    for u in ("m", "mm"):
        sol, f = sols[u], unit_scale("cm", u)
        assert np.abs(getattr(sol, W) - getattr(ref, W)).max() < 1e-6, u
        np.testing.assert_allclose(sol.marker_rmse, ref.marker_rmse * f, rtol=1e-6)
        np.testing.assert_allclose(sol.marker_rmse_residual, ref.marker_rmse_residual * f, rtol=1e-5)
        assert sol.neutral_frames == ref.neutral_frames
        for frame in (0, 120, 300):
            # the dense result is the same surface, written in the rig's units (1e-5 cm = 0.1 µm)
            np.testing.assert_allclose(sol.dense(frame) / f, ref.dense(frame), atol=1e-5)


def test_a_drag_poses_the_face_alike_in_m_cm_mm(rigs, segmentations):
    """The mouth-corner drag of test_retarget at level 3 on the rig in each unit: the same regional weights."""
    regions = [r.vertices for r in segmentations["cm"].levels[3].regions]
    cm = rigs["cm"]
    corner = int(np.argmax(np.linalg.norm(cm.deltas[cm.shape_index("mouthSmile_L"), :9409], axis=1)))
    brow = int(np.argmax(np.linalg.norm(cm.deltas[cm.shape_index("browInnerUp_L"), :9409], axis=1)))
    found = {}
    for u in UNITS:
        rig = rigs[u]
        ms = MarkerSet([Marker("corner", corner), Marker("brow", brow)], rig.n_vertices)
        solver = ms.drag_solver(rig, regions, shape_region_max(rig.deltas, regions))
        rest = ms.positions(rig.neutral)
        W = np.zeros((len(regions) + 1, rig.n_shapes))
        for step in range(1, 7):
            targets = rest.copy()
            targets[0] += np.array([1.5, 1.0, 0.0]) * length(step / 6, u)    # 1.5 cm out, 1 cm up in six moves
            W = solver.solve((targets - rest).reshape(-1), W)
        found[u] = W
    assert found["cm"].max() > 0.2   # the drag does pose the face
    for u in ("m", "mm"):
        assert np.abs(found[u] - found["cm"]).max() < 1e-6, u


def test_the_multiquadric_residual_is_a_length_too(rigs, take):
    """The multiquadric kernel is a length, so its Tikhonov λ is one: the residual of a rig in metres is the one in
    centimetres, scaled (with a dimensionless λ it would be 100 times stiffer)."""
    take_, mm = take
    cm, m = (solve_take(rigs[u], take_, mm, residual="multiquadric") for u in ("cm", "m"))
    assert np.abs(m.weights - cm.weights).max() < 1e-6
    np.testing.assert_allclose(m.dense(200) * 100.0, cm.dense(200), atol=1e-5)


def test_length_boxes_keep_their_physical_size_across_units(qtbot):
    """The Mocap panel's RBF length and the nudge step show the rig's units: on a rig in metres they show the same
    2 cm and 1 mm in metres, the solve settings still get 2 cm, and going back to cm gives the defaults again."""
    from widgets.mocap_panel import MocapPanel
    from widgets.segmentation_panel import SegmentationPanel
    mocap, seg = MocapPanel(), SegmentationPanel()
    qtbot.addWidget(mocap)
    qtbot.addWidget(seg)
    assert mocap.rbf_scale.value() == DEFAULTS["rbf_scale"] and seg.nudge_amount.value() == pytest.approx(0.1)
    for units, rbf, nudge in (("m", 0.02, 0.001), ("mm", 20.0, 1.0), ("cm", 2.0, 0.1)):
        mocap.set_units(units)
        seg.set_units(units)
        assert mocap.rbf_scale.suffix() == f" {units}" and seg.nudge_amount.suffix() == f" {units}"
        assert mocap.rbf_scale.value() == pytest.approx(rbf) and seg.nudge_amount.value() == pytest.approx(nudge)
        assert mocap.settings()["rbf_scale"] == pytest.approx(DEFAULTS["rbf_scale"])
    seg.set_units("m")
    seg.nudge_amount.setValue(0.0005)          # half a millimetre can be set on a rig in metres
    assert seg.nudge_amount.value() == pytest.approx(0.0005)
