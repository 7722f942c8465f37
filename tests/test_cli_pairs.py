"""`pairs`: the interference finder from the command line, ranked as in the Correctives panel."""
from __future__ import annotations

import json
import subprocess

import numpy as np

from model.interference import PairRow, ranked_pairs
from tests.cli_runner import command, run_cli


def _vertex_areas(rig) -> np.ndarray:
    """A third of the area of every triangle at each of its corners, polygons fanned from their first vertex."""
    X, areas, start = rig.neutral.astype(np.float64), np.zeros(rig.n_vertices), 0
    tris = []
    for n in rig.face_counts:
        f = rig.face_indices[start:start + n]
        tris += [(f[0], f[k], f[k + 1]) for k in range(1, n - 1)]
        start += n
    T = np.array(tris)
    third = np.linalg.norm(np.cross(X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]]), axis=1) / 6
    for c in range(3):
        np.add.at(areas, T[:, c], third)
    return areas


def _overshoot_scores(rig, areas) -> np.ndarray:
    """The finder's overshoot measure for every pair, straight from its definition (README, ALGORITHMS §6):
    Σ w e / (Σ w + 10) over the vertices both shapes move (more than 1e-3 of their peak), e the sum's excess
    over the larger displacement relative to it, w the smaller relative displacement times the vertex area
    relative to the median area of the moving vertices."""
    D = rig.deltas.astype(np.float64)
    n = np.linalg.norm(D, axis=2)
    rel = n / n.max(axis=1, keepdims=True)
    acts = rel > 1e-3
    moving = acts.any(axis=0) & (areas > 0)
    a = areas / np.median(areas[moving])
    K = len(D)
    S = np.eye(K)
    for i in range(K):
        for j in range(i + 1, K):
            both = acts[i] & acts[j]
            m = np.maximum(n[i, both], n[j, both])
            e = (np.linalg.norm(D[i, both] + D[j, both], axis=1) - m) / m
            w = np.minimum(rel[i, both], rel[j, both]) * a[both]
            S[i, j] = S[j, i] = (w * e).sum() / (w.sum() + 10.0)
    return S


def _mirror(name: str) -> str:
    return name[:-2] + {"_L": "_R", "_R": "_L"}[name[-2:]] if name[-2:] in ("_L", "_R") else name


def test_pairs_on_ict_rank_smiths_brow_pair_and_say_where(ict_dir, ict_rig):
    out = json.loads(run_cli("pairs", ict_dir, "--top", "12", "--json").stdout)
    assert out["measure"] == "overshoot" and out["units"] == "cm" and len(out["pairs"]) == 12
    rows = {frozenset(r["shapes"]): r for r in out["pairs"]}
    brows = rows[frozenset(("browInnerUp_L", "browInnerUp_R"))]
    assert brows["rank"] <= 10 and brows["mirror"] is None
    lids = out["pairs"][0]
    assert lids["shapes"] == ["eyeLookUp_L", "eyeWide_L"] and lids["mirror"] == ["eyeLookUp_R", "eyeWide_R"]
    # the numbers, computed here from their definitions: score, and the peak and area of the overshoot heat
    names = ict_rig.shape_names
    areas = _vertex_areas(ict_rig)
    S = _overshoot_scores(ict_rig, areas)
    i, j = names.index("browInnerUp_L"), names.index("browInnerUp_R")
    assert abs(brows["score"] - S[i, j]) < 1e-5
    di, dj = ict_rig.deltas[i].astype(np.float64), ict_rig.deltas[j].astype(np.float64)
    heat = np.maximum(np.linalg.norm(di + dj, axis=1)
                      - np.maximum(np.linalg.norm(di, axis=1), np.linalg.norm(dj, axis=1)), 0.0)
    assert abs(brows["peak"] - heat.max()) < 2e-6
    assert abs(brows["area"] - areas[heat > 0.1 * heat.max()].sum()) < 1e-4
    assert 0.2 < brows["peak"] < 0.3 and 40 < brows["area"] < 70      # cm, cm²: the brow midline
    # the ranking: a pair and its mirror image are one row, scored by the better side, best first
    best = {}
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            pair = frozenset((names[a], names[b]))
            row = frozenset((pair, frozenset(map(_mirror, pair))))
            best[row] = max(best.get(row, -np.inf), S[a, b])
    ranked = sorted(best, key=best.get, reverse=True)
    assert best[ranked[11]] - best[ranked[12]] > 1e-4             # no near-tie at the cut
    got = [frozenset((frozenset(r["shapes"]), frozenset(r["mirror"] or r["shapes"]))) for r in out["pairs"]]
    assert set(got) == set(ranked[:12])
    scores = [r["score"] for r in out["pairs"]]
    assert scores == sorted(scores, reverse=True)
    np.testing.assert_allclose(scores, [best[g] for g in got], atol=1e-5)


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
