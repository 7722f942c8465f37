"""Bad input around actors (issue 15): a scan with NaN on the command line, and a project's antagonist pairs
hardened like its other members (one sentence naming the file; projects without them open as before)."""
from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from model.errors import RigInputError
from model.obj_io import write_obj
from model.project import Project, load_project, save_project
from tests.cli_runner import run_cli


def test_cli_personalize_refuses_a_scan_with_nan_and_writes_nothing(sample_rig, tmp_path):
    from resources.sample_rig import write_sample
    folder = write_sample(tmp_path / "sample")
    rig = sample_rig
    pts = rig.neutral.copy()
    pts[11, 2] = np.nan
    scan = tmp_path / "nan_scan.obj"
    write_obj(scan, pts, rig.face_counts, rig.face_indices)
    out = tmp_path / "actor.bsproj"
    for option in (["--neutral-scan", scan], ["--scans", scan]):
        proc = run_cli("personalize", folder, *option, "-o", out, check=False)
        assert proc.returncode == 2, proc.stderr
        assert "nan_scan.obj" in proc.stderr and "NaN" in proc.stderr and proc.stderr.count("\n") == 1, proc.stderr
        assert not out.exists()


def _with_manifest(src, out, edit):
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as b:
        for n in a.namelist():
            data = a.read(n)
            if n == "manifest.json":
                data = json.dumps(edit(json.loads(data))).encode()
            b.writestr(n, data)
    return out


@pytest.fixture()
def pairs_project(tmp_path, sample_rig):
    path = tmp_path / "pairs.bsproj"
    save_project(Project(rig=sample_rig.copy(), antagonists=[("jawOpen", "mouthClose"), ("mouthLeft", "mouthRight")]),
                 path)
    return path


def test_antagonist_pairs_round_trip_and_old_projects_have_none(pairs_project, tmp_path, sample_rig):
    assert load_project(pairs_project).antagonists == [("jawOpen", "mouthClose"), ("mouthLeft", "mouthRight")]
    old = tmp_path / "old.bsproj"
    save_project(Project(rig=sample_rig.copy()), old)
    assert "antagonists" not in json.loads(zipfile.ZipFile(old).read("manifest.json"))
    p = load_project(old)
    assert p.antagonists is None
    from model.antagonists import rig_antagonists
    assert p.antagonist_pairs() == rig_antagonists(sample_rig)
    # an empty list is the user's choice (no pair kept apart), not "the rig's"
    save_project(Project(rig=sample_rig.copy(), antagonists=[]), old)
    assert load_project(old).antagonists == [] and load_project(old).antagonist_pairs() == []


@pytest.mark.parametrize("value, words", [
    ("jawOpen+mouthClose", "not a list"),
    ({"a": 1}, "not a list"),
    ([["jawOpen"]], "not two shape names"),
    ([["jawOpen", 3]], "not two shape names"),
    ([["jawOpen", "mouthClose", "x"]], "not two shape names"),
    ([["jawOpen", "noSuchShape"]], "noSuchShape, which the rig does not have"),
    ([["jawOpen", "jawOpen"]], "with itself"),
    ([[["deep"] * 3, "x"]], "not two shape names"),
])
def test_a_damaged_antagonist_list_is_one_sentence_naming_the_file(pairs_project, tmp_path, value, words):
    def edit(m):
        m["antagonists"] = value
        return m
    bad = _with_manifest(pairs_project, tmp_path / "bad.bsproj", edit)
    with pytest.raises(RigInputError) as err:
        load_project(bad)
    msg = str(err.value)
    assert msg.startswith(str(bad)) and words in msg and "\n" not in msg, msg


def test_a_pair_of_a_deleted_shape_is_not_written(sample_rig, tmp_path):
    """A shape deleted after its pair was added: the file stays one the application opens."""
    rig = sample_rig.copy()
    rig.presets = {}            # (a deletion edits the presets too; they are not what this test is about)
    p = Project(rig=rig, antagonists=[("jawOpen", "mouthClose"), ("mouthLeft", "mouthRight")])
    k = rig.shape_index("mouthClose")
    rig.shape_names = rig.shape_names[:k] + rig.shape_names[k + 1:]
    rig.deltas = np.delete(rig.deltas, k, axis=0)
    p.weights = np.delete(p.weights, k)
    path = tmp_path / "deleted.bsproj"
    save_project(p, path)
    assert load_project(path).antagonists == [("mouthLeft", "mouthRight")]


def test_duplicated_pairs_are_kept_once(pairs_project, tmp_path):
    def edit(m):
        m["antagonists"] = [["jawOpen", "mouthClose"], ["mouthClose", "jawOpen"]]
        return m
    assert load_project(_with_manifest(pairs_project, tmp_path / "dup.bsproj", edit)).antagonists == \
        [("jawOpen", "mouthClose")]
