"""`solve` on the command line: the real marker take within 0.22 mm of the actor's true surface, and a
one-frame TRC keyframe (--global --residual none) recovering known weights."""
from __future__ import annotations

import json

import numpy as np
import pytest

from model.pc2 import read_pc2
from model.weights_csv import read_weights_csv
from tests.cli_runner import run_cli
from tests.conftest import DATA, require_data


def dense_rms_mm(frames: np.ndarray, truth) -> float:
    """The data README's measure: RMS over `moving` of the distance to `positions`, averaged over frames."""
    pos, moving = truth["positions"], truth["moving"]
    errs = [np.sqrt(np.mean(np.sum((frames[f, : pos.shape[1]][moving] - pos[i][moving]) ** 2, axis=1)))
            for i, f in enumerate(truth["frames"])]
    return float(np.mean(errs)) * 10.0  # cm -> mm


def test_solve_real_take_defaults(ict_dir, take_dir, tmp_path):
    out, cache, report = tmp_path / "w.csv", tmp_path / "dense.pc2", tmp_path / "report.json"
    run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json", "-o", out,
            "--cache", cache, "--report", report)
    rep = json.loads(report.read_text())
    assert rep["frames"] == 358 and rep["marker_rmse"] < 0.1 and rep["frames_per_second"] > 0
    frames, _, _ = read_pc2(cache)
    assert frames.shape == (358, 26719, 3)
    rms = dense_rms_mm(frames, np.load(take_dir / "truth_dense_face.npz"))
    assert rms < 0.22, f"dense RMS {rms:.4f} mm"
    _, _, names, W = read_weights_csv(out)
    assert W.shape == (358, 57) and W.min() >= 0 and W.max() <= 1
    truth = np.genfromtxt(take_dir / "truth_weights.csv", delimiter=",", names=True)
    jaw = names.index("jawOpen")
    assert np.corrcoef(W[:, jaw], truth["jawOpen"])[0, 1] > 0.9



def test_a_regional_solves_weights_csv_reproduces_its_surface(ict_rig, ict_dir, take_dir, tmp_path):
    """A per-region solve has one weight vector per region; its weights CSV (one column per shape, what a DCC
    plays) holds the global weights whose surface is closest to each frame's regional surface. Posed with them,
    the rig is ~0.02 mm RMS over its vertices from the solve's dense cache (no residual: the cache is the
    blendshape surface); the background row alone, the first global pass, which the CSV held before, ~0.07."""
    common = ["--map", take_dir / "marker_map.json", "--residual", "none"]
    run_cli("solve", ict_dir, take_dir / "take.c3d", *common, "--threshold", "0.5", "--level", "2",
            "-o", tmp_path / "region.csv", "--cache", tmp_path / "region.pc2", "--report", tmp_path / "r.json")
    run_cli("solve", ict_dir, take_dir / "take.c3d", *common, "--global", "-o", tmp_path / "global.csv")
    assert json.loads((tmp_path / "r.json").read_text())["mode"] == "regional"
    dense, _, _ = read_pc2(tmp_path / "region.pc2")
    _, _, names, W = read_weights_csv(tmp_path / "region.csv")
    _, _, _, W_global = read_weights_csv(tmp_path / "global.csv")
    assert names == list(ict_rig.shape_names) and W.min() >= 0 and W.max() <= 1
    D = ict_rig.deltas.reshape(ict_rig.n_shapes, -1).astype(np.float64)
    def rms_mm(weights) -> float:
        frames = range(0, 358, 7)
        posed = (weights[list(frames)] @ D).reshape(len(frames), -1, 3) + ict_rig.neutral
        return float(np.sqrt(np.mean(np.sum((posed - dense[list(frames)]) ** 2, axis=2)))) * 10
    assert rms_mm(W) < 0.04 < rms_mm(W_global), (rms_mm(W), rms_mm(W_global))


