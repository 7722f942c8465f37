"""The command line on real data: info, export, render, and one-sentence errors with a non-zero exit."""
from __future__ import annotations

import json

import numpy as np
import pytest

from model.obj_io import read_obj
from model.readers import load_rig
from tests.cli_runner import run_cli
from tests.conftest import DATA, require_data
from tests.rig_files import write_rig_folder


def test_info_json_on_ict(ict_dir):
    info = json.loads(run_cli("info", ict_dir, "--json").stdout)
    assert info["vertices"] == 26719 and info["faces"] == 26384 and len(info["shapes"]) == 57
    assert info["units"] == "cm" and "jawOpen" in info["shapes"]
    # DESIGN.md's contract: the neutral's bounds as {"min": [x, y, z], "max": [x, y, z]}, in the rig's units
    rig = load_rig(ict_dir)
    np.testing.assert_allclose(info["bounds"]["min"], rig.neutral.min(axis=0), atol=1e-5)
    np.testing.assert_allclose(info["bounds"]["max"], rig.neutral.max(axis=0), atol=1e-5)


def test_export_keeps_vertex_order(ict_dir, ict_rig, tmp_path):
    out = tmp_path / "jaw.obj"
    run_cli("export", ict_dir, "--weights", "jawOpen=1,mouthSmile_L=0.5", "-o", out)
    mesh = read_obj(out)
    expected = ict_rig.neutral + ict_rig.deltas[ict_rig.shape_index("jawOpen")] \
        + 0.5 * ict_rig.deltas[ict_rig.shape_index("mouthSmile_L")]
    assert mesh.vertices.shape == (26719, 3)
    np.testing.assert_allclose(mesh.vertices, expected, atol=1e-5)
    assert np.array_equal(mesh.face_counts, ict_rig.face_counts)
    assert np.array_equal(mesh.face_indices, ict_rig.face_indices)


def test_render_jaw_open_changes_the_mouth(ict_dir, tmp_path):
    from tests.image_compare import load_png
    run_cli("render", ict_dir, "-o", tmp_path / "n.png", "--size", "400,400")
    run_cli("render", ict_dir, "-o", tmp_path / "j.png", "--size", "400,400", "--weights", "jawOpen=1")
    a, b = load_png(tmp_path / "n.png"), load_png(tmp_path / "j.png")
    assert a.shape == (400, 400, 3)
    diff = np.abs(a.astype(int) - b.astype(int)).sum(axis=2) > 40
    ys, xs = np.nonzero(diff)
    assert diff.sum() > 500, "opening the jaw should change many pixels"
    # The change sits in the lower-middle of the face (mouth and chin), not at the top of the head.
    assert 0.45 * 400 < np.median(ys) < 0.85 * 400 and 0.35 * 400 < np.median(xs) < 0.65 * 400


@pytest.mark.parametrize("args, words", [
    (["info", "{folder}/nope"], ["does not exist"]),
    (["render", "{folder}", "-o", "{tmp}/x.png", "--weights", "jawOpen=1"], ["no shape named 'jawOpen'"]),
    (["render", "{folder}", "-o", "{tmp}/x.png", "--weights", "raise"], ["not NAME=VALUE"]),
    (["export", "{folder}", "-o", "{tmp}/x.obj", "--weights", "raise=abc"], ["not a number"]),
    (["render", "{folder}", "-o", "{tmp}/x.png", "--size", "big"], ["--size"]),
])
def test_cli_errors_are_one_sentence(tmp_path, args, words):
    folder = tmp_path / "rig"
    write_rig_folder(folder)
    proc = run_cli(*[a.format(folder=folder, tmp=tmp_path) for a in args], check=False)
    assert proc.returncode != 0
    err = proc.stderr.strip()
    assert err.startswith("error: ") and err.count("\n") == 0, err
    for w in words:
        assert w in err


def test_cli_bad_target_names_the_file(tmp_path):
    folder = tmp_path / "rig"
    write_rig_folder(folder)
    (folder / "raise.obj").write_text("v 1 2\n")
    proc = run_cli("info", folder, check=False)
    assert proc.returncode == 2 and "raise.obj" in proc.stderr


