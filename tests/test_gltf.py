"""glTF 2.0 / GLB morph targets (model/gltf.py): round trips, buffer kinds, and broken files."""
from __future__ import annotations

import base64
import json
import struct

import numpy as np
import pytest

from model.errors import RigInputError
from model.gltf import load_gltf, write_gltf
from model.readers import load_rig
from model.rig import Rig
from tests.gltf_reference import reference_mesh


@pytest.fixture
def cube() -> Rig:
    """A unit cube (quads) with two morph targets, values exact in float32."""
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=np.float64) - 0.5
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])
    d = np.zeros((2, 8, 3))
    d[0, v[:, 2] > 0, 2] = 0.25  # push the top up
    d[1, v[:, 0] > 0, 0] = -0.125  # pinch the right side
    return Rig(neutral=v, face_counts=np.full(6, 4), face_indices=quads.reshape(-1), shape_names=["up", "pinch"],
               deltas=d, units="m", name="cube")


def assert_same(back: Rig, rig: Rig) -> None:
    assert back.shape_names == rig.shape_names
    assert np.array_equal(back.neutral, rig.neutral.astype(np.float32).astype(np.float64))
    assert np.array_equal(back.deltas, rig.deltas.astype(np.float32).astype(np.float64))
    assert np.array_equal(back.triangles(), rig.triangles())
    assert np.all(back.face_counts == 3)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_cube_round_trip(tmp_path, cube, suffix):
    path = tmp_path / f"cube{suffix}"
    write_gltf(cube, path)
    back = load_gltf(path)
    assert_same(back, cube)
    assert np.array_equal(back.neutral, cube.neutral) and np.array_equal(back.deltas, cube.deltas)
    assert back.units == "m"
    assert load_rig(path).n_vertices == 8  # the generic reader dispatches on the suffix


def test_ict_round_trip_as_glb_keeps_vertex_order(tmp_path, ict_rig):
    path = tmp_path / "ict.glb"
    write_gltf(ict_rig, path)
    back = load_rig(path, units="cm")
    assert back.units == "cm" and back.n_vertices == 26719 and back.n_shapes == 57
    assert_same(back, ict_rig)


def test_sample_rig_round_trip(tmp_path):
    from resources.sample_rig import build_sample_rig
    rig = build_sample_rig()
    for suffix in (".gltf", ".glb"):
        path = tmp_path / f"sample{suffix}"
        write_gltf(rig, path)
        assert_same(load_gltf(path, units=rig.units), rig)


def test_write_in_metres_scales_coordinates(tmp_path, cube):
    cm = Rig(neutral=cube.neutral * 100, face_counts=cube.face_counts, face_indices=cube.face_indices,
             shape_names=cube.shape_names, deltas=cube.deltas * 100, units="cm")
    write_gltf(cm, tmp_path / "m.glb", units="m")
    back = load_gltf(tmp_path / "m.glb")
    assert np.allclose(back.neutral, cube.neutral, atol=1e-7)


def _doc(tmp_path, cube):
    """The cube as a JSON document plus its raw buffer bytes."""
    write_gltf(cube, tmp_path / "c.gltf")
    doc = json.loads((tmp_path / "c.gltf").read_text())
    blob = base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1])
    return doc, blob


def _write(tmp_path, doc, name="x.gltf"):
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return p


def test_external_buffer_and_missing_names(tmp_path, cube):
    doc, blob = _doc(tmp_path, cube)
    (tmp_path / "cube data.bin").write_bytes(blob)
    doc["buffers"][0]["uri"] = "cube%20data.bin"
    del doc["meshes"][0]["extras"]
    back = load_gltf(_write(tmp_path, doc))
    assert back.shape_names == ["target_0", "target_1"]
    assert np.array_equal(back.deltas, cube.deltas)


def test_sparse_morph_target(tmp_path, cube):
    doc, blob = _doc(tmp_path, cube)
    moved = np.flatnonzero(np.abs(cube.deltas[0]).max(axis=1) > 0).astype("<u2")
    values = cube.deltas[0][moved].astype("<f4")
    extra = moved.tobytes() + b"\0" * (-moved.nbytes % 4)
    off = len(blob)
    blob = blob + extra + values.tobytes()
    doc["bufferViews"] += [{"buffer": 0, "byteOffset": off, "byteLength": moved.nbytes},
                           {"buffer": 0, "byteOffset": off + len(extra), "byteLength": values.nbytes}]
    nv = len(doc["bufferViews"])
    doc["accessors"].append({"componentType": 5126, "count": 8, "type": "VEC3", "sparse": {
        "count": int(moved.size), "indices": {"bufferView": nv - 2, "componentType": 5123},
        "values": {"bufferView": nv - 1}}})
    doc["meshes"][0]["primitives"][0]["targets"][0]["POSITION"] = len(doc["accessors"]) - 1
    doc["buffers"][0] = {"byteLength": len(blob),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}
    back = load_gltf(_write(tmp_path, doc))
    assert np.array_equal(back.deltas, cube.deltas)