def _write_trc(path, labels, points_mm):
    n = len(labels)
    lines = ["PathFileType\t4\t(X/Y/Z)\tkey.trc",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"24\t24\t1\t{n}\tmm\t24\t1\t1",
             "Frame#\tTime\t" + "\t\t\t".join(labels),
             "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(n)),
             "",
             "1\t0.0\t" + "\t".join(f"{v:.6f}" for v in points_mm.ravel())]
    path.write_text("\n".join(lines) + "\n")


def _write_keyframe(tmp_path, rig, posed) -> np.ndarray:
    """A one-frame TRC (mm) of 50 markers spread over the face vertices the rig moves, at ``posed`` (cm), and
    its marker map: key.trc and map.json in ``tmp_path``. Returns the moving face vertices."""
    face = np.arange(9409)
    moving = face[np.linalg.norm(rig.deltas[:, face], axis=2).max(axis=0) > 1e-4]
    markers = moving[np.linspace(0, moving.size - 1, 50).astype(int)]
    labels = [f"K{i:02d}" for i in range(50)]
    _write_trc(tmp_path / "key.trc", labels, posed[markers] * 10.0)
    (tmp_path / "map.json").write_text(json.dumps({"rig_units": "cm", "take_units": "mm",
                                                   "markers": {l: int(v) for l, v in zip(labels, markers)}}))
    return moving


def test_one_frame_trc_global_recovers_weights(ict_rig, ict_dir, tmp_path):
    rig = ict_rig
    truth_w = rig.weights_from_dict({"jawOpen": 0.6, "mouthSmile_L": 0.8, "browInnerUp_R": 0.5,
                                     "eyeBlink_L": 0.9, "mouthPucker": 0.3, "cheekPuff_R": 0.4})
    posed = rig.neutral + np.einsum("k,kvc->vc", truth_w, rig.deltas)
    moving = _write_keyframe(tmp_path, rig, posed)
    run_cli("solve", ict_dir, tmp_path / "key.trc", "--map", tmp_path / "map.json", "--global", "--residual", "none",
            "-o", tmp_path / "w.csv", "--cache", tmp_path / "d.pc2", "--report", tmp_path / "r.json")
    assert json.loads((tmp_path / "r.json").read_text())["head"] == "fixed"
    frames, _, _ = read_pc2(tmp_path / "d.pc2")
    err = np.linalg.norm(frames[0][moving] - posed[moving], axis=1)
    assert np.sqrt(np.mean(err ** 2)) * 10 < 0.1, f"{np.sqrt(np.mean(err ** 2)) * 10:.4f} mm"


@pytest.mark.parametrize("case", ["absent", "beyond", "weights"])
def test_solve_bad_input(ict_dir, take_dir, llf_csv, tmp_path, case):
    if case == "weights":   # a weights CSV naming a shape the rig does not have
        (tmp_path / "weights.csv").write_text("frame,time,jawOpen,tail_L\n0,0.0,0.5,0.2\n1,0.04,0.6,0.1\n")
        proc = run_cli("solve", ict_dir, tmp_path / "weights.csv", "-o", tmp_path / "w.csv", check=False)
        words = "weights.csv: names shapes the rig does not have: tail_L."
    else:
        m = json.loads((take_dir / "marker_map.json").read_text())
        if case == "absent":
            m["markers"] = {f"X{i}": v for i, v in enumerate(m["markers"].values())}
            words = "map.json"
        else:
            m["markers"]["M00"] = 999999
            words = "999999"
        (tmp_path / "map.json").write_text(json.dumps(m))
        proc = run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", tmp_path / "map.json",
                       "-o", tmp_path / "w.csv", check=False)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("error: ") and words in proc.stderr, proc.stderr
    assert not (tmp_path / "w.csv").exists()


