"""The shape list's model (issue 18): in-betweens blended piecewise linearly as Maya's, mute, solo and slider
ranges in the one pose evaluator; reorder, rename, duplicate and delete keeping every reference consistent and
undoing bit for bit; groups of ICT/ARKit names; the project keeps it all and refuses damaged entries."""
from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import scipy.sparse as sp

from model import shape_edits as se
from model.correctives import Corrective, set_correctives
from model.errors import RigInputError
from model.export import export_content
from model.pose import PoseEvaluator
from model.project import Project, load_project, save_project
from model.rig import Inbetween
from model.shape_weights import shape_offset


def _w(rig, **named):
    w = np.zeros(rig.n_shapes)
    for n, v in named.items():
        w[rig.shape_index(n)] = v
    return w


@pytest.fixture()
def rig(sample_rig):
    return sample_rig.copy()


def _bent(d):
    """An in-between target that is not on the straight line: the half shape plus a sideways bulge."""
    return 0.5 * d + 0.2 * np.roll(d, 1, axis=1)


def test_an_inbetween_at_half_is_blended_piecewise_linearly(rig):
    k = rig.shape_index("jawOpen")
    d = rig.deltas[k]
    D = _bent(d)
    rig.inbetweens = {"jawOpen": [Inbetween(0.5, D)]}
    rig.validate()
    ev64, ev32 = PoseEvaluator(rig, dtype=np.float64), PoseEvaluator(rig)
    for w, expected in ((0.25, 0.5 * D), (0.5, D), (0.75, 0.5 * D + 0.5 * d), (1.0, d),
                        (1.25, d + 0.5 * (d - D)), (-0.5, -D)):
        x = ev64.evaluate(_w(rig, jawOpen=w))
        np.testing.assert_allclose(x, rig.neutral + expected, atol=1e-12, err_msg=f"weight {w}")
        np.testing.assert_allclose(ev32.evaluate(_w(rig, jawOpen=w)), x, atol=2e-5)
    # the straight line would be 0.25 d at 0.25: the in-between really bends the path
    assert np.abs(0.5 * D - 0.25 * d).max() > 0.05
    # a batch of poses (PC2 caches, take exports) is the same product
    W = np.stack([_w(rig, jawOpen=w, mouthSmile_L=0.3) for w in (0.25, 0.5, 0.75)])
    np.testing.assert_allclose(ev64.evaluate_many(W, dtype=np.float64), np.stack([ev64.evaluate(w) for w in W]),
                               atol=1e-12)
    np.testing.assert_allclose(shape_offset(rig, "jawOpen", 0.75), 0.5 * D + 0.5 * d, atol=1e-12)


def test_two_inbetweens_make_three_segments(rig):
    k = rig.shape_index("eyeBlink_L")
    d = rig.deltas[k]
    A, B = 0.1 * d + 0.05 * np.roll(d, 1, 1), 0.9 * d - 0.05 * np.roll(d, 2, 1)
    rig.inbetweens = {"eyeBlink_L": [Inbetween(0.7, B), Inbetween(0.3, A)]}
    rig.validate()
    assert [i.weight for i in rig.inbetweens["eyeBlink_L"]] == [0.3, 0.7]
    ev = PoseEvaluator(rig, dtype=np.float64)
    for w, expected in ((0.15, 0.5 * A), (0.5, 0.5 * A + 0.5 * B), (0.85, 0.5 * B + 0.5 * d)):
        np.testing.assert_allclose(ev.evaluate(_w(rig, eyeBlink_L=w)), rig.neutral + expected, atol=1e-12)


def test_a_regional_pose_blends_each_regions_inbetween_pose(rig):
    k = rig.shape_index("jawOpen")
    D = _bent(rig.deltas[k])
    rig.inbetweens = {"jawOpen": [Inbetween(0.5, D)]}
    rig.validate()
    V = rig.n_vertices
    phi = np.linspace(0, 1, V)
    blend = sp.csr_matrix(np.column_stack([phi, 1 - phi]))
    W = np.zeros((2, rig.n_shapes))
    W[0, k], W[1, k] = 0.25, 0.75
    ev = PoseEvaluator(rig, dtype=np.float64)
    expected = rig.neutral + phi[:, None] * (0.5 * D) + (1 - phi)[:, None] * (0.5 * D + 0.5 * rig.deltas[k])
    np.testing.assert_allclose(ev.evaluate_regional(W, blend), expected, atol=1e-12)