@pytest.mark.parametrize("args, sentence", [
    (["render", "{folder}", "-o", "{tmp}/x.png", "--weights", "nosuchshape=1"],
     "{folder}: the rig has no shape named 'nosuchshape' (--weights)."),
    (["export", "{folder}", "-o", "{tmp}/x.obj", "--weights", "nosuchshape=1"],
     "{folder}: the rig has no shape named 'nosuchshape' (--weights)."),
    (["render", "{folder}", "-o", "{tmp}/x.png", "--view", "segmentation", "--threshold", "5"],
     "{folder}: --threshold 5 is outside 0 to 1 (a quantile of the rig's moving skin)."),
    (["segment", "{folder}", "-o", "{tmp}/x.json", "--threshold", "5"],
     "{folder}: --threshold 5 is outside 0 to 1 (a quantile of the rig's moving skin)."),
    (["render", "{folder}", "-o", "{tmp}/x.png", "--size", "-5,100"],
     "--size: -5x100 is not a positive size in pixels (16..8192 each)."),
    (["render", "{folder}", "-o", "{tmp}/x.png", "--camera", "above"],
     "argument --camera: invalid choice: 'above' (choose from … (see blendshape-studio render --help)."),
    (["render", "{folder}"], "the following arguments are required: -o/--output (see blendshape-studio render "
                             "--help)."),
    # 1e308 passed as finite and posed the surface to inf and NaN: the OBJ was written full of "v nan nan -inf"
    (["export", "{folder}", "-o", "{tmp}/x.obj", "--weights", "raise=1e308"],
     "--weights: the value of 'raise' is outside ±1000."),
    (["render", "{folder}", "-o", "{tmp}/x.png", "--weights", "push=-1001"],
     "--weights: the value of 'push' is outside ±1000."),
    # 10⁸ rounds of smoothing (or of a project's closing rings) ran on and on: still running after 5 minutes
    (["segment", "{folder}", "-o", "{tmp}/x.json", "--smoothing", "100000000"],
     "{folder}: the segmentation setting 'smoothing' must be at most 1000; got 100000000."),
    (["segment", "{folder}", "-o", "{tmp}/x.json", "--overlap", "1001"],
     "{folder}: the segmentation setting 'overlap_rings' must be at most 1000; got 1001."),
])
def test_errors_are_one_sentence_naming_the_rig_and_argparse_gives_no_usage_block(tmp_path, args, sentence):
    """Audit item 11: the rig's path in a sentence about the rig; argparse's complaints (an unknown choice, a
    missing option) as one `error:` line, exit 2, not its usage block; `--size -5,100` read as --size's value
    (argparse took it for an option: "expected one argument") and refused as not positive. A weight or a round
    count beyond reason is refused at once: `export --weights raise=1e308` wrote an OBJ of NaN and inf, and
    `segment --smoothing 100000000` ran on for minutes."""
    folder = tmp_path / "rig"
    write_rig_folder(folder)
    proc = run_cli(*[a.format(folder=folder, tmp=tmp_path) for a in args], check=False, timeout=60)
    assert proc.returncode == 2 and proc.stdout == ""
    head, _, tail = f"error: {sentence.format(folder=folder)}\n".partition("…")   # "…": argparse's list of choices
    assert proc.stderr.startswith(head) and proc.stderr.endswith(tail) and proc.stderr.count("\n") == 1, proc.stderr
    assert not any(p.name.startswith("x.") for p in tmp_path.iterdir())      # nothing written


def test_a_rig_option_that_says_nothing_of_the_rig_is_refused(tmp_path):
    """--units on a project, --mesh on an OBJ folder, --neutral on a glTF were ignored (`info P.bsproj --units mm`
    printed the project's cm): one sentence naming the rig, exit 2."""
    from model.gltf import write_gltf
    from model.project import Project, save_project
    folder = tmp_path / "rig"
    write_rig_folder(folder)
    rig = load_rig(folder)
    save_project(Project(rig=rig), tmp_path / "p.bsproj")
    write_gltf(rig, tmp_path / "r.glb")
    take = tmp_path / "take.csv"
    take.write_text("frame,raise\n0,0.5\n1,1\n")
    for args, path, sentence in [
            (("info", folder, "--mesh", "Face"), folder,
             "is an OBJ folder, and --mesh names the mesh of a glTF to read."),
            (("info", tmp_path / "r.glb", "--neutral", "neutral.obj"), tmp_path / "r.glb",
             "is a glTF, and --neutral names the neutral OBJ of an OBJ folder."),
            *((args, tmp_path / "p.bsproj", "is a project, and --units names the units of an OBJ folder or a glTF (a "
                                            "project keeps its own).")
              for args in (("info", tmp_path / "p.bsproj", "--units", "mm"),
                           ("solve", tmp_path / "p.bsproj", take, "--units", "mm", "-o", tmp_path / "w.csv"),
                           ("corrective", tmp_path / "p.bsproj", "--drivers", "raise,push", "--target",
                            folder / "raise.obj", "--units", "mm", "-o", tmp_path / "c.bsproj")))]:
        proc = run_cli(*args, check=False)
        assert (proc.returncode, proc.stdout, proc.stderr) == (2, "", f"error: {path}: {sentence}\n"), args