def test_solve_a_project_with_a_corrective(ict_dir, tmp_path):
    """`solve` on a project whose rig has Smith's inner-brow corrective (from a scan): the keyframe made by that
    rig comes back with the corrective in the dense result, and the report names it."""
    from model.obj_io import read_obj, write_obj
    from model.pose import PoseEvaluator
    from model.project import load_project
    run_cli("export", ict_dir, "--weights", "browInnerUp_L=1,browInnerUp_R=1", "-o", tmp_path / "both.obj")
    scan = read_obj(tmp_path / "both.obj")
    v = scan.vertices.copy()
    glabella = v[np.argmax(np.where(np.abs(v[:9409, 0]) < 1.0, v[:9409, 1] - 0.3 * np.abs(v[:9409, 2] - 10), -1e9))]
    v[:, 2] += 0.3 * np.exp(-np.sum((v - glabella) ** 2, axis=1) / 2.0)       # the sculpted fix: 3 mm forward
    write_obj(tmp_path / "scan.obj", v, scan.face_counts, scan.face_indices)
    run_cli("corrective", ict_dir, "--drivers", "browInnerUp_L,browInnerUp_R", "--target", tmp_path / "scan.obj",
            "-o", tmp_path / "fixed.bsproj")
    rig = load_project(tmp_path / "fixed.bsproj").rig
    truth_w = rig.weights_from_dict({"browInnerUp_L": 0.8, "browInnerUp_R": 0.7, "jawOpen": 0.3})
    posed = PoseEvaluator(rig, dtype=np.float64).evaluate(truth_w)
    moving = _write_keyframe(tmp_path, rig, posed)
    out = run_cli("solve", tmp_path / "fixed.bsproj", tmp_path / "key.trc", "--map", tmp_path / "map.json",
                  "--global", "--residual", "none", "-o", tmp_path / "w.csv", "--cache", tmp_path / "d.pc2",
                  "--report", tmp_path / "r.json").stdout
    assert json.loads((tmp_path / "r.json").read_text())["correctives"] == ["browInnerUp_L+browInnerUp_R"]
    assert "with 1 corrective(s)" in out
    frames, _, _ = read_pc2(tmp_path / "d.pc2")
    fixed = np.linalg.norm(rig.correctives[0].delta, axis=1) > 0.05   # where the fix moves the brows > 0.5 mm
    assert fixed.sum() >= 20
    err = np.linalg.norm(frames[0] - posed, axis=1)
    # mm; measured 5e-6 where the corrective acts (1.6 mm when the solve ignores it)
    assert err[fixed].max() * 10 < 0.05 and np.sqrt(np.mean(err[moving] ** 2)) * 10 < 0.05


@pytest.mark.parametrize("option, words", [
    (["--neutral-frames", "400:420"], "outside the take"),
    # the take named (before: "Stable markers root-* are not in the take", no file)
    (["--stable", "root-*"], "take.c3d: the stable markers root-* are not in the take"),
    (["--stable", "M00,M01"], "take.c3d: head motion needs at least 3 stable markers"),
    # a count the take cannot give (before: the whole take, expressions and all, silently taken as the neutral),
    # a negative count (before: no calibration, silently), and a neutral range for a solve that calibrates on none
    (["--calibration-frames", "100000"], "has 358 frames, fewer than the 100000 calibration frames"),
    (["--calibration-frames", "-1"], "--calibration-frames: -1 is not a count of frames"),
    (["--calibration-frames", "0", "--neutral-frames", "0:29"], "calibrates on no neutral"),
    # per-region options with --global (before: solved globally, the options silently unused)
    (["--threshold", "0.4", "--global"], "--global: solves one weight vector for the whole face, and --threshold "
                                         "chooses the regions of a per-region solve; give one or the other."),
    (["--global", "--threshold", "0.4", "--level", "1"], "and --threshold and --level choose the regions"),
])
def test_solve_bad_calibration_input(ict_dir, take_dir, tmp_path, option, words):
    proc = run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json", *option,
                   "-o", tmp_path / "w.csv", check=False)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("error: ") and words in proc.stderr and proc.stderr.count("\n") == 1, proc.stderr
    assert not (tmp_path / "w.csv").exists()