def test_mute_removes_a_shape_and_its_correctives_solo_keeps_only_the_soloed(rig):
    a, b = "eyeBlink_L", "eyeBlink_R"
    fix = 0.3 * np.roll(rig.deltas[rig.shape_index(a)], 1, axis=1)
    set_correctives(rig, [Corrective(drivers=[a, b], delta=fix)])
    w = _w(rig, eyeBlink_L=0.8, eyeBlink_R=0.6, jawOpen=0.5)
    plain = PoseEvaluator(rig, dtype=np.float64)
    full = plain.evaluate(w)
    rig.muted = [a]
    rig.validate()
    muted = PoseEvaluator(rig, dtype=np.float64).evaluate(w)
    w_off = w.copy()
    w_off[rig.shape_index(a)] = 0
    np.testing.assert_array_equal(muted, plain.evaluate(w_off))          # no eyeBlink_L, no fix
    assert np.abs(full - muted).max() > 0.1
    rig.muted, rig.solo = [], [b, "jawOpen"]
    rig.validate()
    np.testing.assert_array_equal(PoseEvaluator(rig, dtype=np.float64).evaluate(w), plain.evaluate(w_off))
    rig.muted = ["jawOpen"]     # mute wins over solo
    rig.validate()
    only_b = _w(rig, eyeBlink_R=0.6)
    np.testing.assert_array_equal(PoseEvaluator(rig, dtype=np.float64).evaluate(w), plain.evaluate(only_b))


def test_a_range_allows_overdrive_and_negative_weights_and_clamps_beyond(rig):
    k = rig.shape_index("jawOpen")
    d = rig.deltas[k]
    rig.ranges = {"jawOpen": (-0.5, 1.5)}
    rig.validate()
    ev = PoseEvaluator(rig, dtype=np.float64)
    for w, used in ((1.3, 1.3), (-0.4, -0.4), (3.0, 1.5), (-2.0, -0.5)):
        np.testing.assert_allclose(ev.evaluate(_w(rig, jawOpen=w)), rig.neutral + used * d, atol=1e-12)
    # without a range a weight is not clamped (presets may overdrive)
    np.testing.assert_allclose(ev.evaluate(_w(rig, mouthClose=1.4)),
                               rig.neutral + 1.4 * rig.deltas[rig.shape_index("mouthClose")], atol=1e-12)


def _project(rig):
    set_correctives(rig, [Corrective(drivers=["jawOpen", "mouthFunnel"],
                                     delta=0.2 * np.roll(rig.deltas[rig.shape_index("jawOpen")], 1, 1)),
                          Corrective(drivers=["eyeBlink_L", "eyeBlink_R"], delta=0.1 * rig.deltas[0])])
    rig.presets = {"open": {"jawOpen": 1.0, "mouthFunnel": 0.5}}
    rig.inbetweens = {"jawOpen": [Inbetween(0.5, _bent(rig.deltas[rig.shape_index("jawOpen")]))]}
    rig.ranges = {"mouthFunnel": (0.0, 1.2)}
    rig.muted = ["eyeWide_L"]
    rig.validate()
    rng = np.random.default_rng(3)
    w = rng.uniform(0, 1, rig.n_shapes)
    phi = rng.uniform(0, 1, (rig.n_vertices, 3))
    blend = sp.csr_matrix(phi / phi.sum(axis=1, keepdims=True))
    p = Project(rig=rig, weights=w, region_weights=rng.uniform(0, 1, (3, rig.n_shapes)), region_blend=blend,
                region_level=0)
    p.arrays["keyframes/weights"] = rng.uniform(0, 1, (4, 3, rig.n_shapes))
    return p


def test_reorder_keeps_every_reference_and_the_surface_and_undoes_exactly(rig):
    p = _project(rig)
    names, D, w = list(rig.shape_names), rig.deltas.copy(), p.weights.copy()
    R, keys = p.region_weights.copy(), p.arrays["keyframes/weights"].copy()
    before = PoseEvaluator(rig, dtype=np.float64).evaluate(w)
    order = se.sorted_order(names, "name")
    inverse = se.reorder_shapes(p, order)
    assert rig.shape_names == sorted(names, key=str.lower)
    k = rig.shape_index("jawOpen")
    assert np.array_equal(rig.deltas[k], D[names.index("jawOpen")])
    assert p.weights[k] == w[names.index("jawOpen")]
    assert np.array_equal(p.arrays["keyframes/weights"][..., k], keys[..., names.index("jawOpen")])
    assert np.array_equal(p.region_weights[:, k], R[:, names.index("jawOpen")])
    np.testing.assert_allclose(PoseEvaluator(rig, dtype=np.float64).evaluate(p.weights), before, atol=1e-12)
    se.reorder_shapes(p, inverse)
    assert rig.shape_names == names and np.array_equal(rig.deltas, D) and np.array_equal(p.weights, w)
    assert np.array_equal(p.region_weights, R) and np.array_equal(p.arrays["keyframes/weights"], keys)


