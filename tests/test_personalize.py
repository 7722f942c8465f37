"""Personalisation (Ma et al. 2016 §3; ALGORITHMS.md §9; issue 15 item 5): an actor's own rig from scans.

Synthetic tests have an independent reference (the deltas and weights that generated the scans, or the
geometry of a scaled and rotated face); the data test checks the issue's figure on ``mocap/actor_take``.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from model.errors import RigInputError
from model.obj_io import write_obj
from model.personalize import personalize_rig, personalize_rig_detailed, shape_change_report
from model.rig import Rig
from solvers.personalize import gradient_operator, personalize, shape_change
from tests.cli_runner import run_cli


# --- a small curved patch with four local shapes -------------------------------------------------------------
def _patch(n: int = 16):
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing="ij")
    X = np.stack([u.ravel(), v.ravel(), 0.2 * (u.ravel() ** 2 + 0.5 * v.ravel() ** 2)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    deltas = []
    for cx, cy, direction in [(-0.4, -0.4, (0, 0, 0.3)), (0.4, -0.3, (0.2, 0, 0.1)), (0.0, 0.45, (0, -0.25, 0)),
                              (0.3, 0.3, (0.1, 0.1, -0.2))]:
        r = np.hypot(X[:, 0] - cx, X[:, 1] - cy)
        bump = np.where(r < 0.6, np.cos(np.pi * np.minimum(r / 0.6, 1)) * 0.5 + 0.5, 0.0) ** 2
        deltas.append(bump[:, None] * np.asarray(direction, float))
    return X, tris, np.array(deltas)


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_gradient_operator_reproduces_the_tangent_projector_and_linear_fields():
    X, tris, _ = _patch(8)
    G, area = gradient_operator(X, tris)
    J = (G @ X).reshape(-1, 3, 3) / np.sqrt(area)[:, None, None]
    e1, e2 = X[tris[:, 1]] - X[tris[:, 0]], X[tris[:, 2]] - X[tris[:, 0]]
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n, axis=1)[:, None]
    assert np.allclose(J, np.eye(3) - n[:, :, None] * n[:, None, :], atol=1e-12)   # ∇ of the identity map
    # the gradient of f(x) = a·x is a projected onto each triangle's plane; a constant has none
    a = np.array([0.3, -1.2, 0.7])
    g = (G @ (X @ a)).reshape(-1, 3) / np.sqrt(area)[:, None]
    assert np.allclose(g, a - (n @ a)[:, None] * n, atol=1e-12)
    assert np.abs(G @ np.ones(len(X))).max() < 1e-12


def test_known_weights_recover_the_deltas_that_made_the_scans():
    X, tris, Dt = _patch()
    rng = np.random.default_rng(1)
    actor = X + 0.05 * np.stack([np.sin(2 * X[:, 1]), np.cos(1.5 * X[:, 0]), X[:, 0] * X[:, 1]], axis=1)
    field = 1 + 0.3 * np.sin(3 * X[:, 0] + 1)[None, :, None] * np.array([1, -1, 0.5, 2])[:, None, None]
    D_true = Dt * field                                  # zero where the template is zero
    W = rng.uniform(0.1, 0.9, (9, 4))
    scans = actor + np.einsum("nk,kvc->nvc", W, D_true)
    res = personalize(X, Dt, tris, scans, actor, weights=W, lam_r=1e-9, lam_d=1e-9, tol=1e-12, maxiter=2000)
    assert np.abs(res.deltas - D_true).max() < 1e-6 * np.abs(D_true).max()
    assert res.unknowns == 3 * int((np.abs(Dt).max(axis=2) > 0).sum())
    assert res.fit_rms[-1] < 1e-7


def test_a_template_actor_keeps_its_shapes_and_gets_its_weights_and_head_motion_back():
    X, tris, Dt = _patch()
    rng = np.random.default_rng(2)
    W = rng.uniform(0.05, 0.95, (6, 4))
    R = np.stack([_rotation(rng.normal(size=3), 0.1 * (i + 1)) for i in range(6)])
    t = rng.normal(size=(6, 3)) * 0.2
    poses = X + np.einsum("nk,kvc->nvc", W, Dt)
    scans = np.einsum("nvc,ndc->nvd", poses, R) + t[:, None]
    res = personalize(X, Dt, tris, scans, X, lam_sparsity=0.0, tol=1e-12, maxiter=2000)
    assert np.abs(res.deltas - Dt).max() < 1e-6
    assert np.abs(res.weights - W).max() < 1e-5
    assert np.abs(res.rotations - R).max() < 1e-6 and np.abs(res.translations - t).max() < 1e-6


def test_deformation_transfer_scales_and_turns_the_shapes_with_the_face():
    """No scans: the shapes of a face twice rotated and 1.25 times larger are the template's, rotated and
    1.25 times larger (Sumner & Popović 2004); plain closeness to the template (λ_d alone) would not move them."""
    X, tris, Dt = _patch()
    R = _rotation([0.2, 1.0, 0.3], 0.4)
    actor = 1.25 * X @ R.T + np.array([1.0, -2.0, 0.5])
    res = personalize(X, Dt, tris, np.zeros((0,) + X.shape), actor, lam_d=1e-7, tol=1e-12, maxiter=3000)
    expected = 1.25 * Dt @ R.T
    assert np.abs(res.deltas - expected).max() < 2e-3 * np.abs(expected).max()
    only_close = personalize(X, Dt, tris, np.zeros((0,) + X.shape), actor, lam_r=0.0, lam_d=1.0)
    assert np.abs(only_close.deltas - Dt).max() < 1e-9


def test_unknown_weights_personalise_an_actor_whose_shapes_differ():
    """Weights re-estimated by alternation: the personalised rig reproduces new poses of the actor much better
    than the template does (the scale of each shape against its weight is Ma's gauge, so poses are compared)."""
    X, tris, Dt = _patch()
    rng = np.random.default_rng(3)
    actor = X + 0.04 * np.stack([np.sin(2 * X[:, 1]), np.cos(1.5 * X[:, 0]), X[:, 0] * X[:, 1]], axis=1)
    field = 1 + 0.4 * np.cos(3 * X[:, 1] + np.arange(4)[:, None])[:, :, None]
    D_true = Dt * field
    W = rng.uniform(0.0, 0.8, (12, 4))
    scans = actor + np.einsum("nk,kvc->nvc", W, D_true)
    res = personalize(X, Dt, tris, scans, actor, iterations=6, lam_sparsity=0.0)
    W_new = rng.uniform(0.0, 0.8, (5, 4))
    new = actor + np.einsum("nk,kvc->nvc", W_new, D_true)

    def refit_error(D):
        from solvers.personalize import solve_pose_weights
        Wf, _, _ = solve_pose_weights(actor, D, new, rigid=False, lam_sparsity=0.0)
        return np.sqrt(((actor + np.einsum("nk,kvc->nvc", Wf, D) - new) ** 2).sum(axis=2).mean())

    assert refit_error(res.deltas) < 0.5 * refit_error(Dt)
    assert res.fit_rms[-1] < 0.5 * res.fit_rms[0]


def test_shape_change_measures_each_shape():
    Dt = np.zeros((2, 4, 3))
    Dt[0, :2, 0] = 1.0
    Dt[1, 2:, 2] = 2.0
    D = Dt.copy()
    D[0, 1, 0] = 1.3                   # one vertex of shape 0 moves 0.3 further
    D[1, 3, 1] = 0.4                   # shape 1 gains a sideways 0.4 at one vertex
    ch = shape_change(Dt, D)
    assert np.allclose(ch.per_vertex, [[0, 0.3, 0, 0], [0, 0, 0, 0.4]])
    assert np.allclose(ch.rms, [np.sqrt(0.09 / 2), np.sqrt(0.16 / 2)]) and np.allclose(ch.max, [0.3, 0.4])
    assert np.allclose(ch.relative, [np.sqrt(0.09 / 2) / 1.0, np.sqrt(0.16 / 2) / 2.0])


# --- the model function: rig in, rig out ----------------------------------------------------------------------
def _scans_of(rig: Rig, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    W = np.where(rng.random((n, rig.n_shapes)) < 0.3, rng.uniform(0.2, 1.0, (n, rig.n_shapes)), 0.0)
    return W, rig.neutral + np.einsum("nk,kvc->nvc", W, rig.deltas)


def test_personalize_rig_keeps_names_presets_and_correctives(sample_rig):
    from model.correctives import Corrective
    rig = sample_rig.copy()
    rig.presets = {"smirk": {rig.shape_names[0]: 0.5}}
    drivers = rig.shape_names[:2]
    bump = 0.3 * (rig.deltas[0] + rig.deltas[1])
    rig.correctives = [Corrective(drivers=drivers, delta=bump, rule="product", muted=True)]
    _, scans = _scans_of(rig, 8)
    bigger = rig.neutral * 1.1
    actor, result, summary = personalize_rig_detailed(rig, bigger, list(scans * 1.1))
    assert actor.shape_names == rig.shape_names and actor.presets == rig.presets and actor.units == rig.units
    assert np.array_equal(actor.face_indices, rig.face_indices) and np.allclose(actor.neutral, bigger)
    (c,) = actor.correctives
    assert c.drivers == drivers and c.muted and c.rule == "product"
    # the corrective is carried onto the bigger face, in the same place: grown toward 1.1 times the template's
    # by the transferred gradients, held near it by the closeness term (λ_d), never beyond the face's growth
    moved = np.abs(bump).max(axis=1) > 0
    assert np.array_equal(np.abs(c.delta).max(axis=1) > 0, moved)
    ratio = np.linalg.norm(c.delta[moved]) / np.linalg.norm(bump[moved])
    assert 1.01 < ratio < 1.1
    assert summary["unknowns"] == result.unknowns > 0 and len(summary["fit_rms"]) == 4


def test_personalize_rig_keeps_the_shape_lists_settings_and_moves_its_inbetweens(sample_rig):
    from model.rig import Inbetween
    rig = sample_rig.copy()
    k = rig.shape_index("jawOpen")
    half = 0.6 * rig.deltas[k]
    rig.inbetweens = {"jawOpen": [Inbetween(0.5, half)]}
    rig.muted, rig.ranges = ["eyeBlink_L"], {"jawOpen": (0.0, 1.4)}
    from model.correctives import Corrective
    rig.correctives = [Corrective(drivers=["jawOpen", "mouthClose"], delta=half)]   # the same offset, as a fix
    rig.validate()
    _, scans = _scans_of(rig, 8)
    actor, _, _ = personalize_rig_detailed(rig, rig.neutral * 1.1, list(scans * 1.1))
    assert actor.muted == ["eyeBlink_L"] and actor.ranges == {"jawOpen": (0.0, 1.4)}
    (ib,) = actor.inbetweens["jawOpen"]
    assert ib.weight == 0.5
    # carried onto the actor's face exactly as a corrective with the same offset is
    np.testing.assert_allclose(ib.delta, actor.correctives[0].delta, atol=1e-9)
    assert np.abs(ib.delta - half).max() > 1e-3


def test_bad_input_is_one_sentence(sample_rig, tmp_path):
    rig = sample_rig
    with pytest.raises(RigInputError, match="none was given"):
        personalize_rig(rig)
    short = tmp_path / "short.obj"
    write_obj(short, rig.neutral[:-5], np.array([3]), np.array([0, 1, 2]))
    with pytest.raises(RigInputError, match=rf"short\.obj: has {rig.n_vertices - 5} vertices but the rig has "
                                            rf"{rig.n_vertices}"):
        personalize_rig(rig, rig.neutral, [short])
    nan = rig.neutral.copy()
    nan[7, 1] = np.nan
    bad = tmp_path / "nan.obj"
    bad.write_text("".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in nan))
    with pytest.raises(RigInputError, match=r"nan\.obj: vertex 7 has a NaN or infinite coordinate"):
        personalize_rig(rig, rig.neutral, [rig.neutral, bad])
    with pytest.raises(RigInputError, match="the neutral scan: vertex 7 has NaN"):
        personalize_rig(rig, nan)


def test_cli_writes_the_actor_project_and_reports_changes(sample_rig, tmp_path):
    from model.project import load_project
    from model.readers import load_rig
    from resources.sample_rig import write_sample
    folder = write_sample(tmp_path / "sample")
    rig = load_rig(folder)
    _, scans = _scans_of(rig, 6, seed=4)
    scans = scans + 0.02 * np.sin(rig.neutral[:, :1] * 3)                 # an actor a little off the template
    (tmp_path / "scans").mkdir()
    for i, s in enumerate(scans):
        write_obj(tmp_path / "scans" / f"s{i}.obj", s, rig.face_counts, rig.face_indices)
    write_obj(tmp_path / "neutral.obj", rig.neutral, rig.face_counts, rig.face_indices)
    out = tmp_path / "actor.bsproj"
    proc = run_cli("personalize", folder, "--neutral-scan", tmp_path / "neutral.obj", "--scans", tmp_path / "scans",
                   "--report", tmp_path / "r.json", "-o", out)
    assert f"wrote {out}" in proc.stdout and "unknowns" in proc.stdout
    actor = load_project(out).rig
    assert actor.shape_names == rig.shape_names and actor.n_vertices == rig.n_vertices
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["scans"] == 6 and report["neutral"] == "scan" and len(report["shapes"]) == rig.n_shapes
    assert report["fit_rms"][-1] < report["fit_rms"][0]
    # bad input: exit 2 and one sentence naming the file
    write_obj(tmp_path / "scans" / "broken.obj", rig.neutral[:10], np.array([3]), np.array([0, 1, 2]))
    proc = run_cli("personalize", folder, "--scans", tmp_path / "scans", "-o", tmp_path / "x.bsproj", check=False)
    assert proc.returncode == 2 and "broken.obj: has 10 vertices" in proc.stderr
    assert proc.stderr.count("\n") == 1 and not (tmp_path / "x.bsproj").exists()
    proc = run_cli("personalize", folder, "-o", tmp_path / "x.bsproj", check=False)
    assert proc.returncode == 2 and "none was given" in proc.stderr


def test_a_scan_folders_obj_that_is_not_a_file_is_named(tmp_path):
    """A folder named like a scan in --scans' folder was passed over (one scan fewer, without a word)."""
    from model.personalize import scan_paths
    (tmp_path / "scans").mkdir()
    (tmp_path / "scans" / "s0.obj").write_text("v 0 0 0\n")
    (tmp_path / "scans" / "s1.obj").mkdir()
    with pytest.raises(RigInputError, match=r"^.*s1\.obj: is a folder, not a file\.$"):
        scan_paths([tmp_path / "scans"])


def test_a_scan_or_target_that_is_not_an_obj_is_named_as_what_it_is(tmp_path):
    """A glTF given to ``personalize --neutral-scan``/``--scans`` (or ``corrective --target``) read as "has no vertex
    ('v') records" (a .gltf) or "is a binary file, not a text OBJ" (a .glb, even one the rig's own export wrote):
    one sentence saying it is a glTF, not an OBJ mesh, exit 2, nothing written."""
    from tests.conftest import DATA, require_data
    from tests.rig_files import write_rig_folder
    folder = tmp_path / "rig"
    write_rig_folder(folder)
    glb = tmp_path / "rig.glb"
    run_cli("export", folder, "-o", glb)
    gltf = require_data(DATA / "thirdparty" / "gltf" / "SimpleMorph.gltf")
    disguised = tmp_path / "scan.obj"                     # a GLB renamed: its bytes say what it is
    disguised.write_bytes(glb.read_bytes())
    out = tmp_path / "actor.bsproj"
    advice = "file, not an OBJ mesh; save it as OBJ with the rig's vertices in the rig's order."
    for args, path, kind in [
            (("personalize", folder, "--neutral-scan", gltf), gltf, "a glTF"),
            (("personalize", folder, "--scans", glb), glb, "a binary glTF (GLB)"),
            (("personalize", folder, "--scans", disguised), disguised, "a binary glTF (GLB)"),
            (("corrective", folder, "--drivers", "raise,push", "--target", glb), glb, "a binary glTF (GLB)")]:
        proc = run_cli(*args, "-o", out, check=False)
        assert (proc.returncode, proc.stderr) == (2, f"error: {path}: is {kind} {advice}\n") and not out.exists()


def test_personalize_says_what_the_takes_reader_decided(tmp_path):
    """`personalize --take` on a take cut short read it to its last whole frame and said nothing (`solve` prints the
    reader's warnings): it prints them too, one `warning:` line each."""
    from resources.sample_rig import write_sample
    from tests.conftest import DATA, require_data
    folder = write_sample(tmp_path / "sample")
    data = require_data(DATA / "mocap" / "actor_take" / "take.c3d").read_bytes()
    take = tmp_path / "cut.c3d"
    take.write_bytes(data[:int(len(data) * 0.6)])
    proc = run_cli("personalize", folder, "--take", take, "-o", tmp_path / "actor.bsproj")
    assert proc.stderr == (f"warning: {take}: the file ends early: 358 frames declared but 214 whole frames present; "
                           "read to the last whole frame.\n")


# --- the actor of mocap/actor_take ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def actor_dir():
    from tests.conftest import DATA, require_data
    return require_data(DATA / "mocap" / "actor_take")


@pytest.fixture(scope="module")
def actor_rig(ict_rig, actor_dir):
    scans = sorted((actor_dir / "scans").glob("*.obj"))
    assert len(scans) == 24
    return personalize_rig_detailed(ict_rig, actor_dir / "actor_neutral.obj", scans)


def test_actor_take_on_the_personalised_rig_is_within_target(actor_rig, ict_rig, actor_dir):
    from tests.actor_take_measure import dense_error_solved, dense_error_true_weights
    rig, result, summary = actor_rig
    solved, posed = dense_error_solved(rig, actor_dir), dense_error_true_weights(rig, actor_dir)
    print(f"\nactor_take solved on the personalised rig: {10 * solved:.3f} mm; posed with the true weights: "
          f"{10 * posed:.3f} mm; {summary['unknowns']} unknowns, "
          f"{summary['seconds']:.1f} s, scan fit {summary['fit_rms']}")
    # Issue 15 asks for 0.21 mm; measured 0.190 mm (0.191 with the head pose read over the whole surface; λ_s 0.01 and
    # Ma's λ_d 0.05: 0.212 mm; the ICT shapes on the actor's neutral scan: 0.243 mm; the actor's own linear shapes
    # posed with the true weights: 0.17 mm)
    assert solved < 0.021                                     # cm
    # and the weights keep their meaning: posed with the performance's true weights the rig is 0.263 mm from the
    # actor (the ICT shapes on the scan: 0.267 mm; with λ_s 0.01 the scans' weights shrank, the shapes grew: 0.84)
    assert posed < 0.03
    _, rows = shape_change_report(ict_rig, rig)
    assert rows[0]["rms"] > 0.005 and rows[0]["max"] > rows[0]["rms"]   # the shapes did change


def test_pose_scans_without_a_neutral_scan_find_the_actors_neutral(ict_rig, actor_dir):
    """Only the 24 pose scans: the neutral is re-estimated, from a first guess made from the scans themselves
    (``solvers.personalize._neutral_from_poses``). Started from ICT's neutral, the actor's identity went into the
    shapes: the neutral ended 4.4 mm RMS from the actor's neutral scan over the moving face (placed by one rigid
    transform) and the take solved on the result had weights 0.086 RMS off the truth, worse than ICT's own 0.057.
    Measured now: 2.0 mm and 0.056 (2.3 mm with the head's pose read over the whole surface)."""
    from model.obj_io import read_obj
    from solvers.rigid import kabsch
    from tests.actor_take_measure import truth, weights_error_solved
    rig, _, summary = personalize_rig_detailed(ict_rig, None, sorted((actor_dir / "scans").glob("*.obj")))
    assert summary["neutral"] == "re-estimated from the pose scans"
    actor = read_obj(actor_dir / "actor_neutral.obj").vertices
    moving = truth(actor_dir)[2]
    R, t = kabsch(rig.neutral[moving], actor[moving])
    neutral = float(np.sqrt(((rig.neutral[moving] @ R.T + t - actor[moving]) ** 2).sum(axis=1).mean()))
    weights, template = weights_error_solved(rig, actor_dir), weights_error_solved(ict_rig, actor_dir)
    print(f"\npose scans alone: the neutral {10 * neutral:.2f} mm from the actor's scan; the take's weights "
          f"{weights:.4f} RMS off the truth (ICT's own {template:.4f}); {summary['seconds']:.1f} s")
    assert neutral < 0.22                                     # cm
    assert weights < 0.06 and weights < template + 0.003


def test_a_marker_take_alone_personalises_the_face_the_markers_cover(ict_rig, actor_dir):
    """No scans: the template warped onto the actor's neutral markers (placed rigidly on the rig's marker points,
    at the actor's size; bent onto them by the thin-plate surface warp) with its shapes transferred, then the take
    solved on it. Markers cannot say where the actor's face sits in the truth's frame, so the result is measured
    placed there by one rigid transform (``dense_error_solved(placed=True)``).

    Issue 15 asks for 1.0 mm over every moving vertex; measured 2.52 mm (the Gaussian RBF warp before: 3.2 mm).
    Within 2 cm of a marker (5,374 of the 9,005 moving vertices) it is 0.66 mm. What 60 markers cannot measure is
    the identity far from them: 2,221 moving vertices lie over 6 cm from any marker (the sides of the head, under
    the jaw) and carry three quarters of the error; ``test_what_sixty_markers_can_say_of_the_actors_neutral``
    measures the bound."""
    from model.marker_map import load_marker_map
    from model.takes import load_take
    from tests.actor_take_measure import dense_error_solved
    take = load_take(actor_dir / "take.c3d")
    rig, _, summary = personalize_rig_detailed(ict_rig, take=take, marker_map=load_marker_map(actor_dir /
                                                                                               "marker_map.json"))
    assert summary["neutral"] == "warped to the take's neutral markers" and summary["markers"] == 60
    everywhere, covered = dense_error_solved(rig, actor_dir, within=2.0, placed=True)
    print(f"\nactor_take solved on the rig personalised from the take alone: {10 * covered:.3f} mm within 2 cm of a "
          f"marker, {10 * everywhere:.3f} mm over every moving vertex")
    assert covered < 0.08                                     # cm
    assert everywhere < 0.27


def test_what_sixty_markers_can_say_of_the_actors_neutral(ict_rig, actor_dir):
    """The ceiling of any marker-only personalisation on actor_take, measured on the truth: the actor's TRUE neutral
    at the 60 marker vertices (no noise, no calibration) warped onto the template after the similarity, against the
    actor's neutral over the moving vertices (placed by one rigid transform, as above). The surface warp: 2.51 mm;
    the best fit of the whole true neutral by the similarity plus an affine map and all 57 of ICT's shapes (an
    oracle that sees every vertex) still leaves 1.94 mm. Below 1.0 mm needs a prior on faces (an identity model
    such as ICT FaceKit's identity modes, which the shared data does not hold)."""
    from model.marker_map import load_marker_map
    from model.obj_io import read_obj
    from solvers.rigid import kabsch, umeyama
    from solvers.surface_warp import biharmonic_warp
    from model.personalize import WARP_LENGTH
    actor = read_obj(actor_dir / "actor_neutral.obj").vertices
    moving = np.load(actor_dir / "truth_dense_face.npz")["moving"]
    B = load_marker_map(actor_dir / "marker_map.json").binding(ict_rig)
    s, R, t = umeyama(B @ ict_rig.neutral, B @ actor, scale=True)
    base = s * ict_rig.neutral @ R.T + t

    def placed_rms(Y):
        Rp, tp = kabsch(Y[moving], actor[moving])
        return 10 * float(np.sqrt((((Y[moving] @ Rp.T + tp) - actor[moving]) ** 2).sum(axis=1).mean()))
    warped = base + biharmonic_warp(base, ict_rig.triangles(), B, B @ actor - B @ base, length=s * WARP_LENGTH)
    oracle = np.column_stack([ict_rig.deltas[:, moving].reshape(ict_rig.n_shapes, -1).T] +
                             [np.kron(np.column_stack([base[moving], np.ones(len(moving))]), np.eye(3))])
    rest = (actor[moving] - base[moving]).ravel()
    fitted = base.copy()
    fitted[moving] += (oracle @ np.linalg.lstsq(oracle, rest, rcond=None)[0]).reshape(-1, 3)
    print(f"\nmarker-only ceiling: similarity {placed_rms(base):.2f} mm, surface warp of the true marker points "
          f"{placed_rms(warped):.2f} mm, oracle fit of every vertex by affine + 57 shapes {placed_rms(fitted):.2f} mm")
    assert 2.3 < placed_rms(warped) < 2.7 and placed_rms(warped) < placed_rms(base) - 1.0
    assert 1.0 < placed_rms(fitted) < 2.2


@pytest.mark.parametrize("count", ["0", "100000"])
def test_personalize_refuses_calibration_frames_the_take_cannot_give(ict_dir, take_dir, tmp_path, count):
    """0 frames (before: "markers M00, M01, ... are missing in every calibration frame", all 60 named) or more than
    the take has (before: the whole take's mean taken as the actor's neutral): one sentence naming the take."""
    proc = run_cli("personalize", ict_dir, "--take", take_dir / "take.c3d", "--map", take_dir / "marker_map.json",
                   "--calibration-frames", count, "-o", tmp_path / "actor.bsproj", check=False)
    assert proc.returncode == 2 and proc.stderr == (
        f"error: {take_dir / 'take.c3d'}: has 358 frames; --calibration-frames {count} must be 1 to 358 (the "
        "actor's neutral frames at its start).\n"), proc.stderr
    assert not (tmp_path / "actor.bsproj").exists()


def test_a_takes_chosen_neutral_frames_are_the_actors_neutral(ict_rig, ict_dir, actor_dir, tmp_path):
    """``neutral_frames`` (the solve's ``--neutral-frames A:B``; the Mocap panel's Use This Frame as Neutral) is the
    frames the actor's neutral markers are read from: personalising read only the first calibration frames. The
    command line's ``--neutral-frames 120:120`` writes the neutral the model gives for frame 120, not the one of the
    first 30 frames."""
    from model.marker_map import load_marker_map
    from model.personalize import _marker_neutral
    from model.project import load_project
    from model.takes import load_take
    take, mm = load_take(actor_dir / "take.c3d"), load_marker_map(actor_dir / "marker_map.json")
    at_120, info = _marker_neutral(ict_rig, take, mm, neutral_frames=(120, 120))
    assert info["neutral_frames"] == [120, 120]
    assert np.array_equal(_marker_neutral(ict_rig, take, mm, neutral_frames="120:120")[0], at_120)
    at_start, info = _marker_neutral(ict_rig, take, mm, 30)
    assert info["neutral_frames"] == [0, 29] and np.abs(at_120 - at_start).max() > 0.05
    out = tmp_path / "actor.bsproj"
    proc = run_cli("personalize", ict_dir, "--take", actor_dir / "take.c3d", "--map", actor_dir / "marker_map.json",
                   "--neutral-frames", "120:120", "-o", out)
    assert "neutral: warped to the take's neutral markers of frames 120:120" in proc.stdout
    assert np.abs(load_project(out).rig.neutral - at_120).max() < 1e-5


@pytest.mark.parametrize("value, message", [
    ("1-5", "--neutral-frames: '1-5' is not a frame range A:B or 'auto'."),
    ("9:3", "--neutral-frames: the neutral range 9:3 ends before it starts."),
    ("auto", "--neutral-frames: personalize takes the actor's neutral as a frame range A:B, not 'auto'."),
    ("350:400", "{take}: the neutral frames 350:400 (--neutral-frames) are outside the take, which has frames 0 to "
                "357."),
    ("-1:2", "{take}: the neutral frames -1:2 (--neutral-frames) are outside the take, which has frames 0 to 357."),
])
def test_personalize_refuses_neutral_frames_the_take_cannot_give(ict_dir, take_dir, tmp_path, value, message):
    """``personalize --neutral-frames`` is checked as ``solve``'s is: one sentence, exit code 2, nothing written."""
    proc = run_cli("personalize", ict_dir, "--take", take_dir / "take.c3d", "--map", take_dir / "marker_map.json",
                   f"--neutral-frames={value}", "-o", tmp_path / "actor.bsproj", check=False)
    assert proc.returncode == 2 and proc.stderr == f"error: {message.format(take=take_dir / 'take.c3d')}\n", \
        proc.stderr
    assert not (tmp_path / "actor.bsproj").exists()


def test_personalize_neutral_frames_need_a_take(ict_dir, tmp_path):
    proc = run_cli("personalize", ict_dir, "--neutral-frames", "3:5", "-o", tmp_path / "actor.bsproj", check=False)
    assert proc.returncode == 2 and proc.stderr == (
        "error: --neutral-frames: the actor's neutral frames are a marker take's; give --take too.\n"), proc.stderr