def test_interleaved_positions(tmp_path, cube):
    doc, blob = _doc(tmp_path, cube)
    pos = cube.neutral.astype("<f4")
    inter = np.concatenate([pos, np.ones((8, 1), "<f4")], axis=1)  # stride 16: x y z pad
    off = len(blob)
    blob = blob + inter.tobytes()
    doc["bufferViews"].append({"buffer": 0, "byteOffset": off, "byteLength": inter.nbytes, "byteStride": 16})
    doc["accessors"][0]["bufferView"] = len(doc["bufferViews"]) - 1
    doc["buffers"][0] = {"byteLength": len(blob),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}
    assert np.array_equal(load_gltf(_write(tmp_path, doc)).neutral, cube.neutral)


def test_broken_files_raise_one_clear_sentence(tmp_path, cube):
    def fails(path, match):
        with pytest.raises(RigInputError, match=match) as e:
            load_gltf(path)
        assert str(path) in str(e.value)

    empty = tmp_path / "empty.gltf"
    empty.write_bytes(b"")
    fails(empty, "empty")
    junk = tmp_path / "junk.gltf"
    junk.write_bytes(b"\x00\x01 not json")
    fails(junk, "neither valid glTF JSON nor a GLB")
    write_gltf(cube, tmp_path / "c.glb")
    raw = (tmp_path / "c.glb").read_bytes()
    short = tmp_path / "short.glb"
    short.write_bytes(raw[: len(raw) // 2])
    fails(short, "truncated")
    v1 = tmp_path / "v1.glb"
    v1.write_bytes(raw[:4] + struct.pack("<I", 1) + raw[8:])
    fails(v1, "version")

    doc, _ = _doc(tmp_path, cube)
    d = json.loads(json.dumps(doc))
    d["buffers"][0]["uri"] = "missing.bin"
    fails(_write(tmp_path, d), "missing.bin")
    d = json.loads(json.dumps(doc))
    d["meshes"][0]["primitives"][0]["targets"] = []
    fails(_write(tmp_path, d), "no morph targets")
    d = json.loads(json.dumps(doc))
    target = d["accessors"][d["meshes"][0]["primitives"][0]["targets"][1]["POSITION"]]
    target["count"] = 4
    fails(_write(tmp_path, d), "morph target 1 has 4 vertices" if "sparse" not in target else "sparse index beyond")
    target.pop("sparse", None)                         # (the writer stores a cube's target sparse: 4 of 8 rows)
    fails(_write(tmp_path, d), "morph target 1 has 4 vertices")
    d = json.loads(json.dumps(doc))
    d["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    fails(_write(tmp_path, d), "unsupported glTF extension")
    d = json.loads(json.dumps(doc))
    d["meshes"][0]["extras"]["targetNames"] = ["a", "a"]
    fails(_write(tmp_path, d), "duplicate")
    d = json.loads(json.dumps(doc))
    prim = d["meshes"][0]["primitives"][0]
    for a in [prim["attributes"]["POSITION"]] + [t["POSITION"] for t in prim["targets"]]:
        d["accessors"][a]["count"] = 4  # fewer vertices than the indices refer to
    fails(_write(tmp_path, d), "index beyond")
    d = json.loads(json.dumps(doc))
    d["meshes"] = []
    fails(_write(tmp_path, d), "no meshes")
    with pytest.raises(RigInputError, match="does not exist"):
        load_gltf(tmp_path / "nope.glb")
    with pytest.raises(RigInputError, match=r"\.gltf or \.glb"):
        write_gltf(cube, tmp_path / "cube.obj")


def test_primitives_of_the_mesh_are_concatenated_in_order(tmp_path, cube):
    doc, _ = _doc(tmp_path, cube)
    prim = doc["meshes"][0]["primitives"][0]
    doc["meshes"][0]["primitives"] = [prim, json.loads(json.dumps(prim))]
    back = load_gltf(_write(tmp_path, doc))
    assert back.n_vertices == 16
    assert np.array_equal(back.neutral, np.concatenate([cube.neutral, cube.neutral]))
    assert np.array_equal(back.deltas, np.concatenate([cube.deltas, cube.deltas], axis=1))
    tris = cube.triangles()
    assert np.array_equal(back.triangles(), np.concatenate([tris, tris + 8]))


# --- files other tools wrote, against an independent reading (pygltflib + numpy) ------------------
THIRDPARTY = ["MorphStressTest.gltf", "SimpleMorph.gltf", "singleBlendshapeCube_sparse.glb"]
def assert_matches_reference(path, **kwargs):
    rig = load_gltf(path, **kwargs)
    ref_v, ref_t, ref_names, ref_d = reference_mesh(path)
    assert rig.shape_names == ref_names
    assert rig.n_vertices == len(ref_v)
    assert np.allclose(rig.neutral, ref_v, rtol=0, atol=1e-12 + 1e-9 * np.abs(ref_v).max())
    assert np.allclose(rig.deltas, ref_d, rtol=0, atol=1e-12 + 1e-9 * max(np.abs(ref_d).max(), 1e-30))
    assert np.array_equal(rig.triangles(), ref_t)
    return rig


@pytest.mark.parametrize("name", THIRDPARTY)
def test_thirdparty_files_read_as_pygltflib_reads_them(name):
    from tests.conftest import DATA, require_data
    rig = assert_matches_reference(require_data(DATA / "thirdparty" / "gltf" / name))
    assert rig.n_shapes >= 1 and np.abs(rig.deltas).max() > 0  # the morph targets really move something


def _gltf(tmp_path, doc, name="x.gltf"):
    return _write(tmp_path, doc, name)


def test_node_hierarchy_is_applied_to_positions_and_deltas(tmp_path, cube):
    doc, _ = _doc(tmp_path, cube)
    q = [np.sin(0.3) * v for v in (0.6, 0.0, 0.8)] + [np.cos(0.3)]  # 0.6 rad about (0.6, 0, 0.8)
    doc["nodes"] = [{"name": "root", "translation": [1.0, -2.0, 0.5], "scale": [2.0, 2.0, 2.0], "children": [1]},
                    {"name": "mid", "matrix": [1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 0.25, 0, 1], "children": [2]},
                    {"name": "face", "rotation": q, "scale": [0.5, 1.0, 1.5], "mesh": 0}]
    doc["scenes"] = [{"nodes": [0]}]
    path = _gltf(tmp_path, doc)
    rig = assert_matches_reference(path)
    # The same by hand: S, then R, then the parent's matrix (a quarter turn about x plus a shift), then root.
    from scipy.spatial.transform import Rotation
    R = Rotation.from_quat(q).as_matrix()
    local = cube.neutral * [0.5, 1.0, 1.5] @ R.T
    mid = local @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T + [0, 0.25, 0]
    assert np.allclose(rig.neutral, 2 * mid + [1.0, -2.0, 0.5], atol=1e-6)
    d_local = cube.deltas[0] * [0.5, 1.0, 1.5] @ R.T
    assert np.allclose(rig.deltas[0], 2 * d_local @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T, atol=1e-6)


def test_mirroring_node_keeps_faces_facing_out(tmp_path, cube):
    doc, _ = _doc(tmp_path, cube)
    doc["nodes"][0]["scale"] = [-1.0, 1.0, 1.0]
    rig = assert_matches_reference(_gltf(tmp_path, doc))
    tri = rig.triangles()
    n = np.cross(rig.neutral[tri[:, 1]] - rig.neutral[tri[:, 0]], rig.neutral[tri[:, 2]] - rig.neutral[tri[:, 0]])
    centre = rig.neutral[tri].mean(axis=1)
    straight = load_gltf(_gltf(tmp_path, _doc(tmp_path, cube)[0], "plain.gltf"))
    t0 = straight.triangles()
    n0 = np.cross(straight.neutral[t0[:, 1]] - straight.neutral[t0[:, 0]], straight.neutral[t0[:, 2]] - straight.neutral[t0[:, 0]])
    # the cube's own winding decides in or out; mirrored, it stays the same way round
    assert np.array_equal(np.sign((n * centre).sum(1)), np.sign((n0 * straight.neutral[t0].mean(axis=1)).sum(1)))


def test_ict_with_node_scale_and_rotation_reads_back_as_the_obj_rig_in_cm(tmp_path, ict_rig):
    from scipy.spatial.transform import Rotation
    rot = Rotation.from_euler("xyz", [-90, 20, 35], degrees=True)
    R = rot.as_matrix()
    stored = Rig(neutral=ict_rig.neutral @ R, face_counts=ict_rig.face_counts, face_indices=ict_rig.face_indices,
                 shape_names=ict_rig.shape_names, deltas=ict_rig.deltas @ R, units="cm")  # R^T p, in cm
    write_gltf(stored, tmp_path / "ict.gltf")
    doc = json.loads((tmp_path / "ict.gltf").read_text())
    doc["nodes"][0].update(rotation=rot.as_quat().tolist(), scale=[0.01, 0.01, 0.01])
    path = _write(tmp_path, doc, "ict_node.gltf")
    back = load_rig(path)
    assert back.units == "m" and back.n_vertices == ict_rig.n_vertices and back.shape_names == ict_rig.shape_names
    assert np.abs(back.neutral * 100 - ict_rig.neutral).max() < 1e-4  # float32 storage of ~20 cm coordinates
    assert np.abs(back.deltas * 100 - ict_rig.deltas).max() < 1e-5
    assert np.array_equal(back.triangles(), ict_rig.triangles())
    assert np.abs(load_gltf(tmp_path / "ict.gltf").neutral - ict_rig.neutral).max() > 1.0  # without the node: wrong


def test_quantized_positions_and_deltas(tmp_path, cube):
    """KHR_mesh_quantization as gltfpack writes it: normalised int16 positions and int8/int16 deltas, dequantised
    by the node's scale and translation."""
    centre = cube.neutral.mean(axis=0)
    scale = float(np.abs(np.concatenate([cube.neutral - centre, cube.deltas.reshape(-1, 3)])).max())
    qp = np.round((cube.neutral - centre) / scale * 32767).astype("<i2")
    qd = [np.round(cube.deltas[0] / scale * 32767).astype("<i2"), np.round(cube.deltas[1] / scale * 127).astype("<i1")]
    tris = cube.triangles().astype("<u2").reshape(-1)
    blobs = [np.concatenate([qp, np.zeros((8, 1), "<i2")], axis=1).tobytes(),  # VEC3 int16 padded to 8 bytes
             tris.tobytes() + b"\0" * (-tris.nbytes % 4),
             np.concatenate([qd[0], np.zeros((8, 1), "<i2")], axis=1).tobytes(),
             np.concatenate([qd[1], np.zeros((8, 1), "<i1")], axis=1).tobytes()]
    offs = np.cumsum([0] + [len(b) for b in blobs])
    blob = b"".join(blobs)
    doc = {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_mesh_quantization"],
           "extensionsRequired": ["KHR_mesh_quantization"],
           "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
           "bufferViews": [{"buffer": 0, "byteOffset": int(offs[0]), "byteLength": len(blobs[0]), "byteStride": 8},
                           {"buffer": 0, "byteOffset": int(offs[1]), "byteLength": tris.nbytes},
                           {"buffer": 0, "byteOffset": int(offs[2]), "byteLength": len(blobs[2]), "byteStride": 8},
                           {"buffer": 0, "byteOffset": int(offs[3]), "byteLength": len(blobs[3]), "byteStride": 4}],
           "accessors": [{"bufferView": 0, "componentType": 5122, "normalized": True, "count": 8, "type": "VEC3"},
                         {"bufferView": 1, "componentType": 5123, "count": int(tris.size), "type": "SCALAR"},
                         {"bufferView": 2, "componentType": 5122, "normalized": True, "count": 8, "type": "VEC3"},
                         {"bufferView": 3, "componentType": 5120, "normalized": True, "count": 8, "type": "VEC3"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "targets": [{"POSITION": 2}, {"POSITION": 3}]}],
                       "extras": {"targetNames": ["up", "pinch"]}}],
           "nodes": [{"mesh": 0, "translation": centre.tolist(), "scale": [scale] * 3}], "scenes": [{"nodes": [0]}], "scene": 0}
    path = _write(tmp_path, doc, "quantized.gltf")
    rig = assert_matches_reference(path)
    assert np.allclose(rig.neutral, qp / 32767 * scale + centre, atol=1e-12)
    assert np.abs(rig.neutral - cube.neutral).max() < scale / 32767  # not half size, not shifted
    assert np.abs(rig.deltas[1] - cube.deltas[1]).max() < scale / 127


def _two_meshes(tmp_path, cube):
    """An 'Eye' mesh first (one target) and the 'Head' (two targets), as avatars are laid out."""
    doc, _ = _doc(tmp_path, cube)
    prim = doc["meshes"][0]["primitives"][0]
    eye = {"name": "Eye", "primitives": [dict(prim, targets=prim["targets"][:1])], "extras": {"targetNames": ["blink"]}}
    doc["meshes"] = [eye, dict(doc["meshes"][0], name="Head")]
    doc["nodes"] = [{"mesh": 0, "translation": [5, 0, 0]}, {"mesh": 1}]
    doc["scenes"] = [{"nodes": [0, 1]}]
    return _write(tmp_path, doc, "avatar.gltf")


def test_the_mesh_with_most_targets_is_read_and_mesh_names_another(tmp_path, cube):
    path = _two_meshes(tmp_path, cube)
    head = load_gltf(path)
    assert head.name == "Head" and head.shape_names == ["up", "pinch"]
    eye = load_rig(path, mesh="Eye")
    assert eye.shape_names == ["blink"] and np.allclose(eye.neutral, cube.neutral + [5, 0, 0])
    with pytest.raises(RigInputError, match=r"no mesh named 'Nose' \(it has: Eye, Head\)"):
        load_gltf(path, mesh="Nose")


def test_cli_mesh_option(tmp_path, cube):
    from tests.cli_runner import run_cli
    path = _two_meshes(tmp_path, cube)
    info = json.loads(run_cli("info", path, "--json").stdout)
    assert info["shapes"] == ["up", "pinch"]
    assert info["meshes"] == [{"name": "Eye", "targets": 1, "vertices": 8}, {"name": "Head", "targets": 2, "vertices": 8}]
    assert "meshes (--mesh NAME): Eye (1 targets, 8 vertices), Head" in run_cli("info", path).stdout
    info = json.loads(run_cli("info", path, "--json", "--mesh", "Eye").stdout)
    assert info["shapes"] == ["blink"] and info["bounds"]["min"][0] == pytest.approx(4.5)
    bad = run_cli("info", path, "--mesh", "Nose", check=False)
    assert bad.returncode == 2 and "no mesh named 'Nose'" in bad.stderr and "Traceback" not in bad.stderr
    run_cli("export", path, "--mesh", "Eye", "-o", tmp_path / "eye.glb")
    assert load_gltf(tmp_path / "eye.glb").shape_names == ["blink"]


def test_texture_extensions_never_block_the_geometry(tmp_path, cube):
    doc, _ = _doc(tmp_path, cube)
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_texture_webp", "KHR_texture_basisu",
                                                         "KHR_materials_variants"]
    doc["images"] = [{"uri": "skin.webp"}, {"uri": "skin.ktx2"}]
    doc["textures"] = [{"extensions": {"EXT_texture_webp": {"source": 0}, "KHR_texture_basisu": {"source": 1}}}]
    back = load_gltf(_write(tmp_path, doc))
    assert np.array_equal(back.neutral, cube.neutral)