def test_a_reorder_that_would_change_a_hierarchical_three_way_corrective_is_refused(rig):
    drivers = ["eyeBlink_L", "eyeWide_L", "browDown_L"]
    set_correctives(rig, [Corrective(drivers=drivers, delta=0.1 * rig.deltas[0], rule="hierarchical")])
    order = list(range(rig.n_shapes))
    a, b = rig.shape_index("eyeWide_L"), rig.shape_index("browDown_L")
    order[a], order[b] = order[b], order[a]     # the middle driver moves to the end
    with pytest.raises(RigInputError, match="hierarchical"):
        se.reorder_shapes(Project(rig=rig), order)
    order = list(range(rig.n_shapes))
    order[0], order[1] = order[1], order[0]     # not touching the drivers' order: fine
    se.reorder_shapes(Project(rig=rig), order)


def test_rename_follows_into_correctives_presets_and_settings_and_undoes(rig):
    p = _project(rig)
    rec = se.rename_shape(p, "jawOpen", "jawDrop")
    assert "jawDrop" in rig.shape_names and "jawOpen" not in rig.shape_names
    assert rig.correctives[0].drivers == ["jawDrop", "mouthFunnel"] and rig.correctives[0].name == "jawDrop+mouthFunnel"
    assert rig.presets["open"] == {"jawDrop": 1.0, "mouthFunnel": 0.5}
    assert list(rig.inbetweens) == ["jawDrop"]
    rig.validate()
    with pytest.raises(RigInputError, match="already has a shape"):
        se.rename_shape(p, "jawDrop", "mouthFunnel")
    with pytest.raises(RigInputError, match="corrective"):
        se.rename_shape(p, "jawDrop", "eyeBlink_L+eyeBlink_R")
    se.undo_rename(p, rec)
    assert rig.shape_names[rig.shape_index("jawOpen")] == "jawOpen"
    assert rig.correctives[0].name == "jawOpen+mouthFunnel" and rig.presets["open"]["jawOpen"] == 1.0


def test_delete_takes_its_correctives_and_restore_is_bit_exact(rig):
    p = _project(rig)
    snapshot = (list(rig.shape_names), rig.deltas.copy(), p.weights.copy(), p.region_weights.copy(),
                p.arrays["keyframes/weights"].copy(), [(c.name, c.delta.copy(), c.drivers[:]) for c in rig.correctives],
                json.dumps(rig.presets), dict(rig.ranges), list(rig.muted))
    surface = PoseEvaluator(rig, dtype=np.float64).evaluate(p.weights)
    assert se.correctives_needing(rig, ["mouthFunnel", "eyeWide_L"]) == ["jawOpen+mouthFunnel"]
    rec = se.delete_shapes(p, ["mouthFunnel", "eyeWide_L"])
    assert rig.n_shapes == 32 and [c.name for c in rig.correctives] == ["eyeBlink_L+eyeBlink_R"]
    assert rig.presets["open"] == {"jawOpen": 1.0} and rig.ranges == {} and rig.muted == []
    assert p.weights.shape == (32,) and p.region_weights.shape == (3, 32)
    assert p.arrays["keyframes/weights"].shape == (4, 3, 32)
    rig.validate()
    se.restore_shapes(p, rec)
    after = (list(rig.shape_names), rig.deltas, p.weights, p.region_weights, p.arrays["keyframes/weights"],
             [(c.name, c.delta, c.drivers) for c in rig.correctives], json.dumps(rig.presets), dict(rig.ranges),
             list(rig.muted))
    assert after[0] == snapshot[0]
    for x, y in zip(after[1:5], snapshot[1:5]):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert [(n, dr) for n, _, dr in after[5]] == [(n, dr) for n, _, dr in snapshot[5]]
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(after[5], snapshot[5]))
    assert after[6:] == snapshot[6:]
    assert np.array_equal(PoseEvaluator(rig, dtype=np.float64).evaluate(p.weights), surface)