@pytest.mark.parametrize("mapped", [True, False])
def test_a_neutral_range_outside_the_take_is_one_sentence_naming_it(ict_dir, take_dir, tmp_path, mapped):
    """With a map or mapped automatically, the same sentence naming the take (before: "The take could not be
    solved: TAKE: The neutral frames ..." with a map, and "--neutral-frames: ...", not naming the take, without one)."""
    take = take_dir / "take.c3d"
    options = ["--map", take_dir / "marker_map.json"] if mapped else []
    proc = run_cli("solve", ict_dir, take, *options, "--neutral-frames", "500:600", "-o", tmp_path / "w.csv",
                   check=False)
    assert proc.returncode == 2 and proc.stderr == (f"error: {take}: the neutral frames 500:600 (--neutral-frames) are "
                                                    "outside the take, which has frames 0 to 357.\n"), proc.stderr


def test_no_calibration_takes_the_markers_as_the_rigs_own_face(ict_dir, take_dir, tmp_path):
    """--calibration-frames 0: no neutral, no similarity; the markers (in the take's units) are the rig's own face in
    rig space, and the head motion is still solved. The shared ICT take is that face: it solves as well as with its
    30 calibration frames (marker RMSE 0.0334 cm against 0.0335). The report says so, not "fixed head"."""
    proc = run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json", "--global",
                   "--calibration-frames", "0", "-o", tmp_path / "w.csv", "--report", tmp_path / "r.json")
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["neutral_frames"] is None and rep["head"] == "solved" and rep["marker_rmse"] < 0.04
    assert rep["neutral_frames_how"].startswith("no calibration")
    assert "neutral frames none (no calibration)" in proc.stdout


@pytest.mark.parametrize("cut", ["c3d", "trc"])
def test_solve_says_what_the_take_reader_decided(ict_dir, take_dir, tmp_path, cut):
    """A take cut short (a C3D at 90% of its bytes, a TRC with its first 300 of 358 frames) is read to its last whole
    frame with a warning: `solve` prints it (`warning: ...` on stderr, as `take-info` does) and the report lists it
    under `warnings` (before: exit 0, nothing said, nothing in the report)."""
    if cut == "c3d":
        raw = (take_dir / "take.c3d").read_bytes()
        take = tmp_path / "cut.c3d"
        take.write_bytes(raw[: int(len(raw) * 0.9)])
        words = "the file ends early"
    else:
        lines = (take_dir / "take.trc").read_text().splitlines(keepends=True)
        start = next(i for i, line in enumerate(lines) if line.split("\t", 1)[0] == "1")   # the first data row
        take = tmp_path / "cut.trc"
        take.write_text("".join(lines[: start + 300]))
        words = "declares 358 frames but the file holds 300"
    proc = run_cli("solve", ict_dir, take, "--map", take_dir / "marker_map.json", "--global", "--residual", "none",
                   "-o", tmp_path / "w.csv", "--report", tmp_path / "r.json")
    rep = json.loads((tmp_path / "r.json").read_text())
    assert len(rep["warnings"]) == 1, rep["warnings"]
    assert words in rep["warnings"][0] and str(take) in rep["warnings"][0], rep["warnings"]
    assert f"warning: {rep['warnings'][0]}\n" in proc.stderr


def test_solve_reports_the_neutral_it_found(ict_dir, take_dir, tmp_path):
    proc = run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json",
                   "--neutral-frames", "auto", "--global", "--residual", "none",
                   "-o", tmp_path / "w.csv", "--report", tmp_path / "r.json")
    rep = json.loads((tmp_path / "r.json").read_text())
    a, b = rep["neutral_frames"]
    assert b - a == 29 and b <= 31, rep["neutral_frames"]        # the take's neutral lead-in is frames 0–29
    assert "most neutral" in rep["neutral_frames_how"] and 0.9 < rep["motion_explained"] < 1.0
    assert "motion explained" in proc.stdout


