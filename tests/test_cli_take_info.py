"""`blendshape-studio take-info TAKE [--json]`: what a take holds, as the readers see it."""
from __future__ import annotations

import json

import numpy as np

from model.take_c3d import read_c3d
from tests.cli_runner import run_cli
from tests.conftest import DATA, require_data


def test_take_info_json_on_the_shared_take(take_dir):
    info = json.loads(run_cli("take-info", take_dir / "take.c3d", "--json").stdout)
    take = read_c3d(take_dir / "take.c3d")
    assert info["kind"] == "markers" and info["frames"] == 358 and info["rate"] == 60.0 and info["units"] == "mm"
    assert info["labels"] == take.labels and info["warnings"] == []
    missing = take.missing.sum(axis=0)
    assert info["missing"] == {label: int(n) for label, n in zip(take.labels, missing)} and sum(missing) > 0
    seen = take.positions[~take.missing]
    np.testing.assert_allclose(info["bounds"]["min"], seen.min(axis=0), atol=1e-6)
    np.testing.assert_allclose(info["bounds"]["max"], seen.max(axis=0), atol=1e-6)


def test_take_info_says_what_the_reader_decided():
    """A C3D whose parameters disagree with its data: the reading and the warnings reach the user."""
    path = require_data(DATA / "thirdparty" / "c3d" / "Sample13__Dance1.c3d")
    proc = run_cli("take-info", path)
    assert "498 frames at 65.0364 fps, 40 markers (mm)" in proc.stdout
    assert "warning:" in proc.stderr and "POINT:FRAMES says 499" in proc.stderr
    info = json.loads(run_cli("take-info", path, "--json").stdout)
    assert info["frames"] == 498 and any("POINT:DATA_START says 1" in w for w in info["warnings"])


def test_take_info_on_a_live_link_face_csv(llf_csv):
    info = json.loads(run_cli("take-info", llf_csv, "--json").stdout)
    assert info["kind"] == "weights" and info["frames"] == 328 and info["rate"] == 60.0
    assert "JawOpen" in info["labels"] and "HeadYaw" not in info["labels"] and info["dropped_frames"] == 0


def test_take_info_bad_input_is_one_sentence(tmp_path):
    junk = tmp_path / "junk.c3d"
    junk.write_bytes(b"hello" * 200)
    proc = run_cli("take-info", junk, check=False)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.strip() == f"error: {junk}: is not a C3D file (no C3D header)."
    analog = require_data(DATA / "thirdparty" / "c3d" / "Sample30__emgwl.c3d")
    proc = run_cli("take-info", analog, "--json", check=False)
    assert proc.returncode == 2 and "holds no 3D points" in proc.stderr and proc.stderr.count("\n") == 1


def test_a_weights_csv_without_a_time_column_is_a_weight_take(ict_rig, ict_dir, tmp_path):
    """`frame,<shape names>` (the shared actor take's truth_weights.csv) is a weights CSV, not a marker CSV: before,
    `take-info` and `solve` said "after the frame column the header needs X, Y and Z columns per marker". It reads at
    30 frames a second with a warning (the file holds no rate), and `solve` plays it on the rig; a weights CSV as
    `solve` writes it (`frame,time,...`) is a weight take to `take-info` too. Marker CSV headers keep their message."""
    truth = require_data(DATA / "mocap" / "actor_take" / "truth_weights.csv")
    header = truth.read_text().splitlines()[0].split(",")
    proc = run_cli("take-info", truth, "--json")
    info = json.loads(proc.stdout)
    assert info["kind"] == "weights" and info["frames"] == 358 and info["rate"] == 30.0
    assert info["labels"] == header[1:] and info["warnings"] == [f"{truth}: has no time column; 30 frames a second "
                                                                 "assumed."]
    run_cli("solve", ict_dir, truth, "-o", tmp_path / "w.csv", "--report", tmp_path / "r.json")
    from model.weights_csv import read_weights_csv
    _, times, names, W = read_weights_csv(tmp_path / "w.csv")
    truth_w = np.loadtxt(truth, delimiter=",", skiprows=1)[:, 1:]
    assert names == ict_rig.shape_names and np.allclose(times, np.arange(358) / 30.0)
    assert np.array_equal(W[:, [names.index(n) for n in header[1:]]], truth_w)
    assert json.loads((tmp_path / "r.json").read_text())["warnings"] == info["warnings"]
    info = json.loads(run_cli("take-info", tmp_path / "w.csv", "--json").stdout)
    assert info["kind"] == "weights" and info["rate"] == 30.0 and info["labels"] == ict_rig.shape_names
    for text, words in (("frame,A_X,A_Y\n0,1,2\n", "after the frame column the header needs X, Y and Z columns"),
                        ("frame,M0x,M0y,M0z\n0,1,2,3\n", "columns M0x, M0y, M0z are not one marker's name_X")):
        (tmp_path / "m.csv").write_text(text)
        proc = run_cli("take-info", tmp_path / "m.csv", check=False)
        assert proc.returncode == 2 and words in proc.stderr, proc.stderr