def test_duplicate_copies_the_shape_and_its_inbetweens_after_it(rig):
    p = _project(rig)
    k = rig.shape_index("jawOpen")
    new = se.duplicate_shape(p, "jawOpen")
    assert new == "jawOpen_copy" and rig.shape_names[k + 1] == new
    assert np.array_equal(rig.deltas[k + 1], rig.deltas[k]) and p.weights[k + 1] == 0
    assert rig.inbetweens[new][0].weight == 0.5 and rig.inbetweens[new][0].delta is not rig.inbetweens["jawOpen"][0].delta
    assert p.arrays["keyframes/weights"].shape[-1] == rig.n_shapes
    assert se.unique_name(rig, "jawOpen") == "jawOpen_copy2"
    rig.validate()


def test_groups_of_ict_names(ict_rig):
    groups = dict(se.shape_groups(ict_rig.shape_names, "prefix"))
    assert {"brow", "eye", "mouth", "cheek", "nose", "jaw"} <= set(groups)
    names = ict_rig.shape_names
    assert {names[i] for i in groups["jaw"]} == {"jawForward", "jawLeft", "jawOpen", "jawRight"}
    assert all(names[i].startswith("brow") for i in groups["brow"])
    sides = dict(se.shape_groups(names, "side"))
    assert list(sides) == ["Left", "Right", "Centre"]
    assert "eyeBlink_L" in {names[i] for i in sides["Left"]} and "jawOpen" in {names[i] for i in sides["Centre"]}
    assert se.shape_prefix("browInnerUp_L") == "brow" and se.shape_prefix("PupilDilate_R") == "pupil"
    order = se.sorted_order(names, "group")
    assert [se.shape_prefix(names[i]) for i in order] == sorted(se.shape_prefix(n) for n in names)
    assert se.moved_order(4, [1, 2], -1) == [1, 2, 0, 3] and se.moved_order(4, [0], -1) == [0, 1, 2, 3]
    assert se.moved_to_order(5, [3], 1) == [0, 3, 1, 2, 4] and se.moved_to_order(5, [0, 1], 5) == [2, 3, 4, 0, 1]


def test_the_project_keeps_the_shape_settings(rig, tmp_path):
    p = _project(rig)
    save_project(p, tmp_path / "p.bsproj")
    q = load_project(tmp_path / "p.bsproj").rig
    assert q.muted == ["eyeWide_L"] and q.ranges == {"mouthFunnel": (0.0, 1.2)}
    assert np.array_equal(q.inbetweens["jawOpen"][0].delta, rig.inbetweens["jawOpen"][0].delta)
    w = p.weights
    assert np.array_equal(PoseEvaluator(q, dtype=np.float64).evaluate(w), PoseEvaluator(rig, dtype=np.float64).evaluate(w))
    # a project without settings writes no "shapes" member (older readers see nothing new)
    save_project(Project(rig=rig.__class__(neutral=rig.neutral, face_counts=rig.face_counts,
                                           face_indices=rig.face_indices, shape_names=rig.shape_names,
                                           deltas=rig.deltas)), tmp_path / "plain.bsproj")
    with zipfile.ZipFile(tmp_path / "plain.bsproj") as z:
        assert "shapes" not in json.loads(z.read("manifest.json"))["rig"]


def _edit_manifest(src, out, edit):
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(out, "w") as b:
        for n in a.namelist():
            data = a.read(n)
            if n == "manifest.json":
                m = json.loads(data)
                edit(m["rig"]["shapes"])
                data = json.dumps(m).encode()
            b.writestr(n, data)
    return out


@pytest.mark.parametrize("edit, words", [
    (lambda s: s["inbetweens"]["jawOpen"][0].update(weight=1.0), "other than 0 and 1"),
    (lambda s: s["inbetweens"]["jawOpen"][0].update(weight="half"), "other than 0 and 1"),
    (lambda s: s["inbetweens"]["jawOpen"][0].update(array="rig/deltas"), "stored arrays"),
    (lambda s: s["inbetweens"].update(noSuchShape=s["inbetweens"]["jawOpen"]), "does not have"),
    (lambda s: s.update(ranges={"mouthFunnel": [2, 1]}), "min < max"),
    (lambda s: s.update(ranges={"mouthFunnel": "wide"}), "pair"),
    (lambda s: s.update(muted="eyeWide_L"), "list of shape names"),
    (lambda s: s.update(solo=["ghost"]), "does not have"),
    (lambda s: s.update(inbetweens=[1, 2]), "objects"),
])
def test_damaged_shape_settings_are_one_sentence(rig, tmp_path, edit, words):
    save_project(_project(rig), tmp_path / "p.bsproj")
    bad = _edit_manifest(tmp_path / "p.bsproj", tmp_path / "bad.bsproj", edit)
    with pytest.raises(RigInputError) as err:
        load_project(bad)
    msg = str(err.value)
    assert msg.startswith(str(bad)) and "\n" not in msg and words in msg, msg