def test_a_rig_in_metres_solves_as_well_as_in_centimetres(ict_rig, ict_dir, take_dir, tmp_path):
    """Issue 16: ICT exported as glTF (metres, float32) solves the shared take as the OBJ rig in cm does: the solver's
    lengths are physical, not rig units (before, the metres rig's dense result was 2.9 mm off instead of 0.20)."""
    from model.take_workspace import solve_take
    from model.marker_map import load_marker_map
    from model.take_c3d import read_c3d
    run_cli("export", ict_dir, "-o", tmp_path / "ict.glb")
    info = json.loads(run_cli("info", tmp_path / "ict.glb", "--json").stdout)
    assert info["units"] == "m"
    run_cli("solve", tmp_path / "ict.glb", take_dir / "take.c3d", "--map", take_dir / "marker_map.json",
            "-o", tmp_path / "w.csv", "--cache", tmp_path / "d.pc2", "--report", tmp_path / "r.json")
    frames, _, _ = read_pc2(tmp_path / "d.pc2")
    rms = dense_rms_mm(frames * 100.0, np.load(take_dir / "truth_dense_face.npz"))    # m -> cm
    assert rms < 0.205, f"dense RMS {rms:.4f} mm"                                   # measured 0.2025, as in cm
    cm = solve_take(ict_rig, read_c3d(take_dir / "take.c3d"), load_marker_map(take_dir / "marker_map.json"))
    _, _, names, W = read_weights_csv(tmp_path / "w.csv")
    assert names == ict_rig.shape_names
    assert np.abs(W - cm.weights).max() < 1e-5       # measured 1.2e-6: the glTF's float32 vertices
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["rig_units"] == "m"
    assert rep["marker_rmse"] * 100 == pytest.approx(float(np.nanmean(cm.marker_rmse)), rel=1e-3)


def test_solve_a_live_link_face_take_writes_weights_cache_report_and_gltf(ict_rig, ict_dir, llf_csv, tmp_path):
    """Issue 16: `solve` on the shared Live Link Face CSV writes the weights CSV (the rig's shapes, ARKit columns
    mapped as the GUI plays them), the PC2 cache (frame k = the rig posed with row k), the report and a glTF whose
    animation holds the CSV's weights; a weights CSV solves to the same weights again."""
    from model.livelink import read_livelink_csv
    from model.pose import PoseEvaluator
    from tests.gltf_reference import reference_animation
    out = {k: tmp_path / f"llf{k}" for k in (".csv", ".pc2", ".json", ".glb")}
    proc = run_cli("solve", ict_dir, llf_csv, "-o", out[".csv"], "--cache", out[".pc2"], "--report", out[".json"],
                   "--gltf", out[".glb"])
    assert "328 frames at 60 fps" in proc.stdout and "TongueOut" in proc.stderr
    frames, times, names, W = read_weights_csv(out[".csv"])
    played = read_livelink_csv(llf_csv, ict_rig.shape_names)          # what the GUI's Mocap panel plays
    assert names == ict_rig.shape_names and np.array_equal(W, played.weights) and W.shape == (328, 57)
    np.testing.assert_allclose(times, np.arange(328) / 60.0, atol=1e-12)
    rep = json.loads(out[".json"].read_text())
    assert rep["kind"] == "weights" and rep["frames"] == 328 and rep["rate"] == 60.0
    assert rep["unmapped"] == ["TongueOut"] and "jawOpen" in rep["shapes_driven"] and rep["marker_rmse"] is None
    t, G = reference_animation(out[".glb"])                               # read by pygltflib
    np.testing.assert_allclose(t, times, atol=1e-6)
    assert G.shape == W.shape and np.abs(G - W).max() < 1e-6               # float32 in the file
    cache, _, _ = read_pc2(out[".pc2"])
    ev = PoseEvaluator(ict_rig, dtype=np.float64)
    for k in (0, 150, 327):
        assert np.abs(cache[k] - ev.evaluate(W[k])).max() < 1e-4, k
    again = tmp_path / "again.csv"
    run_cli("solve", ict_dir, out[".csv"], "-o", again)
    assert again.read_bytes() == out[".csv"].read_bytes()