def test_meshopt_compression_is_refused_in_one_sentence(tmp_path, cube):
    doc, _ = _doc(tmp_path, cube)
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_meshopt_compression"]
    with pytest.raises(RigInputError, match=r"^[^\n]*x\.gltf: holds meshopt-compressed geometry .*re-export"):
        load_gltf(_write(tmp_path, doc))
    # only "used" (with a fallback buffer without data): refused when a compressed view is read
    doc["extensionsRequired"] = []
    doc["bufferViews"][0]["extensions"] = {"EXT_meshopt_compression": {"buffer": 0, "byteLength": 4, "count": 8,
                                                                       "byteStride": 12, "mode": "ATTRIBUTES"}}
    with pytest.raises(RigInputError, match="meshopt-compressed geometry"):
        load_gltf(_write(tmp_path, doc, "used.gltf"))


@pytest.mark.parametrize("uri", ["../outside.bin", "/etc/passwd", "sub/../../outside.bin", "file:///etc/passwd",
                                 "%2E%2E/outside.bin", "link.bin"])
def test_buffer_uris_outside_the_folder_are_refused(tmp_path, cube, uri):
    doc, blob = _doc(tmp_path, cube)
    inside = tmp_path / "model"
    inside.mkdir()
    (tmp_path / "outside.bin").write_bytes(blob)
    (inside / "link.bin").symlink_to(tmp_path / "outside.bin")
    doc["buffers"][0]["uri"] = uri
    path = _write(inside, doc)
    with pytest.raises(RigInputError, match=r"x\.gltf: buffer 0 points outside the glTF's folder"):
        load_gltf(path)
    (inside / "data").mkdir()
    (inside / "data" / "in.bin").write_bytes(blob)
    doc["buffers"][0]["uri"] = "data/in.bin"  # a subfolder is inside
    assert np.array_equal(load_gltf(_write(inside, doc)).neutral, cube.neutral)