def test_gltf_content_bakes_inbetweens_as_morph_targets_with_piecewise_weights(rig):
    p = _project(rig)
    w = p.weights
    content = export_content(rig, w, units=rig.units)
    assert "jawOpen@0.5" in content.names
    assert len(content.names) == rig.n_shapes + 1 + len(rig.correctives)
    surface = content.neutral + np.einsum("k,kvc->vc", content.pose, content.deltas)
    np.testing.assert_allclose(surface, PoseEvaluator(rig, dtype=np.float64).evaluate(w), atol=1e-10)


def test_a_take_solve_leaves_a_muted_shape_at_zero(rig):
    from model.marker_map import MarkerMap
    from model.take_workspace import solve_take
    from model.takes import MarkerTake
    ev = PoseEvaluator(rig, dtype=np.float64)
    frames = np.stack([_w(rig, jawOpen=x, mouthSmile_L=0.5) for x in (0.2, 0.6, 0.9)])
    truth = np.stack([ev.evaluate(w) for w in frames])
    vertices = np.flatnonzero(np.abs(rig.deltas).max(axis=(0, 2)) > 0)[::40]
    labels = [f"M{i:03d}" for i in range(vertices.size)]
    mm = MarkerMap(markers=dict(zip(labels, vertices.tolist())), rig_units="cm")
    take = MarkerTake(positions=truth[:, vertices], labels=labels, rate=30.0, units="cm")
    options = dict(calibration_frames=0, head_motion=False, residual="none", two_pass=False)
    k = rig.shape_index("jawOpen")
    free = solve_take(rig, take, mm, **options).weights
    assert free[:, k].min() > 0.15 and np.corrcoef(free[:, k], frames[:, k])[0, 1] > 0.99   # it is used
    rig.muted = ["jawOpen"]
    rig.validate()
    sol = solve_take(rig, take, mm, **options)
    assert np.abs(sol.weights[:, k]).max() < 1e-6
    assert sol.weights.shape[1] == rig.n_shapes       # the CSV keeps its column


def test_a_glb_export_plays_the_inbetween_pose(rig, tmp_path):
    """A glTF viewer blends morph targets linearly: the in-between is a target of its own and the file's default
    weights give the evaluator's surface (to float32), not the straight-line pose."""
    import struct
    from model.export import export_rig
    from model.readers import load_rig
    k = rig.shape_index("jawOpen")
    d = rig.deltas[k]
    rig.inbetweens = {"jawOpen": [Inbetween(0.5, _bent(d))]}
    rig.validate()
    w = _w(rig, jawOpen=0.25)
    export_rig(rig, tmp_path / "ib.glb", w)            # metres
    back = load_rig(tmp_path / "ib.glb")
    assert back.shape_names[rig.n_shapes:] == ["jawOpen@0.5"]
    data = (tmp_path / "ib.glb").read_bytes()
    n = struct.unpack("<I", data[12:16])[0]
    weights = np.array(json.loads(data[20:20 + n])["meshes"][0]["weights"])
    assert weights[k] == 0 and weights[-1] == 0.5
    played = 100.0 * (back.neutral + np.einsum("k,kvc->vc", weights, back.deltas))
    expected = PoseEvaluator(rig, dtype=np.float64).evaluate(w)
    assert np.abs(played - expected).max() < 1e-5
    assert np.abs(expected - (rig.neutral + 0.25 * d)).max() > 0.05


