"""`corrective` from a scan (Smith §4.5): export at full drivers reproduces the scan; one driver off, it is gone."""
from __future__ import annotations

import json

import numpy as np
import pytest

from model.obj_io import read_obj, write_obj
from tests.cli_runner import run_cli


@pytest.fixture(scope="module")
def sample_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sample") / "rig"
    run_cli("sample", "-o", out)
    return out


def _scan(sample_dir, tmp_path, weights, name="scan.obj"):
    """The rig's own combination plus a smooth forehead bump: what a sculptor or a scanner would give."""
    run_cli("export", sample_dir, "--weights", weights, "-o", tmp_path / "combo.obj")
    m = read_obj(tmp_path / "combo.obj")
    v = m.vertices.copy()
    centre = np.array([0.0, np.percentile(v[:, 1], 85), v[:, 2].max()])
    v[:, 2] += 0.25 * np.exp(-np.sum((v - centre) ** 2, axis=1) / 4.0)
    write_obj(tmp_path / name, v, m.face_counts, m.face_indices)
    return v


@pytest.mark.parametrize("rule", ["product", "hierarchical", "min", "smooth-min"])
def test_corrective_from_scan_round_trip(sample_dir, tmp_path, rule):
    scan = _scan(sample_dir, tmp_path, "browInnerUp_L=1,browInnerUp_R=1")
    out = tmp_path / "fixed.bsproj"
    run_cli("corrective", sample_dir, "--drivers", "browInnerUp_L,browInnerUp_R", "--target", tmp_path / "scan.obj",
            "--rule", rule, "-o", out)
    info = json.loads(run_cli("info", out, "--json").stdout)
    assert info["correctives"] == [{"name": "browInnerUp_L+browInnerUp_R",
                                    "drivers": ["browInnerUp_L", "browInnerUp_R"], "rule": rule,
                                    "muted": False}]
    run_cli("export", out, "--weights", "browInnerUp_L=1,browInnerUp_R=1", "-o", tmp_path / "full.obj")
    np.testing.assert_allclose(read_obj(tmp_path / "full.obj").vertices, scan, atol=2e-6)
    # One driver off: the corrective adds nothing, the surface is the plain shape.
    run_cli("export", out, "--weights", "browInnerUp_L=1", "-o", tmp_path / "one.obj")
    run_cli("export", sample_dir, "--weights", "browInnerUp_L=1", "-o", tmp_path / "plain.obj")
    np.testing.assert_array_equal(read_obj(tmp_path / "one.obj").vertices, read_obj(tmp_path / "plain.obj").vertices)


def test_corrective_bad_input(sample_dir, tmp_path):
    _scan(sample_dir, tmp_path, "browInnerUp_L=1,browInnerUp_R=1")
    cases = [
        (["--drivers", "browInnerUp_L"], "two or more driver shapes"),
        # the rig named (before: "The rig has no shape named 'notAShape'.", no file)
        (["--drivers", "browInnerUp_L,notAShape"], f"error: {sample_dir}: the rig has no shape named 'notAShape' "
                                                   "(--drivers).\n"),
        (["--drivers", "browInnerUp_L,browInnerUp_L"], "error: --drivers: browInnerUp_L is listed more than once.\n"),
        (["--drivers", "browInnerUp_L,browInnerUp_R", "--rule", "sum"], "unknown rule"),
    ]
    for extra, words in cases:
        proc = run_cli("corrective", sample_dir, "--target", tmp_path / "scan.obj", "-o", tmp_path / "x.bsproj",
                       *extra, check=False)
        assert proc.returncode == 2 and words in proc.stderr, proc.stderr
    small = tmp_path / "small.obj"
    small.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    proc = run_cli("corrective", sample_dir, "--drivers", "browInnerUp_L,browInnerUp_R", "--target", small,
                   "-o", tmp_path / "x.bsproj", check=False)
    assert proc.returncode == 2 and "small.obj" in proc.stderr and "3 vertices" in proc.stderr
    assert not (tmp_path / "x.bsproj").exists()


def test_corrective_with_mirror_adds_the_other_side(sample_dir, tmp_path):
    from solvers.symmetry import mirror_map
    scan = _scan(sample_dir, tmp_path, "browInnerUp_L=1,browOuterUp_L=1")
    out = tmp_path / "both.bsproj"
    proc = run_cli("corrective", sample_dir, "--drivers", "browInnerUp_L,browOuterUp_L", "--target",
                   tmp_path / "scan.obj", "--rule", "min", "--mirror", "-o", out)
    assert "browInnerUp_L+browOuterUp_L and browInnerUp_R+browOuterUp_R" in proc.stdout
    info = json.loads(run_cli("info", out, "--json").stdout)
    assert info["correctives"] == [
        {"name": "browInnerUp_L+browOuterUp_L", "drivers": ["browInnerUp_L", "browOuterUp_L"], "rule": "min",
         "muted": False},
        {"name": "browInnerUp_R+browOuterUp_R", "drivers": ["browInnerUp_R", "browOuterUp_R"], "rule": "min",
         "muted": False}]
    # the right-side combination is the mirror image of the left-side scan (the sample rig is symmetric)
    run_cli("export", out, "--weights", "browInnerUp_R=1,browOuterUp_R=1", "-o", tmp_path / "right.obj")
    right = read_obj(tmp_path / "right.obj").vertices
    m = mirror_map(read_obj(sample_dir / "neutral.obj").vertices)
    np.testing.assert_allclose(right, scan[m] * np.array([-1.0, 1.0, 1.0]), atol=1e-4)
    # a pair that is its own mirror image is refused with one sentence
    proc = run_cli("corrective", sample_dir, "--drivers", "browInnerUp_L,browInnerUp_R", "--target",
                   tmp_path / "scan.obj", "--mirror", "-o", tmp_path / "x.bsproj", check=False)
    assert proc.returncode == 2 and "its own mirror image" in proc.stderr, proc.stderr
    assert not (tmp_path / "x.bsproj").exists()


def test_info_and_export_of_a_muted_corrective(sample_dir, tmp_path):
    from dataclasses import replace
    from model.project import load_project, save_project
    _scan(sample_dir, tmp_path, "browInnerUp_L=1,browInnerUp_R=1")
    out = tmp_path / "fixed.bsproj"
    run_cli("corrective", sample_dir, "--drivers", "browInnerUp_L,browInnerUp_R", "--target", tmp_path / "scan.obj",
            "-o", out)
    project = load_project(out)
    project.rig.correctives = [replace(c, muted=True) for c in project.rig.correctives]
    save_project(project, tmp_path / "muted.bsproj")
    assert "correctives: browInnerUp_L+browInnerUp_R (muted)" in run_cli("info", tmp_path / "muted.bsproj").stdout
    assert json.loads(run_cli("info", tmp_path / "muted.bsproj", "--json").stdout)["correctives"][0]["muted"]
    # a muted corrective is left out of the exported surface: the plain combination comes out
    run_cli("export", tmp_path / "muted.bsproj", "--weights", "browInnerUp_L=1,browInnerUp_R=1", "-o",
            tmp_path / "muted.obj")
    np.testing.assert_allclose(read_obj(tmp_path / "muted.obj").vertices, read_obj(tmp_path / "combo.obj").vertices,
                               atol=2e-6)
