"""The Qt-free take workspace (model.take_workspace) on the sample rig: a map the take cannot use is refused and
the one loaded stays, a new rig drops what no longer fits, a one-frame take is solved with the head fixed and
its report says so, and the per-region options need a segmentation level that exists."""
from __future__ import annotations

import json

import numpy as np
import pytest

from model.errors import RigInputError
from model.marker_map import MarkerMap
from model.pose import PoseEvaluator
from model.take_exports import export_report, export_weights_csv
from model.take_workspace import TakeWorkspace, regional_solve_options
from model.takes import MarkerTake


def _keyframe(rig, weights):
    """A one-frame take (cm) of 40 markers on moving vertices at the rig's pose ``weights``, and its map."""
    moving = np.flatnonzero(np.abs(rig.deltas).max(axis=(0, 2)) > 0)
    vertices = moving[np.linspace(0, moving.size - 1, 40).astype(int)]
    labels = [f"K{i:02d}" for i in range(vertices.size)]
    x = PoseEvaluator(rig, dtype=np.float64).evaluate(weights)
    take = MarkerTake(positions=x[vertices][None], labels=labels, rate=24.0, units="cm", source="key.trc")
    return take, MarkerMap(markers=dict(zip(labels, vertices.tolist())), rig_units="cm", source="key.json")


def test_workspace_solves_a_keyframe_and_reports_it(sample_rig, tmp_path):
    rig = sample_rig
    truth = rig.weights_from_dict({"jawOpen": 0.6, "browInnerUp_L": 0.8})
    take, mm = _keyframe(rig, truth)
    ws = TakeWorkspace(rig)
    with pytest.raises(RigInputError, match="Load a marker take and a marker map"):
        ws.solve({"mode": "global"})
    ws.take = take
    ws.set_map(mm)
    # a map naming a marker the take lacks is refused (the GUI's check) and the loaded map stays
    extra = MarkerMap(markers={**mm.markers, "NOPE": 3}, rig_units="cm", source="extra.json")
    with pytest.raises(RigInputError, match="extra.json.*NOPE"):
        ws.set_map(extra)
    assert ws.marker_map is mm
    sol = ws.solve({"mode": "global", "residual": "none"})
    assert np.abs(sol.weights[0] - truth).max() < 1e-3
    export_weights_csv(ws, tmp_path / "w.csv")
    rep = export_report(ws, tmp_path / "r.json")
    assert json.loads((tmp_path / "r.json").read_text()) == json.loads(json.dumps(rep))
    assert rep["frames"] == 1 and rep["markers"] == 40 and rep["head"] == "fixed" and rep["neutral_frames"] is None
    assert rep["residual"] == "none" and rep["markers_left_out"] == [] and rep["marker_rmse"] < 1e-4
    # a per-region solve needs a segmentation level that exists
    with pytest.raises(RigInputError, match="needs a segmentation"):
        ws.solve({"mode": "region", "level": 0})
    from model.segmentation import SegmentationSettings, segment_rig
    seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, SegmentationSettings(t=0.9))
    with pytest.raises(RigInputError, match=f"levels 0 to {len(seg.levels) - 1}"):
        regional_solve_options(seg, len(seg.levels))
    regional = ws.solve({"mode": "region", "level": 0, "residual": "none"}, segmentation=seg)
    assert regional.region_weights.shape == (1, seg.levels[0].n_regions + 1, rig.n_shapes)
    assert ws.report()["mode"] == "regional" and ws.report()["level"] == 0
    # a rig the map does not fit (fewer vertices) drops the map and the solution, and says so
    small = rig.copy()
    small.neutral = small.neutral[:10]
    small.deltas = small.deltas[:, :10]
    dropped = ws.set_rig(small)
    assert ws.marker_map is None and ws.solution is None and "marker map" in dropped[0]


def test_a_neutral_range_outside_the_take_is_one_sentence_in_the_window_too(sample_rig):
    """The window's Solve (``TakeWorkspace.solve``, not the command's checks first): a neutral range outside the take
    is the solver's one sentence after the take's name, not "The take could not be solved: TAKE: The neutral ..."
    (two sentences run together); Auto Map with it names the take too (it said "--neutral-frames: ...")."""
    rig = sample_rig
    take, mm = _keyframe(rig, np.zeros(rig.n_shapes))
    take = MarkerTake(positions=np.repeat(take.positions, 10, axis=0), labels=take.labels, rate=24.0, units="cm",
                      source="ten.trc")
    ws = TakeWorkspace(rig)
    ws.take = take
    ws.set_map(mm)
    with pytest.raises(RigInputError) as err:
        ws.solve({"mode": "global", "neutral_frames": "20:30"})
    assert str(err.value) == "ten.trc: the neutral frames 20:30 are outside the take, which has frames 0 to 9."
    with pytest.raises(RigInputError) as err:
        ws.find_auto_map(neutral_frames="20:30")
    assert str(err.value) == ("ten.trc: the neutral frames 20:30 (--neutral-frames) are outside the take, which has "
                              "frames 0 to 9.")