def test_a_solved_take_with_a_corrective_exports_a_valid_gltf_animation(ict_rig, take_dir, tmp_path):
    """`solve --gltf` on ICT with a corrective and the shared marker take: the animation is the solved weights plus
    the corrective's activation per frame, and the file passes the glTF validator's rules (and the Khronos validator
    itself where node and the gltf-validator module are found, on NODE_PATH)."""
    from model.correctives import Corrective, add_corrective, corrective_activations
    from model.project import Project, save_project
    from tests.gltf_reference import reference_animation
    from tests.gltf_rules import read_gltf_file, violations
    from tests.test_export import _validator
    rig = ict_rig.copy()
    jaw, smile = rig.shape_index("jawOpen"), rig.shape_index("mouthSmile_L")
    centre = 0.5 * (rig.neutral[np.argmax(np.linalg.norm(rig.deltas[jaw], axis=1))]
                    + rig.neutral[np.argmax(np.linalg.norm(rig.deltas[smile], axis=1))])
    delta = 0.3 * np.exp(-((rig.neutral - centre) ** 2).sum(axis=1) / 4.0)[:, None] * np.array([0.0, 0.6, 0.8])
    delta[np.abs(delta).max(axis=1) < 1e-9] = 0.0
    add_corrective(rig, Corrective(drivers=["jawOpen", "mouthSmile_L"], delta=delta, rule="min"))
    save_project(Project(rig=rig), tmp_path / "ict.bsproj")
    run_cli("solve", tmp_path / "ict.bsproj", take_dir / "take.c3d", "--map", take_dir / "marker_map.json",
            "-o", tmp_path / "w.csv", "--gltf", tmp_path / "take.glb")
    _, times, _, W = read_weights_csv(tmp_path / "w.csv")
    t, G = reference_animation(tmp_path / "take.glb")
    act = np.array([corrective_activations(rig.correctives, rig.shape_names, w)[0] for w in W])
    assert act.max() > 0.1                                              # the take does drive the corrective
    np.testing.assert_allclose(t, times, atol=1e-6)
    assert G.shape == (358, 58) and np.abs(G[:, :57] - W).max() < 1e-6 and np.abs(G[:, 57] - act).max() < 1e-6
    doc, blob, container = read_gltf_file(tmp_path / "take.glb")
    assert container == [] and violations(doc, blob) == []
    validate = _validator()
    if validate is not None:
        report = validate(tmp_path / "take.glb")
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:10]
        assert report["info"]["animationCount"] == 1 and report["info"]["totalVertexCount"] == 26719


def test_a_weights_csv_as_a_take_keeps_time_or_says_why_not(ict_rig, tmp_path):
    """A weights CSV read as a take: its rate from the times; frames that skip, times that do not step evenly, a
    cell too large for a CSV and a frame number that is not whole are refused in one sentence naming the file."""
    from model.errors import RigInputError
    from model.weights_csv import read_weights_take
    names = ict_rig.shape_names
    ok = tmp_path / "ok.csv"
    ok.write_text("frame,time,jawOpen\n" + "".join(f"{k},{k / 24},{k / 10}\n" for k in range(10)))
    take = read_weights_take(ok, names)
    assert take.rate == 24.0 and take.weights.shape == (10, 57) and take.weights[9, names.index("jawOpen")] == 0.9
    one = tmp_path / "one.csv"
    one.write_text("frame,time,jawOpen\n0,0.0,0.5\n")
    assert read_weights_take(one, names).warnings == [f"{one}: one frame has no frame rate; 30 frames a second assumed."]
    cases = {"skips.csv": ("frame,time,jawOpen\n0,0,0\n1,0.04,0\n3,0.12,0\n", "do not count up one by one (row 4)"),
             "uneven.csv": ("frame,time,jawOpen\n0,0,0\n1,0.04,0\n2,0.2,0\n", "not evenly spaced"),
             "huge.csv": ("frame,time,jawOpen\n0,0," + "9" * 140000 + "\n", "not a readable CSV"),
             "half.csv": ("frame,time,jawOpen\n0,0,0\n1.5,0.04,0\n", "row 3 has a frame number that is not a whole")}
    for name, (text, words) in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(RigInputError) as err:
            read_weights_take(tmp_path / name, names)
        assert name in str(err.value) and words in str(err.value), str(err.value)