def test_offsets_strides_and_counts_are_checked_against_the_buffers(tmp_path, cube):
    doc, blob = _doc(tmp_path, cube)
    pos = doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
    view = doc["accessors"][pos]["bufferView"]

    def fails(edit, match):
        d = json.loads(json.dumps(doc))
        edit(d)
        with pytest.raises(RigInputError, match=match) as e:
            load_gltf(_write(tmp_path, d))
        assert "Traceback" not in str(e.value) and str(tmp_path / "x.gltf") in str(e.value)

    fails(lambda d: d["bufferViews"][view].update(byteStride=8), r"byteStride 8, less than the 12-byte elements")
    fails(lambda d: d["bufferViews"][view].update(byteStride=-12), r"byteStride -12")
    fails(lambda d: d["bufferViews"][view].update(byteOffset=-4), "negative or missing byteOffset")
    fails(lambda d: d["bufferViews"][view].update(byteLength=len(blob) + 4), "past the end of its")
    fails(lambda d: d["accessors"][pos].update(count=9), "reads past the end of buffer view")
    fails(lambda d: d["accessors"][pos].update(byteOffset=-12), "negative or missing")
    fails(lambda d: d["accessors"][pos].update(count=10 ** 12), "reads past the end")
    fails(lambda d: d["buffers"][0].update(byteLength=len(blob) + 1), "truncated")
    fails(lambda d: d["accessors"][pos].update(sparse={"count": 99, "indices": {"bufferView": 0, "componentType": 5123},
                                                       "values": {"bufferView": 0}}), "sparse count 99 outside 0..8")


