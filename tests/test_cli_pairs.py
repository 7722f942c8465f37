"""`pairs`: the interference finder from the command line, ranked as in the Correctives panel."""
from __future__ import annotations

import json
import subprocess

import numpy as np

from model.interference import PairRow, pair_scores, ranked_pairs, rig_vertex_areas
from solvers.correctives import overshoot_heat
from tests.cli_runner import command, run_cli


def test_pairs_on_ict_rank_smiths_brow_pair_and_say_where(ict_dir, ict_rig):
    out = json.loads(run_cli("pairs", ict_dir, "--top", "12", "--json").stdout)
    assert out["measure"] == "overshoot" and out["units"] == "cm" and len(out["pairs"]) == 12
    rows = {frozenset(r["shapes"]): r for r in out["pairs"]}
    brows = rows[frozenset(("browInnerUp_L", "browInnerUp_R"))]
    assert brows["rank"] <= 10 and brows["mirror"] is None
    lids = out["pairs"][0]
    assert lids["shapes"] == ["eyeLookUp_L", "eyeWide_L"] and lids["mirror"] == ["eyeLookUp_R", "eyeWide_R"]
    # the same numbers as the GUI's finder: score from the area-weighted matrix, peak and area from the heat
    names = ict_rig.shape_names
    i, j = names.index("browInnerUp_L"), names.index("browInnerUp_R")
    areas = rig_vertex_areas(ict_rig)
    assert brows["score"] == round(pair_scores(ict_rig, "overshoot", areas)[i, j], 6)
    heat = overshoot_heat(ict_rig.deltas[i], ict_rig.deltas[j])
    assert brows["peak"] == round(float(heat.max()), 6)
    assert brows["area"] == round(float(areas[heat > 0.1 * heat.max()].sum()), 6)
    assert 0.2 < brows["peak"] < 0.3 and 40 < brows["area"] < 70      # cm, cm²: the brow midline
    assert [r["shapes"] for r in out["pairs"]] == [[names[r.i], names[r.j]] for r in
                                                   ranked_pairs(pair_scores(ict_rig), names, 12)]


def test_pairs_options_and_text(ict_dir):
    partners = json.loads(run_cli("pairs", ict_dir, "--partners-of", "browInnerUp_L", "--top", "3",
                                  "--json").stdout)["pairs"]
    assert [r["shapes"][1] for r in partners] == ["browInnerUp_R", "browOuterUp_L", "browOuterUp_R"]
    separate = json.loads(run_cli("pairs", ict_dir, "--separate-sides", "--top", "2", "--json").stdout)["pairs"]
    assert {frozenset(r["shapes"]) for r in separate} == {frozenset(("eyeLookUp_L", "eyeWide_L")),
                                                         frozenset(("eyeLookUp_R", "eyeWide_R"))}
    overlap = json.loads(run_cli("pairs", ict_dir, "--measure", "overlap", "--top", "1", "--json").stdout)
    assert overlap["measure"] == "overlap" and 0.99 < overlap["pairs"][0]["score"] <= 1.0
    text = run_cli("pairs", ict_dir, "--top", "3").stdout.splitlines()
    assert text[0].startswith("3 pairs by overshoot (cm") and len(text) == 4
    assert "eyeLookUp_L × eyeWide_L" in text[1] and "cm²" in text[1] and "and eyeLookUp_R × eyeWide_R" in text[1]


def test_pairs_bad_input(ict_dir, tmp_path):
    bad = run_cli("pairs", ict_dir, "--partners-of", "nose", check=False)
    assert bad.returncode == 2 and bad.stderr.strip() == \
        f"error: {ict_dir}: the rig has no shape named 'nose' (--partners-of)."
    bad = run_cli("pairs", ict_dir, "--top", "0", check=False)
    assert bad.returncode == 2 and "--top" in bad.stderr
    bad = run_cli("pairs", tmp_path / "missing", check=False)
    assert bad.returncode == 2 and "missing" in bad.stderr and "Traceback" not in bad.stderr


def test_ranked_rows_of_the_model():
    scores = np.array([[1.0, 0.9, 0.1, 0.2], [0.9, 1.0, 0.2, 0.1], [0.1, 0.2, 1.0, 0.8], [0.2, 0.1, 0.8, 1.0]])
    names = ["a_L", "a_R", "b_L", "b_R"]
    assert ranked_pairs(scores, names, 10) == [PairRow(0, 1, 0.9), PairRow(2, 3, 0.8),
                                               PairRow(0, 3, 0.2, (1, 2, 0.2)), PairRow(0, 2, 0.1, (1, 3, 0.1))]
    assert ranked_pairs(scores, names, 2, partner_of="b_R") == [PairRow(3, 2, 0.8), PairRow(3, 0, 0.2)]


def test_pairs_name_the_correctives_a_project_has(tmp_path):
    sample = tmp_path / "rig"
    run_cli("sample", "-o", sample)
    run_cli("export", sample, "--weights", "browInnerUp_L=1,browInnerUp_R=1", "-o", tmp_path / "scan.obj")
    project = tmp_path / "fixed.bsproj"
    run_cli("corrective", sample, "--drivers", "browInnerUp_L,browInnerUp_R", "--target", tmp_path / "scan.obj",
            "-o", project)
    rows = json.loads(run_cli("pairs", project, "--partners-of", "browInnerUp_L", "--json").stdout)["pairs"]
    by_partner = {r["shapes"][1]: r["correctives"] for r in rows}
    assert by_partner["browInnerUp_R"] == ["browInnerUp_L+browInnerUp_R"] and by_partner["browOuterUp_L"] == []
    text = run_cli("pairs", project, "--partners-of", "browInnerUp_L").stdout
    assert "(corrective: browInnerUp_L+browInnerUp_R)" in text


def test_pairs_piped_into_a_reader_that_stops_early(ict_dir):
    """`blendshape-studio pairs RIG | head -3`: no traceback when the reader closes the pipe."""
    proc = subprocess.Popen(command() + ["pairs", str(ict_dir), "--top", "500", "--json"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "{"
    proc.stdout.close()
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0 and "Traceback" not in err and "BrokenPipe" not in err
