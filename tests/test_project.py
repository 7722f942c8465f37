"""The .bsproj project: exact round trip, atomic save, damaged files named clearly."""
from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import scipy.sparse as sp

from model.errors import RigInputError
from model.project import Project, load_project, save_project
from model.readers import load_rig
from tests.rig_files import write_rig_folder


@pytest.fixture
def small_project(tmp_path):
    write_rig_folder(tmp_path / "rig")
    rig = load_rig(tmp_path / "rig")
    rig.presets = {"half": {"raise": 0.5}}
    return Project(rig=rig, weights=np.array([0.25, 0.75]), sections={"segmentation": {"t": 0.6}},
                   arrays={"keys": np.arange(6.0).reshape(2, 3)})


def test_round_trip_exact(small_project, tmp_path):
    path = tmp_path / "p.bsproj"
    save_project(small_project, path)
    back = load_project(path)
    r0, r1 = small_project.rig, back.rig
    for a in ("neutral", "face_counts", "face_indices", "deltas"):
        assert np.array_equal(getattr(r0, a), getattr(r1, a)), a
    assert r1.shape_names == r0.shape_names and r1.units == r0.units and r1.presets == r0.presets
    assert np.array_equal(back.weights, small_project.weights)
    assert back.sections == {"segmentation": {"t": 0.6}}
    assert np.array_equal(back.arrays["keys"], small_project.arrays["keys"])


def test_ict_round_trip_exact(ict_rig, tmp_path):
    path = tmp_path / "ict.bsproj"
    w = np.linspace(0, 1, ict_rig.n_shapes)
    save_project(Project(rig=ict_rig, weights=w), path)
    back = load_project(path)
    assert np.array_equal(back.rig.deltas, ict_rig.deltas) and np.array_equal(back.rig.neutral, ict_rig.neutral)
    assert np.array_equal(back.rig.face_indices, ict_rig.face_indices) and back.rig.shape_names == ict_rig.shape_names
    assert np.array_equal(back.weights, w)


def _regional(project, n_regions=3, seed=0):
    """A regional current pose: a random partition of unity over ``n_regions`` + background, random weights."""
    rng = np.random.default_rng(seed)
    V, K = project.rig.n_vertices, project.rig.n_shapes
    B = rng.random((V, n_regions + 1)) * (rng.random((V, n_regions + 1)) < 0.5)
    B[:, -1] += 1e-3
    B /= B.sum(axis=1, keepdims=True)
    project.region_blend = sp.csr_matrix(B)
    project.region_weights = rng.random((n_regions + 1, K))
    project.region_level = 2
    return project


def test_regional_pose_round_trip_exact(small_project, tmp_path):
    path = tmp_path / "p.bsproj"
    p = _regional(small_project)
    save_project(p, path)
    back = load_project(path)
    assert back.region_level == 2
    np.testing.assert_array_equal(back.region_weights, p.region_weights)
    assert back.region_blend.shape == p.region_blend.shape and (back.region_blend != p.region_blend).nnz == 0
    # a global pose stays global
    p.region_weights = p.region_blend = p.region_level = None
    save_project(p, path)
    assert load_project(path).region_weights is None


def test_damaged_regional_pose_is_named(small_project, tmp_path):
    path = tmp_path / "p.bsproj"
    save_project(_regional(small_project), path)
    good = path.read_bytes()
    import io
    buf = io.BytesIO()
    np.save(buf, np.zeros((2, small_project.rig.n_shapes)))  # 2 rows for a 4-column blend
    manifest = json.loads(zipfile.ZipFile(path).read("manifest.json"))
    manifest["arrays"]["pose/region_weights"][0] = [2, small_project.rig.n_shapes]
    _rewrite(path, replace={"pose/region_weights.npy": buf.getvalue(), "manifest.json": json.dumps(manifest).encode()})
    with pytest.raises(RigInputError, match=r"p.bsproj: the regional pose .* does not fit the rig"):
        load_project(path)
    path.write_bytes(good)
    _rewrite(path, drop="pose/blend_indptr.npy")
    with pytest.raises(RigInputError, match="p.bsproj.*missing the array 'pose/blend_indptr'"):
        load_project(path)