def _float_span(doc, accessor: int) -> tuple[int, int]:
    """(byte offset, float count) in the buffer of an accessor's float32 values (its sparse values if sparse)."""
    acc = doc["accessors"][accessor]
    if "sparse" in acc:
        view = doc["bufferViews"][acc["sparse"]["values"]["bufferView"]]
        start = view.get("byteOffset", 0) + acc["sparse"]["values"].get("byteOffset", 0)
        return start, 3 * acc["sparse"]["count"]
    view = doc["bufferViews"][acc["bufferView"]]
    return view.get("byteOffset", 0) + acc.get("byteOffset", 0), 3 * acc["count"]


@pytest.mark.parametrize("where", ["neutral", "target 0", "target 1"])
def test_nan_or_infinite_coordinates_are_refused_naming_the_file(tmp_path, cube, where):
    """A NaN or an infinity anywhere in the positions or a morph target (first, middle or last value) is refused
    in one sentence naming the file; the same file without it loads."""
    doc, blob = _doc(tmp_path, cube)
    prim = doc["meshes"][0]["primitives"][0]
    accessor = prim["attributes"]["POSITION"] if where == "neutral" else prim["targets"][int(where[-1])]["POSITION"]
    start, n = _float_span(doc, accessor)
    for i in (0, n // 2, n - 1):
        for bad in (np.nan, np.inf, -np.inf):
            b = bytearray(blob)
            b[start + 4 * i:start + 4 * i + 4] = struct.pack("<f", bad)
            d = json.loads(json.dumps(doc))
            d["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(b)).decode()
            path = _write(tmp_path, d, f"bad_{i}.gltf")
            with pytest.raises(RigInputError, match="has NaN or infinite coordinates") as e:
                load_gltf(path)
            assert str(path) in str(e.value)
    assert_same(load_gltf(_write(tmp_path, doc, "good.gltf")), cube)


# --- skinned meshes: the joints place them, not their node (glTF 2.0 §3.7.3) --------------------------------
def _skinned(tmp_path, name: str, mesh_node: dict, joints: list[dict], ibms: list[np.ndarray] | None,
             halves: bool = False):
    """The third-party SimpleMorph.gltf (its animation and default weights dropped) with its mesh skinned to
    ``joints`` (nodes at the scene's root; every vertex on the first, or with ``halves`` half on each of the first
    two) and ``mesh_node``'s transform on its node."""
    from tests.conftest import DATA, require_data
    doc = json.loads(require_data(DATA / "thirdparty" / "gltf" / "SimpleMorph.gltf").read_text())
    doc.pop("animations", None)
    doc["meshes"][0].pop("weights", None)
    n = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["count"]
    blob = bytes([0, 1 if halves else 0, 0, 0] * n) + struct.pack(f"<{4 * n}f", *([0.5, 0.5, 0.0, 0.0] if halves
                                                                                 else [1.0, 0.0, 0.0, 0.0]) * n)
    views = [(0, 4 * n), (4 * n, 16 * n)]
    if ibms is not None:
        views.append((len(blob), 64 * len(ibms)))
        blob += b"".join(struct.pack("<16f", *np.asarray(m, dtype=float).T.reshape(-1)) for m in ibms)
    doc["buffers"].append({"byteLength": len(blob),
                           "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()})
    b, v, a = len(doc["buffers"]) - 1, len(doc["bufferViews"]), len(doc["accessors"])
    doc["bufferViews"] += [{"buffer": b, "byteOffset": o, "byteLength": size} for o, size in views]
    doc["accessors"] += [{"bufferView": v, "componentType": 5121, "count": n, "type": "VEC4"},
                         {"bufferView": v + 1, "componentType": 5126, "count": n, "type": "VEC4"}]
    prim = doc["meshes"][0]["primitives"][0]
    prim["attributes"].update({"JOINTS_0": a, "WEIGHTS_0": a + 1})
    node = next(i for i, nd in enumerate(doc["nodes"]) if "mesh" in nd)
    doc["nodes"][node].update(mesh_node, skin=0)
    first = len(doc["nodes"])
    doc["nodes"] += joints
    doc["scenes"][0]["nodes"] += list(range(first, first + len(joints)))
    doc["skins"] = [{"joints": list(range(first, first + len(joints)))}]
    if ibms is not None:
        doc["accessors"].append({"bufferView": v + 2, "componentType": 5126, "count": len(ibms), "type": "MAT4"})
        doc["skins"][0]["inverseBindMatrices"] = a + 2
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def _shift(x, y, z) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = x, y, z
    return m


# (mesh node, joints, inverse bind matrices, half on each of two joints, the matrix that places the mesh)
SKINNED = {
    "node_ignored": ({"translation": [0, 0, 5]}, [{"name": "root"}], None, False, np.eye(4)),
    "joint_scales": ({"translation": [0, 0, 5]}, [{"scale": [2, 2, 2]}], None, False, np.diag([2, 2, 2, 1.0])),
    "bound_where_it_is": ({"scale": [0.01, 0.01, 0.01]}, [{"translation": [0, 2, 0]}, {"translation": [3, 0, 0]}],
                          [_shift(0, -2, 0), _shift(-3, 0, 0)], True, np.eye(4)),
    "joints_shift_it": ({}, [{"translation": [0, 2, 0]}, {"translation": [0, 2, 0]}], None, True, _shift(0, 2, 0)),
    # the joints disagree (a file posed away from its bind pose): each vertex placed by its joints' blend
    "posed_off_its_bind": ({"translation": [0, 0, 5]}, [{"translation": [0, 2, 0]}, {"translation": [3, 0, 0]}],
                           None, False, _shift(0, 2, 0)),
    "posed_and_blended": ({}, [{"translation": [0, 2, 0]}, {"translation": [3, 0, 0]}], None, True,
                          _shift(1.5, 1, 0)),
}


@pytest.mark.parametrize("case", list(SKINNED))
def test_a_skinned_mesh_is_placed_by_its_joints_not_by_its_node(tmp_path, case):
    """glTF 2.0 §3.7.3: a skinned mesh's node transform is ignored, its joints place it (a joint's world matrix
    times its inverse bind matrix). The reader applied the mesh node's transform: 5 m off, or 100 times too small
    under a centimetre-scaled node, where Blender and every viewer show the mesh where the joints put it."""
    from tests.conftest import DATA
    node, joints, ibms, halves, M = SKINNED[case]
    plain = load_gltf(DATA / "thirdparty" / "gltf" / "SimpleMorph.gltf")
    rig = load_gltf(_skinned(tmp_path, f"{case}.gltf", node, joints, ibms, halves))
    assert np.allclose(rig.neutral, plain.neutral @ M[:3, :3].T + M[:3, 3], atol=1e-9)
    assert np.allclose(rig.deltas, plain.deltas @ M[:3, :3].T, atol=1e-9)


def test_blender_shows_a_skinned_mesh_where_the_reader_puts_it(tmp_path):
    """The skinned files above imported by Blender's glTF importer: its evaluated mesh (the armature applied), in
    glTF's axes, is the rig's neutral."""
    import shutil
    import subprocess
    blender = shutil.which("blender")
    if not blender:
        pytest.skip("blender is not installed")
    paths = [_skinned(tmp_path, f"{case}.gltf", *SKINNED[case][:4]) for case in SKINNED]
    script = tmp_path / "evaluated.py"
    script.write_text(
        "import bpy, json, sys\n"
        "out, paths = sys.argv[-1], sys.argv[sys.argv.index('--') + 1:-1]\n"
        "seen = {}\n"
        "for path in paths:\n"
        "    bpy.ops.wm.read_factory_settings(use_empty=True)\n"
        "    bpy.ops.import_scene.gltf(filepath=path)\n"
        "    o = next(o for o in bpy.data.objects if o.type == 'MESH')\n"
        "    ev = o.evaluated_get(bpy.context.evaluated_depsgraph_get())\n"
        "    seen[path] = [list(ev.matrix_world @ v.co) for v in ev.to_mesh().vertices]\n"
        "json.dump(seen, open(out, 'w'))\n")
    out = tmp_path / "seen.json"
    proc = subprocess.run([blender, "-b", "--factory-startup", "--python", str(script), "--", *map(str, paths),
                           str(out)], capture_output=True, text=True, timeout=600)
    assert out.exists(), proc.stdout[-2000:] + proc.stderr[-2000:]
    seen = json.loads(out.read_text())
    for path in paths:
        b = np.array(seen[str(path)])
        in_gltf_axes = np.c_[b[:, 0], b[:, 2], -b[:, 1]]     # Blender's Z-up back to glTF's Y-up
        assert np.allclose(in_gltf_axes, load_gltf(path).neutral, atol=1e-5), (path.name, in_gltf_axes)


def test_a_mesh_opens_in_its_default_weights_and_keeps_them_as_a_preset(tmp_path, sample_rig):
    """glTF 2.0 §3.7.2.2: a mesh's ``weights`` are the pose viewers show without an animation (Blender's shape key
    values). SimpleMorph's [0.5, 0.5] opened at neutral, and a rig exported in a pose (Export Rig writes the pose
    there) reopened at neutral."""
    from app.loading import open_project_or_rig
    from model.export import export_rig
    from model.gltf import DEFAULT_POSE
    from tests.conftest import DATA, require_data
    project = open_project_or_rig(require_data(DATA / "thirdparty" / "gltf" / "SimpleMorph.gltf"))
    np.testing.assert_array_equal(project.weights, [0.5, 0.5])
    assert project.rig.presets[DEFAULT_POSE] == {"target_0": 0.5, "target_1": 0.5}
    stress = open_project_or_rig(DATA / "thirdparty" / "gltf" / "MorphStressTest.gltf")   # all 0: neutral, no preset
    assert not stress.weights.any() and DEFAULT_POSE not in stress.rig.presets
    pose = np.zeros(sample_rig.n_shapes)
    pose[[1, 4]] = [0.75, 0.25]
    export_rig(sample_rig, tmp_path / "posed.glb", weights=pose)
    np.testing.assert_allclose(open_project_or_rig(tmp_path / "posed.glb").weights, pose, atol=1e-7)


def test_default_weights_that_are_not_one_number_per_target_are_refused(tmp_path, cube):
    path = tmp_path / "cube.gltf"
    write_gltf(cube, path)
    doc = json.loads(path.read_text())
    for bad in ([0.5] * (cube.n_shapes + 1), ["a"] * cube.n_shapes, 7):
        doc["meshes"][0]["weights"] = bad
        path.write_text(json.dumps(doc))
        with pytest.raises(RigInputError, match="default weights are not"):
            load_gltf(path)


def test_default_weights_beyond_any_weight_are_refused(tmp_path, cube):
    """A mesh whose default weights are 1e30 opened in that pose (and kept it as the preset "glTF default pose"):
    `export --preset "glTF default pose"` wrote an OBJ with a vertex 10^30 away. Beyond ±MAX_WEIGHT (as a preset's
    or a pose's) it is one sentence naming the file; within it, the pose is kept."""
    from model.rig import MAX_WEIGHT
    from tests.cli_runner import run_cli
    path = tmp_path / "cube.gltf"
    write_gltf(cube, path)
    doc = json.loads(path.read_text())
    doc["meshes"][0]["weights"] = [1e30] + [0.0] * (cube.n_shapes - 1)
    path.write_text(json.dumps(doc))
    proc = run_cli("export", path, "-o", tmp_path / "x.obj", check=False)
    assert (proc.returncode, proc.stderr) == (2, f"error: {path}: its mesh's default weights reach 1e+30, beyond the "
                                                 f"±{MAX_WEIGHT:g} a weight may have.\n")
    assert not (tmp_path / "x.obj").exists()
    doc["meshes"][0]["weights"][0] = -MAX_WEIGHT
    path.write_text(json.dumps(doc))
    assert load_gltf(path).presets["glTF default pose"] == {cube.shape_names[0]: -MAX_WEIGHT}
