"""Model outputs in a C3D are not markers. Vicon Nexus / Plug-in Gait and pyCGM2 store computed joint angles, forces,
moments and powers as points beside the markers and list their labels in POINT:ANGLES, FORCES, MOMENTS, POWERS
(SCALARS, REACTIONS). The reader leaves them out, keeps the markers in file order and says how many it left out
(a warning, and ``model_outputs_left_out`` in ``take-info --json``); automatic mapping and the solve never see them.
The expected labels come from ezc3d's reading of the parameter section, not from ours."""
from __future__ import annotations

import json

import numpy as np
import pytest

from model.take_c3d import read_c3d
from model.takes import take_summary
from tests.cli_runner import run_cli
from tests.conftest import DATA, require_data

ezc3d = pytest.importorskip("ezc3d")

C3D = DATA / "thirdparty" / "c3d"
OUTPUT_LISTS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")

# file: (points in the file, model outputs among them, markers a user sees)
FILES = {
    "Sample00__Vicon_Motion_Systems__pyCGM2_lower_limb_CGM24_Walking01.c3d": (171, 63, 108),
    "Sample03__gait-pig-nz.c3d": (85, 34, 51),
    "Sample03__gait-pig.c3d": (77, 28, 49),
    "Sample04__sub_labels.c3d": (114, 28, 86),
    "Sample09__PlugInC3D.c3d": (86, 32, 54),
    "Sample09__PolygonC3D.c3d": (86, 32, 54),
    "Sample11__2198928.c3d": (94, 34, 60),
    "Sample23__Vicon_analysis.c3d": (89, 34, 55),
    "Sample33__bigparlove.c3d": (205, 64, 141),
}


def _ezc3d_points(path) -> tuple[list[str], set[str], np.ndarray]:
    """POINT:LABELS, the labels the model-output lists name, and the points (frames, points, 3), as ezc3d reads them."""
    c = ezc3d.c3d(str(path))
    point = c["parameters"]["POINT"]
    outputs = {s for name in OUTPUT_LISTS for s in point.get(name, {}).get("value", [])}
    return list(point["LABELS"]["value"]), outputs, c["data"]["points"][:3].transpose(2, 1, 0)


@pytest.mark.parametrize("name", sorted(FILES))
def test_model_outputs_in_real_files_are_left_out(name):
    path = require_data(C3D / name)
    points, n_outputs, n_markers = FILES[name]
    labels, outputs, xyz = _ezc3d_points(path)
    markers = [i for i, s in enumerate(labels) if s not in outputs]
    assert len(labels) == points and len(markers) == n_markers and points - n_markers == n_outputs
    take = read_c3d(path)
    info = take_summary(take)           # what take-info --json prints
    assert info["labels"] == [labels[i] for i in markers], name     # the markers, in the file's order
    assert info["model_outputs_left_out"] == n_outputs and len(info["missing"]) == n_markers
    assert sorted(take.model_outputs) == sorted(set(labels) - set(info["labels"]))
    assert not any(s.endswith(("Angles", "Force", "Moment", "Power")) for s in info["labels"]), name
    assert any(f"{n_outputs} of the {points} points are model outputs listed in POINT:ANGLES" in w
               for w in take.warnings), take.warnings
    ref = xyz[:, markers].astype(np.float64)
    ref[(ref == 0).all(axis=2)] = np.nan           # gaps, as the reader reads them
    np.testing.assert_allclose(take.positions, ref, rtol=0, atol=1e-6 * np.nanmax(np.abs(ref)), equal_nan=True)


