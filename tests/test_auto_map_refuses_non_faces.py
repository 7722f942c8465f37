"""Automatic marker mapping maps face takes and refuses, in one sentence naming the file, takes whose markers are
not on a face: every marker take other tools wrote (../shared/data/thirdparty: gait, sports and whole-body C3D
and TRC files) and a take whose points are all at one place. A similarity with a free scale fits any cloud onto
the face, so before this check these were mapped and "solved" (exit 0, a marker RMSE of 3-16 cm on the face).
The shared face takes (the rig's own face, and an actor who is not the rig) are still mapped."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from model.errors import RigInputError
from model.marker_map import FACE_SCALE_RANGE, MIN_AUTO_MARKERS, auto_marker_map
from model.take_workspace import read_take
from model.takes import MarkerTake
from tests.cli_runner import run_cli
from tests.conftest import DATA, require_data

THIRDPARTY = DATA / "thirdparty"
TAKES = sorted([*(THIRDPARTY / "c3d").glob("*"), *(THIRDPARTY / "trc").glob("*.trc")]) \
    if THIRDPARTY.is_dir() else []


def _one_sentence_naming(message: str, path) -> None:
    assert str(path) in message and "\n" not in message and message.endswith(".") and "Traceback" not in message


@pytest.mark.parametrize("path", TAKES, ids=[p.name for p in TAKES])
def test_a_third_party_body_take_is_not_mapped_onto_the_face(ict_rig, path):
    try:
        take = read_take(path, ict_rig)
    except RigInputError:
        return      # refused by its reader (tests/test_thirdparty_takes.py checks why)
    if not isinstance(take, MarkerTake):
        return
    with pytest.raises(RigInputError) as refused:
        auto_marker_map(ict_rig, take, calibration_frames=30, refine=0)
    _one_sentence_naming(str(refused.value), path)


def test_the_shared_face_takes_are_still_mapped(ict_rig):
    for name in ("ict_livelink_take", "actor_take"):
        take = read_take(require_data(DATA / "mocap" / name / "take.c3d"), ict_rig)
        mm, info = auto_marker_map(ict_rig, take, calibration_frames=30, refine=0)
        assert len(mm.markers) == 60, name
        assert FACE_SCALE_RANGE[0] < 0.9 < info["scale"] < 1.1 < FACE_SCALE_RANGE[1], (name, info["scale"])


def test_too_few_markers_to_tell_a_face_are_not_mapped(ict_rig, sample_rig, tmp_path):
    """A handful of markers lies on any surface: C3D.org's Sample17 (5 markers seen, a body 5 m across) was mapped
    onto the sample face and solved (exit 0, marker RMSE 15 cm, motion explained 0.000), and OpenSim's format
    example (3 markers) onto ICT. Fewer than MIN_AUTO_MARKERS are refused in one sentence; the actor's face take
    keeps being mapped from that many of its markers."""
    body = require_data(THIRDPARTY / "c3d" / "Sample17__128analogchannels.c3d")
    for rig, path, seen in ((sample_rig, body, 5), (ict_rig, THIRDPARTY / "trc" / "opensim_exampleFormat.trc", 3)):
        with pytest.raises(RigInputError) as refused:
            auto_marker_map(rig, read_take(path, rig), calibration_frames=30, refine=0)
        assert str(refused.value) == (f"{path}: only {seen} markers are seen in the calibration frames, too few to "
                                      f"tell whether they are on a face ({MIN_AUTO_MARKERS} or more are mapped "
                                      "automatically); give a marker map.")
    from resources.sample_rig import write_sample
    folder = write_sample(tmp_path / "sample")
    proc = run_cli("solve", folder, body, "-o", tmp_path / "w.csv", check=False)
    assert proc.returncode == 2 and proc.stderr == f"error: {body}: only 5 markers are seen in the calibration " \
        f"frames, too few to tell whether they are on a face ({MIN_AUTO_MARKERS} or more are mapped automatically); " \
        "give a marker map.\n" and not (tmp_path / "w.csv").exists()
    walk = require_data(THIRDPARTY / "c3d" / "Sample06__newwalk.c3d")     # every marker missing in its first 30 frames
    with pytest.raises(RigInputError, match=f"^{walk}: no marker is seen in the calibration frames, so none can be "
                                            "mapped automatically.$"):
        auto_marker_map(ict_rig, read_take(walk, ict_rig), calibration_frames=30, refine=0)
    face = read_take(require_data(DATA / "mocap" / "actor_take" / "take.c3d"), ict_rig)
    few = MarkerTake(positions=face.positions[:, :MIN_AUTO_MARKERS], labels=face.labels[:MIN_AUTO_MARKERS],
                     rate=face.rate, units=face.units, source=face.source)
    mm, info = auto_marker_map(ict_rig, few, calibration_frames=30, refine=0)
    assert len(mm.markers) == MIN_AUTO_MARKERS and 0.9 < info["scale"] < 1.1


def test_a_take_whose_points_all_coincide_is_refused(ict_rig):
    take = MarkerTake(positions=np.zeros((40, 12, 3)), labels=[f"M{i}" for i in range(12)], rate=60.0, units="mm",
                      source="zeros.c3d")
    with pytest.raises(RigInputError, match="zeros.c3d: its markers' positions .* lie within 1 mm of one point"):
        auto_marker_map(ict_rig, take)


def test_solve_and_batch_refuse_a_body_take_in_one_sentence(ict_dir, take_dir, tmp_path):
    body = require_data(THIRDPARTY / "c3d" / "Sample03__gait-raw.c3d")
    proc = run_cli("solve", ict_dir, body, "-o", tmp_path / "w.csv", check=False)
    assert proc.returncode == 2 and not (tmp_path / "w.csv").exists()
    _one_sentence_naming(proc.stderr.strip(), body)     # and nothing else: no numpy RuntimeWarning lines either
    assert "do not look like a face" in proc.stderr
    # a batch solves the face take and marks the body take failed, with the same sentence
    proc = run_cli("batch", ict_dir, take_dir / "take.c3d", body, "-o", tmp_path / "out", "--workers", "1",
                   check=False)
    takes = {t["take"]: t for t in json.loads((tmp_path / "out" / "batch.json").read_text())["takes"]}
    statuses = {name: t["status"] for name, t in takes.items()}
    assert sorted(statuses.values()) == ["failed", "solved"], statuses
    failed = next(t for t in takes.values() if t["status"] == "failed")
    assert "do not look like a face" in failed["error"] and proc.returncode == 2


def test_a_face_take_on_a_rig_that_is_no_face_is_refused_without_meaningless_numbers():
    """The actor's face take on the third-party glTF MorphStressTest (bars on a plinth): the registration shrinks
    the markers onto one point, and the sentence said so with a 'scale of 4.5e-30' and markers '1.5e+14 m' off."""
    from model.readers import load_rig
    rig = load_rig(require_data(THIRDPARTY / "gltf" / "MorphStressTest.gltf"))
    path = require_data(DATA / "mocap" / "actor_take" / "take.c3d")
    take = read_take(path, rig)
    with pytest.raises(RigInputError) as refused:
        auto_marker_map(rig, take, calibration_frames=30, refine=0)
    message = str(refused.value)
    _one_sentence_naming(message, path)
    assert "do not look like a face" in message and "shrinks them to one point" in message
    assert not re.search(r"\de[+-]\d", message), message      # no 4.5e-30, no 1.5e+14