def test_a_rig_of_a_neutral_alone_renders_exports_and_refuses_a_solve(tmp_path):
    """A folder holding only its neutral is a rig of no shapes: `render` and `export` to OBJ failed unexpectedly
    (exit 1, a crash log: ValueError reshaping its 0 deltas), and so did `solve` on a marker take (a maximum of no
    shapes). The surface renders and exports as it is, and the solve is one sentence naming the rig."""
    folder = tmp_path / "rig"
    write_rig_folder(folder)
    for shape in ("raise", "push"):
        (folder / f"{shape}.obj").unlink()
    run_cli("render", folder, "--size", "32,32", "-o", tmp_path / "r.png")
    run_cli("export", folder, "-o", tmp_path / "e.obj")
    np.testing.assert_array_equal(read_obj(tmp_path / "e.obj").vertices, read_obj(folder / "neutral.obj").vertices)
    take = tmp_path / "markers.csv"
    take.write_text("frame,A_X,A_Y,A_Z\n" + "".join(f"{i},1,2,3\n" for i in range(40)))
    proc = run_cli("solve", folder, take, "-o", tmp_path / "w.csv", check=False)
    assert (proc.returncode, proc.stderr) == (2, f"error: {folder}: the rig has no shapes to solve the take's markers "
                                                 "with.\n") and not (tmp_path / "w.csv").exists()
    # a deformation view: no shapes, no deformation (before: "nothing to segment", though no segmentation was asked)
    for view in ("deformation", "deformation-rgb"):
        proc = run_cli("render", folder, "--view", view, "-o", tmp_path / "d.png", check=False)
        assert (proc.returncode, proc.stderr) == (2, f"error: {folder}: the rig has no blendshapes, so there is no "
                                                     "deformation to show.\n") and not (tmp_path / "d.png").exists()


def test_a_segmentation_or_level_the_rig_cannot_give_names_the_rig(ict_dir, tmp_path):
    proc = run_cli("render", ict_dir, "--view", "segmentation", "--level", "99", "-o", tmp_path / "x.png", check=False)
    assert proc.returncode == 2 and proc.stderr == \
        f"error: {ict_dir}: --level 99 does not exist: this segmentation has levels 0 to 4.\n", proc.stderr
    morph = require_data(DATA / "thirdparty" / "gltf" / "SimpleMorph.gltf")
    proc = run_cli("render", morph, "--view", "segmentation", "-o", tmp_path / "x.png", check=False)
    assert proc.returncode == 2 and proc.stderr.startswith(f"error: {morph}: this rig cannot be segmented")
    assert proc.stderr.count("\n") == 1 and not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("rig, args, advice", [
    # 3 vertices, one of them moving: no threshold and no minimum size can make a region; lowering either is no help
    ("tiny", (), "this rig cannot be segmented: its shapes move 1 vertex of the skin, too few for a region at any "
                 "threshold or minimum region size."),
    # 36 vertices: a threshold as low as 0 still leaves fewer than 100; only a smaller --min-size helps, and works
    ("grid", ("--min-size", "100"), "no threshold leaves a region of at least 100 vertices on this rig (its shapes "
                                    "move 35 vertices of the skin); lower the minimum region size."),
    ("grid", ("--threshold", "1"), "the threshold t=1 leaves no region of at least 30 vertices; lower the threshold "
                                   "or the minimum region size."),
    # a minimum of 1 cannot be lowered: only the threshold is named
    ("grid", ("--threshold", "1", "--min-size", "1"), "the threshold t=1 leaves no region of at least 1 vertex; "
                                                      "lower the threshold."),
])
def test_a_segmentation_that_leaves_no_region_gives_advice_that_helps(tmp_path, rig, args, advice):
    """`render --view segmentation` on a rig too small for a region said "lower the threshold", which cannot help:
    the advice names only what would leave a region, and `render --min-size` is there to follow it."""
    folder = tmp_path / rig
    if rig == "tiny":
        folder.mkdir()
        (folder / "neutral.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        (folder / "jawOpen.obj").write_text("v 0 0 0.1\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    else:
        write_rig_folder(folder)
    out = tmp_path / "x.png"
    proc = run_cli("render", folder, "--view", "segmentation", *args, "-o", out, check=False)
    assert (proc.returncode, proc.stderr) == (2, f"error: {folder}: {advice}\n") and not out.exists()
    if "--min-size" in args:       # the advice followed: a smaller minimum region size renders the regions
        run_cli("render", folder, "--view", "segmentation", "--min-size", "5", "--size", "64,64", "-o", out)
        assert out.exists()