def test_a_weights_csv_whose_times_are_rounded_keeps_its_rate(ict_rig, tmp_path):
    """Times written with printf's %f (6 decimals) or in milliseconds, as other tools write them: the take keeps its
    frame rate (one rounded step made 1/60 s 60.0012 fps, and the 358-frame take was refused as uneven; 1/24 s was
    23.9998 fps, the glTF's last key a third of a millisecond late)."""
    from model.weights_csv import read_weights_take
    names = ict_rig.shape_names
    for rate, frames, decimals in ((60, 358, 6), (60, 358, 3), (24, 48, 6), (30 / 1.001, 500, 6)):
        path = tmp_path / f"w_{rate:g}_{decimals}.csv"
        path.write_text("frame,time,jawOpen\n" + "".join(f"{k},{k / rate:.{decimals}f},0.5\n" for k in range(frames)))
        take = read_weights_take(path, names)
        assert take.rate == pytest.approx(rate, rel=1e-12), (path.name, take.rate)
        assert take.n_frames == frames


def test_a_weights_csv_for_another_rig_names_what_it_lacks_in_one_sentence(ict_rig, tmp_path):
    """The solve's weights of ICT given to the third-party glTF MorphStressTest: one sentence that counts the names
    it leaves out (it ended '..., browInnerUp_L ....'), read as a take and as an export's animation alike."""
    from model.errors import RigInputError
    from model.export import load_animation
    from model.readers import load_rig
    from model.weights_csv import read_weights_take, write_weights_csv
    rig = load_rig(require_data(DATA / "thirdparty" / "gltf" / "MorphStressTest.gltf"))
    path = tmp_path / "ict.csv"
    write_weights_csv(path, np.zeros((3, ict_rig.n_shapes)), ict_rig.shape_names, rate=60)
    for read in (lambda: read_weights_take(path, rig.shape_names), lambda: load_animation(path, rig)):
        with pytest.raises(RigInputError) as refused:
            read()
        assert str(refused.value) == (f"{path}: names shapes the rig does not have: "
                                      f"{', '.join(ict_rig.shape_names[:5])} and {ict_rig.n_shapes - 5} more.")


def test_the_solve_options_help_says_the_default_the_solve_uses():
    """``solve --help`` (and ``batch --help``, the same options) said --global's default was 'per region of a
    hierarchy level' while a solve without options is global (the report's "mode"; README: it measured best)."""
    import argparse
    from app.cli_solve import add_solve_options
    from model.segmentation import SegmentationSettings
    from model.take_workspace import SOLVE_DEFAULTS
    parser = argparse.ArgumentParser()
    add_solve_options(parser)
    helps = {a.dest: a.help for a in parser._actions}
    assert not SOLVE_DEFAULTS["regional"] and "(the default;" in helps["global_solve"], helps["global_solve"]
    assert "default: per region" not in helps["global_solve"]
    assert f"(default {SegmentationSettings().t:g})" in helps["threshold"]
    assert f"(default {SOLVE_DEFAULTS['level']})" in helps["level"]


def test_a_command_asks_for_ordinary_pages_and_the_window_keeps_huge_pages():
    """A command's large arrays are written once and dropped, so ``blendshape-studio COMMAND`` turns off numpy's
    request for transparent huge pages before numpy loads (the kernel's compaction on first touch cost the CLI solve
    up to twice the system time); the window, whose arrays live for the session, keeps numpy's default."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from app.command_line import opens_window
    code = ("import sys\n"
            "from app import launch\n"
            "try:\n"
            "    launch.main(['info', '--help'])\n"
            "except SystemExit:\n"
            "    pass\n"
            "import numpy\n"
            "print(numpy._core.multiarray._set_madvise_hugepage(True))\n")
    root = Path(__file__).resolve().parents[1]
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, env=env, check=True)
    assert out.stdout.splitlines()[-1] == "False", out.stdout
    assert opens_window([]) and opens_window(["rig.bsproj"]) and opens_window(["faces/ict"])
    assert not opens_window(["solve", "rig", "take.c3d"]) and not opens_window(["--help"])