def test_a_mute_or_range_edit_reuses_the_evaluators_matrices_and_an_inbetween_does_not(rig):
    ev = PoseEvaluator(rig, dtype=np.float64)
    w = _w(rig, jawOpen=0.7, mouthSmile_L=0.4)
    se.with_mute(rig, "mouthSmile_L", True).apply(rig)
    se.with_range(rig, "jawOpen", 0.0, 0.5).apply(rig)
    again = ev.with_settings(rig)
    assert again._D is ev._D                                   # no copy of the deltas
    assert np.array_equal(again.evaluate(w), PoseEvaluator(rig, dtype=np.float64).evaluate(w))
    assert np.allclose(again.evaluate(w), rig.neutral + 0.5 * rig.deltas[rig.shape_index("jawOpen")], atol=1e-12)
    se.with_inbetween(rig, "jawOpen", 0.5, _bent(rig.deltas[rig.shape_index("jawOpen")])).apply(rig)
    rebuilt = again.with_settings(rig)
    assert rebuilt._D is not ev._D and rebuilt._D.shape[0] == rig.n_shapes + 1
    assert np.array_equal(rebuilt.evaluate(w), PoseEvaluator(rig, dtype=np.float64).evaluate(w))


def _rig_with_inbetween_and_corrective(rig):
    n = rig.shape_names
    rig.inbetweens = {n[2]: [Inbetween(0.5, _bent(rig.deltas[2]))]}
    rig.correctives = [Corrective(drivers=[n[0], n[1]], delta=0.5 * (rig.deltas[0] - rig.deltas[1]))]
    rig.validate()
    return rig


def _check_against_fresh(ev, rig, rng):
    """``ev`` poses ``rig`` exactly as an evaluator made from scratch (global and regional, with the in-between
    and the corrective acting)."""
    fresh = PoseEvaluator(rig, dtype=np.float64)
    for _ in range(3):
        w = rng.uniform(0, 1, rig.n_shapes)
        np.testing.assert_allclose(ev.evaluate(w), fresh.evaluate(w), rtol=0, atol=1e-12)
    W = rng.uniform(0, 1, (4, rig.n_shapes))
    np.testing.assert_allclose(ev.evaluate_many(W, dtype=np.float64), fresh.evaluate_many(W, dtype=np.float64),
                               rtol=0, atol=1e-12)
    blend = sp.csr_matrix(np.column_stack([np.linspace(0, 1, rig.n_vertices), np.linspace(1, 0, rig.n_vertices)]))
    R = rng.uniform(0, 1, (2, rig.n_shapes))
    np.testing.assert_allclose(ev.evaluate_regional(R, blend), fresh.evaluate_regional(R, blend), rtol=0, atol=1e-12)


def test_a_rename_shares_the_evaluators_matrices_and_a_shape_list_edit_copies_its_rows(rig):
    """After an edit, the document's evaluators are made from the old ones (``PoseEvaluator.with_settings``): a
    rename replaces no array, so the matrices are shared (1-2 s of rebuilding on a 106k-vertex, 228-shape rig
    before); a reorder, delete, restore, duplicate or one shape's new deltas copy the old rows named by
    ``shape_rows``, in-betweens and correctives by their arrays. Every result poses exactly as a fresh evaluator;
    rows the edit did not name are read from the rig, and a wrong row map is refused."""
    rng = np.random.default_rng(5)
    rig = _rig_with_inbetween_and_corrective(rig)
    project = Project(rig=rig)
    ev = PoseEvaluator(rig, dtype=np.float64)
    names = list(rig.shape_names)

    def rows_by_name(before):
        return [before.index(n) if n in before else -1 for n in rig.shape_names]

    rec = se.rename_shape(project, names[0], "renamed")
    renamed = ev.with_settings(rig, rows_by_name(names))
    assert renamed.shares_matrices(ev)
    _check_against_fresh(renamed, rig, rng)        # the corrective's driver follows the new name
    se.undo_rename(project, rec)
    (ib,) = rig.inbetweens[names[2]]               # an in-between moved along its shape: the same row, a new weight
    rig.inbetweens = {names[2]: [Inbetween(0.3, ib.delta)]}
    moved_inbetween = ev.with_settings(rig)
    assert moved_inbetween.shares_matrices(ev)
    _check_against_fresh(moved_inbetween, rig, rng)
    rig.inbetweens = {names[2]: [ib]}

    order = list(rng.permutation(rig.n_shapes))
    se.reorder_shapes(project, order)
    moved = ev.with_settings(rig, order)
    assert not moved.shares_matrices(ev) and moved.moving_vertices is ev.moving_vertices    # copied, not gathered
    _check_against_fresh(moved, rig, rng)

    before = list(rig.shape_names)
    removed = se.delete_shapes(project, [names[0], names[3]])      # the corrective needs names[0]: it goes too
    fewer = moved.with_settings(rig, rows_by_name(before))
    _check_against_fresh(fewer, rig, rng)
    assert len(rig.correctives) == 0 and fewer._D.shape[0] == rig.n_shapes + 1

    after_delete = list(rig.shape_names)
    se.restore_shapes(project, removed)                # their deltas come back: rows read from the rig
    back = fewer.with_settings(rig, rows_by_name(after_delete))
    _check_against_fresh(back, rig, rng)

    # a corrective edit (the commands copy the list, arrays too): the shapes' rows kept, the corrective's read
    c = rig.correctives[0].copy()
    c.delta = 2.0 * c.delta
    rig.correctives = [c]
    fixed = back.with_settings(rig, range(rig.n_shapes))
    assert not fixed.shares_matrices(back)
    _check_against_fresh(fixed, rig, rng)
    back = fixed

    k = 4
    rig.deltas = rig.deltas.copy()
    rig.deltas[k] = 0.5 * rig.deltas[k]
    rows = np.arange(rig.n_shapes)
    rows[k] = -1
    halved = back.with_settings(rig, rows)
    _check_against_fresh(halved, rig, rng)
    with pytest.raises(AssertionError):                # the nearest wrong answer: the old row kept for shape k
        _check_against_fresh(back.with_settings(rig, np.arange(rig.n_shapes)), rig, rng)

    # new deltas that move a vertex no shape moved: made from scratch, its moving vertices grow
    still = np.setdiff1d(np.arange(rig.n_vertices), halved.moving_vertices)
    assert still.size
    rig.deltas = rig.deltas.copy()
    rig.deltas[k, still[0]] = 0.1
    grown = halved.with_settings(rig, rows)
    assert still[0] in grown.moving_vertices
    _check_against_fresh(grown, rig, rng)
    rig.deltas = rig.deltas.copy()
    with pytest.raises(ValueError, match="shape_rows"):           # a map of another length: refused, not guessed
        grown.with_settings(rig, rows[:-1])