def test_crash_mid_save_keeps_previous_file(small_project, tmp_path, monkeypatch):
    path = tmp_path / "p.bsproj"
    save_project(small_project, path)
    before = path.read_bytes()
    import model.project as mp

    def boom(a):
        raise OSError("disk full")
    monkeypatch.setattr(mp, "_npy_bytes", boom)
    with pytest.raises(OSError):
        save_project(small_project, path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.bsproj", "rig"]  # no temporary left behind


def _rewrite(path, drop=None, replace=None):
    with zipfile.ZipFile(path) as z:
        items = {n: z.read(n) for n in z.namelist()}
    if drop:
        items.pop(drop)
    items.update(replace or {})
    with zipfile.ZipFile(path, "w") as z:
        for n, b in items.items():
            z.writestr(n, b)


def test_damaged_projects(small_project, tmp_path):
    path = tmp_path / "p.bsproj"
    save_project(small_project, path)
    good = path.read_bytes()

    path.write_bytes(good[: len(good) // 2])
    with pytest.raises(RigInputError, match="damaged zip"):
        load_project(path)

    path.write_bytes(good)
    _rewrite(path, drop="manifest.json")
    with pytest.raises(RigInputError, match="no manifest"):
        load_project(path)

    path.write_bytes(good)
    import io
    buf = io.BytesIO()
    np.save(buf, np.zeros((3, 3)))
    _rewrite(path, replace={"rig/deltas.npy": buf.getvalue()})
    with pytest.raises(RigInputError, match=r"rig/deltas.*shape"):
        load_project(path)

    path.write_bytes(good)
    _rewrite(path, replace={"manifest.json": json.dumps({"format": "something-else"}).encode()})
    with pytest.raises(RigInputError, match="not a Blendshape Studio project"):
        load_project(path)
    with pytest.raises(RigInputError) as info:
        load_project(path)
    assert str(info.value).startswith(str(path))


@pytest.mark.parametrize("array", ["rig/deltas", "rig/neutral"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_project_with_a_non_finite_value_is_refused(small_project, tmp_path, array, bad):
    """One NaN or infinity anywhere in a saved array (first, middle or last value) is named, never loaded."""
    import io
    path = tmp_path / "p.bsproj"
    save_project(small_project, path)
    good = path.read_bytes()
    with zipfile.ZipFile(path) as z:
        a = np.load(io.BytesIO(z.read(f"{array}.npy")))
    for at in (0, a.size // 2, a.size - 1):
        b = a.copy()
        b.reshape(-1)[at] = bad
        buf = io.BytesIO()
        np.save(buf, b)
        path.write_bytes(good)
        _rewrite(path, replace={f"{array}.npy": buf.getvalue()})
        with pytest.raises(RigInputError, match=f"{array}' holds NaN or infinite values") as info:
            load_project(path)
        assert str(info.value).startswith(str(path))


def test_finite_range_tells_every_non_finite_value():
    from model.rig import finite_range
    a = np.linspace(-2.0, 3.0, 30).reshape(5, 2, 3)
    assert finite_range(a) == (-2.0, 3.0)
    assert finite_range(np.zeros((0, 3))) == (0.0, 0.0)
    for bad in (np.nan, np.inf, -np.inf):
        for at in range(a.size):
            b = a.copy()
            b.reshape(-1)[at] = bad
            assert finite_range(b) is None, (bad, at)


def test_arrays_are_deflated_and_reopen_exactly(ict_rig, tmp_path):
    path = tmp_path / "ict.bsproj"
    save_project(Project(rig=ict_rig), path)
    with zipfile.ZipFile(path) as z:
        deltas = z.getinfo("rig/deltas.npy")
        assert deltas.compress_type == zipfile.ZIP_DEFLATED
        assert deltas.compress_size < deltas.file_size / 3  # 36 MB of float64 deltas, mostly zeros
    assert path.stat().st_size < 12e6
    assert np.array_equal(load_project(path).rig.deltas, ict_rig.deltas)


def test_an_uncompressed_project_still_opens(small_project, tmp_path):
    path = tmp_path / "p.bsproj"
    save_project(small_project, path)
    old = tmp_path / "stored.bsproj"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(old, "w", compression=zipfile.ZIP_STORED) as dst:
        for info in src.infolist():
            dst.writestr(info.filename, src.read(info.filename))
    assert np.array_equal(load_project(old).rig.deltas, small_project.rig.deltas)


def test_the_source_uvs_and_groups_survive_a_project(ict_rig, tmp_path):
    """A rig opened from OBJs, saved as a project and exported again still has the OBJ's UVs and materials."""
    from model.export import write_posed_obj
    from model.obj_io import read_obj
    path = tmp_path / "ict.bsproj"
    save_project(Project(rig=ict_rig), path)
    rig = load_project(path).rig
    for key in ("uvs", "corner_uv"):
        assert np.array_equal(getattr(rig.corners, key), getattr(ict_rig.corners, key)), key
    assert rig.corners.records == ict_rig.corners.records and rig.corners.normals is None
    write_posed_obj(rig, tmp_path / "out.obj")
    back = read_obj(tmp_path / "out.obj")
    assert len(back.vertices) == 26719 and np.array_equal(back.corners.corner_uv, ict_rig.corners.corner_uv)


def test_a_project_whose_every_shape_was_deleted_reopens(small_project, tmp_path):
    """Every shape deleted (the corrective driven by them goes with them), with a regional pose, presets and edited
    antagonist pairs: the project of no shapes is saved, reopens in the model with the same surface and no shapes,
    and `info` reads it (exit 0, `"shapes": []`)."""
    from model.correctives import Corrective, add_corrective
    from model.shape_edits import delete_shapes
    from tests.cli_runner import run_cli
    p = _regional(small_project)
    p.antagonists = [("raise", "push")]
    add_corrective(p.rig, Corrective(drivers=["raise", "push"], delta=np.ones((p.rig.n_vertices, 3))))
    delete_shapes(p, list(p.rig.shape_names))
    assert p.rig.n_shapes == 0 and p.rig.correctives == []
    path = tmp_path / "none.bsproj"
    save_project(p, path)
    back = load_project(path)
    assert back.rig.n_shapes == 0 and back.rig.deltas.shape == (0, p.rig.n_vertices, 3)
    assert np.array_equal(back.rig.neutral, p.rig.neutral) and back.weights.shape == (0,)
    assert back.region_weights is None or back.region_weights.shape[1] == 0
    info = json.loads(run_cli("info", path, "--json").stdout)
    assert info["shapes"] == [] and info["vertices"] == p.rig.n_vertices and info["correctives"] == []