def test_rate_gives_the_frame_rate_of_a_weight_take_whose_file_has_none(tmp_path):
    """A weights CSV without a time column read at 30 fps with a warning, and nothing could say its rate: `--rate` on
    take-info, solve, batch and export --animation reads it at the rate given (no warning); a file with its own rate
    keeps it, with a warning naming --rate; a rate that is not positive and finite is one sentence, exit 2, before
    anything is written."""
    from model.weights_csv import read_weights_csv
    from tests.gltf_reference import reference_animation
    from tests.rig_files import write_rig_folder
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    take = tmp_path / "take.csv"
    W = np.round(np.abs(np.sin(np.arange(10)[:, None] + np.arange(2))), 4)
    take.write_text("frame,raise,push\n" + "".join(f"{f},{a},{b}\n" for f, (a, b) in enumerate(W)))
    info = json.loads(run_cli("take-info", take, "--json", "--rate", "24").stdout)
    assert info["rate"] == 24.0 and info["warnings"] == []
    run_cli("solve", rig, take, "--rate", "24", "-o", tmp_path / "w.csv", "--report", tmp_path / "r.json")
    _, times, names, solved = read_weights_csv(tmp_path / "w.csv")
    assert np.allclose(times, np.arange(10) / 24) and np.array_equal(solved[:, [names.index("raise"),
                                                                                names.index("push")]], W)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["rate"] == 24.0 and report["warnings"] == []
    proc = run_cli("export", rig, "-o", tmp_path / "a.glb", "--animation", take, "--rate", "24")
    assert proc.stderr == "" and np.allclose(reference_animation(tmp_path / "a.glb")[0], np.arange(10) / 24)
    run_cli("batch", rig, take, "-o", tmp_path / "batch", "--rate", "24", "--workers", "1")
    assert json.loads((tmp_path / "batch" / "batch.json").read_text())["takes"][0]["rate"] == 24.0
    assert np.allclose(read_weights_csv(tmp_path / "batch" / "take" / "weights.csv")[1], np.arange(10) / 24)
    # a file with its own times keeps them: --rate is for a file without
    info = json.loads(run_cli("take-info", tmp_path / "w.csv", "--json", "--rate", "30").stdout)
    assert info["rate"] == 24.0 and info["warnings"] == [
        f"{tmp_path / 'w.csv'}: --rate 30 is not used: the file gives its own frame rate (24 fps)."]
    # not a frame rate: one sentence, exit 2, nothing written
    for rate in ("0", "-5", "nan", "inf"):
        shown = {"-5": "-5", "nan": "nan", "inf": "inf"}.get(rate, "0")
        sentence = f"error: --rate: {shown} is not a frame rate; give frames a second from 0.001 to 100000.\n"
        for args in (("take-info", take), ("solve", rig, take, "-o", tmp_path / "x.csv"),
                     ("export", rig, "-o", tmp_path / "x.glb", "--animation", take),
                     ("batch", rig, take, "-o", tmp_path / "xb")):
            proc = run_cli(*args, "--rate", rate, check=False)
            assert (proc.returncode, proc.stdout, proc.stderr) == (2, "", sentence), (args, proc.stderr)
    assert not any((tmp_path / n).exists() for n in ("x.csv", "x.glb", "xb"))


def test_a_weights_csv_of_a_header_alone_holds_no_frames(tmp_path):
    """`frame,time,jawOpen` with no rows read as a take of 0 frames ("one frame has no frame rate" said the warning);
    `solve` and `export --animation` then refused it as needing "one row of weights per frame time". Every command
    says what it is: no frames, one sentence, exit 2."""
    from tests.rig_files import write_rig_folder
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    for header in ("frame,time,raise\n", "frame,raise\n"):
        take = tmp_path / "take.csv"
        take.write_text(header)
        for args in (("take-info", take), ("solve", rig, take, "-o", tmp_path / "w.csv"),
                     ("export", rig, "-o", tmp_path / "a.glb", "--animation", take)):
            proc = run_cli(*args, check=False)
            assert (proc.returncode, proc.stdout, proc.stderr) == (2, "", f"error: {take}: holds no frames.\n"), args


def test_a_plain_marker_csv_read_without_a_rate_says_the_rate_it_assumed(tmp_path):
    """A plain marker CSV (`frame,NAME_X,NAME_Y,NAME_Z`) has no frame rate of its own; read without `--rate` it was
    taken at 60 fps with no word. Now one warning sentence names the file, the 60 fps assumed and `--rate`, on
    take-info's stderr and in its JSON `warnings`; `--rate` gives the rate, and no warning."""
    from model.takes import load_take
    take = tmp_path / "plain.csv"
    take.write_text("frame,A_X,A_Y,A_Z\n0,1,2,3\n1,1,2,4\n")
    proc = run_cli("take-info", take)
    assert "2 frames at 60 fps" in proc.stdout
    said = [line for line in proc.stderr.splitlines() if line.startswith("warning:")]
    assert len(said) == 1 and str(take) in said[0] and "60 frames a second" in said[0] and "--rate" in said[0]
    info = json.loads(run_cli("take-info", take, "--json").stdout)
    assert info["rate"] == 60.0 and info["warnings"] == [said[0].removeprefix("warning: ")]
    assert load_take(take).warnings == info["warnings"]
    info = json.loads(run_cli("take-info", take, "--json", "--rate", "120").stdout)
    assert info["rate"] == 120.0 and info["warnings"] == []
