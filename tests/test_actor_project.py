"""A project's antagonist pairs (issue 15): saved, hardened like the project's other members (one sentence naming
the file; projects without them open as before) and used by `solve` on the project; and a scan with NaN refused by
`personalize` on the command line."""
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


def test_cli_solve_on_a_project_keeps_its_own_pairs_apart(sample_rig, tmp_path):
    """jawOpen and mouthSmile_L both at 0.6 in a take: the rig's pairs let the solve find both, a project that added
    the pair holds them apart; the report says which list was used."""
    import csv
    from model.take_csv import write_marker_csv
    from model.take_data import MarkerTake
    rig = sample_rig
    k1, k2 = rig.shape_index("jawOpen"), rig.shape_index("mouthSmile_L")
    moving = np.flatnonzero(np.linalg.norm(rig.deltas[k1], axis=1) + np.linalg.norm(rig.deltas[k2], axis=1) > 0.05)
    verts = moving[np.linspace(0, len(moving) - 1, 24).astype(int)]
    w = np.zeros((60, rig.n_shapes))
    w[30:, [k1, k2]] = 0.6
    X = rig.neutral[None] + np.einsum("fk,kvc->fvc", w, rig.deltas)
    labels = [f"M{i:02d}" for i in range(len(verts))]
    take = tmp_path / "both.csv"
    write_marker_csv(take, MarkerTake(X[:, verts] * 10.0, labels, 30.0, units="mm"))
    (tmp_path / "map.json").write_text(json.dumps({"rig_units": "cm", "markers": dict(zip(labels, map(int, verts)))}))
    from model.antagonists import rig_antagonists
    pairs = rig_antagonists(rig) + [("jawOpen", "mouthSmile_L")]
    edited, plain = tmp_path / "edited.bsproj", tmp_path / "plain.bsproj"
    save_project(Project(rig=rig.copy(), antagonists=pairs), edited)
    save_project(Project(rig=rig.copy()), plain)
    weights = {}
    for path in (edited, plain):
        run_cli("solve", path, take, "--map", tmp_path / "map.json", "--global", "--residual", "none",
                "-o", tmp_path / f"{path.stem}.csv", "--report", tmp_path / f"{path.stem}.json")
        with open(tmp_path / f"{path.stem}.csv") as f:
            rows = list(csv.DictReader(f))
        weights[path.stem] = np.array([[float(r["jawOpen"]), float(r["mouthSmile_L"])] for r in rows[40:]])
    assert json.loads((tmp_path / "edited.json").read_text())["antagonists"] == ["+".join(p) for p in pairs]
    assert json.loads((tmp_path / "plain.json").read_text())["antagonists"] is None
    both_edited, both_plain = weights["edited"].min(axis=1).mean(), weights["plain"].min(axis=1).mean()
    assert both_plain > 0.5 and both_edited < both_plain - 0.05, (both_edited, both_plain)