def test_take_info_leaves_the_model_outputs_out():
    """The command a user runs first on a Plug-in Gait / pyCGM2 file counts its 108 markers, not 171 points."""
    path = require_data(C3D / "Sample00__Vicon_Motion_Systems__pyCGM2_lower_limb_CGM24_Walking01.c3d")
    proc = run_cli("take-info", path)
    assert "493 frames at 100 fps, 108 markers (mm)" in proc.stdout and "; 63 model outputs left out" in proc.stdout
    assert "LHipAngles" not in proc.stdout and "LHJC_CGM_2.4" in proc.stdout   # a modelled marker is a position
    assert ("63 of the 171 points are model outputs listed in POINT:ANGLES (24), POINT:FORCES (14), POINT:MOMENTS "
            "(13) and POINT:POWERS (12)") in proc.stderr
    info = json.loads(run_cli("take-info", path, "--json").stdout)
    assert len(info["labels"]) == 108 and info["model_outputs_left_out"] == 63
    assert {"frames", "rate", "units", "labels", "missing", "bounds"} <= set(info)    # DESIGN.md's contract


def _with_model_outputs(take, path) -> None:
    """``take`` written (by ezc3d) with four Plug-in Gait outputs among its markers: angles in degrees, a force in
    newtons, a power in watts, all inside the face's volume if they were read as millimetres."""
    F = take.n_frames
    wave = np.stack([30 * np.sin(np.arange(F) / 20 + k) for k in range(3)], axis=-1)
    outputs = {"LHipAngles": wave, "LKneeAngles": 2 * wave, "LAnkleForce": 3 * wave, "LKneePower": 0.1 * wave}
    names = list(outputs)
    labels = take.labels[:10] + names[:2] + take.labels[10:] + names[2:]
    xyz = np.concatenate([take.positions[:, :10], np.stack([outputs[s] for s in names[:2]], axis=1),
                          take.positions[:, 10:], np.stack([outputs[s] for s in names[2:]], axis=1)], axis=1)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [take.rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    c["parameters"]["POINT"]["UNITS"]["value"] = [take.units]
    c.add_parameter("POINT", "ANGLES", names[:2])
    c.add_parameter("POINT", "FORCES", names[2:3])
    c.add_parameter("POINT", "POWERS", names[3:])
    c.add_parameter("POINT", "ANGLE_UNITS", ["deg"])
    points = np.ones((4, len(labels), F))
    points[:3] = xyz.transpose(2, 1, 0)
    c["data"]["points"] = points
    c.write(str(path))


def test_a_take_with_model_outputs_is_mapped_and_solved_on_its_markers_only(ict_dir, tmp_path):
    """Before, four model outputs among the actor take's 60 markers went into the automatic marker map: it left
    three real markers out and the solve explained 0.70 of the motion (0.996 without them)."""
    original = read_c3d(require_data(DATA / "mocap" / "actor_take" / "take.c3d"))
    path = tmp_path / "with_outputs.c3d"
    _with_model_outputs(original, path)
    take = read_c3d(path)
    assert take.labels == original.labels and take.model_outputs == ["LHipAngles", "LKneeAngles", "LAnkleForce",
                                                                      "LKneePower"]
    np.testing.assert_array_equal(take.positions, original.positions)
    run_cli("solve", ict_dir, path, "-o", tmp_path / "w.csv", "--report", tmp_path / "r.json")
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["marker_map"] == "automatic marker map" and report["markers"] == 60
    assert report["markers_left_out"] == [] and report["motion_explained"] > 0.99


def test_a_c3d_of_model_outputs_only_is_refused_in_one_sentence(tmp_path):
    """A C3D holding nothing but model outputs has no markers to solve: take-info says so and exits 2 (before, it
    listed the two joint angles as markers)."""
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ["LKneeAngles", "RKneeAngles"]
    c.add_parameter("POINT", "ANGLES", ["LKneeAngles", "RKneeAngles"])
    points = np.ones((4, 2, 50))
    points[:3] = 10.0
    c["data"]["points"] = points
    path = tmp_path / "angles.c3d"
    c.write(str(path))
    proc = run_cli("take-info", path, check=False)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == (f"error: {path}: holds no markers: all 2 points are model outputs (listed in "
                           "POINT:ANGLES (2)), not positions.\n")
