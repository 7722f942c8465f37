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
    d["accessors"][d["meshes"][0]["primitives"][0]["targets"][1]["POSITION"]]["count"] = 4
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