def test_a_usd_export_keys_the_inbetween_as_a_blend_shape_of_its_own(rig, tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdSkel
    from model.export import export_rig
    k = rig.shape_index("jawOpen")
    rig.inbetweens = {"jawOpen": [Inbetween(0.5, _bent(rig.deltas[k]))]}
    rig.muted = ["mouthClose"]
    rig.validate()
    w = _w(rig, jawOpen=0.75, mouthClose=1.0)
    export_rig(rig, tmp_path / "ib.usda", w)
    stage = Usd.Stage.Open(str(tmp_path / "ib.usda"))
    anim = next(UsdSkel.Animation(p) for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    names = list(anim.GetBlendShapesAttr().Get())
    weights = dict(zip(names, anim.GetBlendShapeWeightsAttr().Get()))
    assert weights["jawOpen"] == pytest.approx(0.5) and weights["jawOpen_0_5"] == pytest.approx(0.5)
    assert weights["mouthClose"] == 0.0            # muted


def test_the_projects_antagonist_pairs_follow_a_rename_and_a_delete_and_come_back_on_undo(rig):
    """Edited pairs name shapes: a rename renames them (the pair is still held apart), a delete drops the pairs
    of the deleted shape, and undoing either gives the list back exactly."""
    p = _project(rig)
    p.antagonists = [("jawOpen", "mouthClose"), ("eyeBlink_L", "eyeWide_L"), ("mouthFunnel", "mouthPucker")]
    before = list(p.antagonists)
    rec = se.rename_shape(p, "jawOpen", "jawDrop")
    assert p.antagonists[0] == ("jawDrop", "mouthClose") and p.antagonists[1:] == before[1:]
    assert p.antagonist_pairs()[0] == ("jawDrop", "mouthClose")
    se.undo_rename(p, rec)
    assert p.antagonists == before
    removed = se.delete_shapes(p, ["eyeWide_L"])
    assert p.antagonists == [before[0], before[2]]
    se.restore_shapes(p, removed)
    assert p.antagonists == before


def _settings(rig) -> tuple:
    """The rig's name-keyed settings and names, by value (in-betweens as weight and delta bytes)."""
    return (json.dumps(rig.presets, sort_keys=True), dict(rig.ranges), list(rig.muted), list(rig.solo),
            list(rig.shape_names), {n: [(i.weight, i.delta.tobytes()) for i in v] for n, v in rig.inbetweens.items()})


@pytest.mark.parametrize("edit", ["reorder", "delete", "restore", "duplicate"])
def test_a_detached_edit_leaves_the_project_as_it_was_until_adopted_then_matches_the_edit_in_place(rig, edit):
    """``model.project.DetachedEdit`` (the window runs the shape list's copying edits on another thread): the list
    edits replace what they change, so the project in use is untouched while the copy is edited -- every
    attribute, array and setting the very same object; adopted, the project is what the edit in place makes, bit
    for bit, on the same Rig object; and an attribute the edit did not change but the window did meanwhile (the
    pose a playback set during a deltas-only edit) is not put back."""
    from model.project import DetachedEdit
    p, twin = _project(rig), _project(rig.copy())
    if edit == "restore":
        rec, twin_rec = (se.delete_shapes(q, ["mouthFunnel", "eyeWide_L"]) for q in (p, twin))
    run = {"reorder": lambda q, r: se.reorder_shapes(q, se.sorted_order(q.rig.shape_names, "name")),
           "delete": lambda q, r: se.delete_shapes(q, ["mouthFunnel", "eyeWide_L"]),
           "restore": lambda q, r: se.restore_shapes(q, r),
           "duplicate": lambda q, r: se.duplicate_shape(q, "jawOpen")}[edit]
    seen = ({k: v for k, v in vars(p).items() if k != "arrays"}, dict(vars(p.rig)), dict(p.arrays),
            _settings(rig))
    job, rig_object = DetachedEdit(p), p.rig
    run(job.project, rec if edit == "restore" else None)
    assert all(getattr(p, k) is v for k, v in seen[0].items())
    assert all(getattr(p.rig, k) is v for k, v in seen[1].items())
    assert all(p.arrays[k] is v for k, v in seen[2].items()) and p.arrays.keys() == seen[2].keys()
    assert _settings(rig) == seen[3]
    assert job.project.rig.shape_names != rig.shape_names     # the copy was edited
    run(twin, twin_rec if edit == "restore" else None)        # the same edit in place, on a twin project
    job.adopt(p)
    assert p.rig is rig_object and p.rig.shape_names == twin.rig.shape_names
    for a, b in [(p.rig.deltas, twin.rig.deltas), (p.weights, twin.weights), (p.region_weights, twin.region_weights),
                 (p.arrays["keyframes/weights"], twin.arrays["keyframes/weights"])]:
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert [c.name for c in p.rig.correctives] == [c.name for c in twin.rig.correctives]
    assert _settings(p.rig) == _settings(twin.rig)
    # new deltas for one shape, while the pose changes in the project in use: the pose stays the new one
    job = DetachedEdit(p)
    deltas = p.rig.deltas.copy()
    deltas[0] *= 2.0
    job.project.rig.deltas = deltas
    p.weights = np.full(p.rig.n_shapes, 0.25)
    job.adopt(p)
    assert p.rig.deltas is deltas and np.all(p.weights == 0.25)


def test_a_snapshot_shares_the_arrays_and_keeps_what_the_rig_was_through_every_shape_edit(rig):
    """``Rig.snapshot`` (an export's, a batch's, a personalisation's copy of the open rig): its arrays are the rig's
    own (no copy of the deltas), its lists, dicts and correctives its own, and the application's edits after it --
    which replace arrays, never write into them -- leave it as the rig was."""
    rig = _rig_with_inbetween_and_corrective(rig)
    snap = rig.snapshot()
    assert snap.deltas is rig.deltas and snap.neutral is rig.neutral and snap.face_indices is rig.face_indices
    assert snap.correctives[0].delta is rig.correctives[0].delta and snap.correctives[0] is not rig.correctives[0]
    k, inbetween = next((s, ib[0]) for s, ib in snap.inbetweens.items())
    assert inbetween.delta is rig.inbetweens[k][0].delta and snap.inbetweens is not rig.inbetweens
    before = {"names": list(rig.shape_names), "deltas": rig.deltas.copy(), "presets": json.dumps(rig.presets)}
    from model.project import Project
    project = Project(rig=rig)
    se.rename_shape(project, rig.shape_names[0], "renamed")
    se.reorder_shapes(project, list(range(rig.n_shapes))[::-1])
    rig.presets["new"] = {"jawOpen": 1.0}
    assert snap.shape_names == before["names"] and json.dumps(snap.presets) == before["presets"]
    np.testing.assert_array_equal(snap.deltas, before["deltas"])
    snap.shape_names[0] = "changed in the snapshot"
    snap.correctives[0].name = "changed in the snapshot"
    assert rig.shape_names[-1] != "changed in the snapshot" and rig.correctives[0].name != "changed in the snapshot"
