"""OBJ-folder reading: vertex order kept, every kind of bad input named in one sentence."""
from __future__ import annotations

import numpy as np
import pytest

from model.errors import RigInputError
from model.obj_io import read_obj, write_obj
from model.readers import load_rig
from tests.rig_files import grid, obj_text, write_rig_folder


def test_small_folder_round_trip(tmp_path):
    verts, targets = write_rig_folder(tmp_path / "rig")
    rig = load_rig(tmp_path / "rig")
    assert rig.n_vertices == len(verts) and rig.n_faces == 25 and sorted(rig.shape_names) == ["push", "raise"]
    np.testing.assert_allclose(rig.neutral, verts)
    for name, t in targets.items():
        np.testing.assert_allclose(rig.shape(name), t, atol=1e-6)
    assert rig.face_counts.tolist() == [4] * 25
    assert rig.polygons()[0].tolist() == [0, 1, 7, 6]


def test_ict_counts_and_file_order(ict_rig, ict_dir):
    assert (ict_rig.n_vertices, ict_rig.n_faces, ict_rig.n_shapes) == (26719, 26384, 57)
    # Vertex order is the file's order of 'v' records (a general loader would re-index at UV seams).
    raw = [l.split()[1:4] for l in (ict_dir / "generic_neutral_mesh.obj").read_text().splitlines() if l.startswith("v ")]
    for i in (0, 1, 9408, 13000, 26718):
        np.testing.assert_allclose(ict_rig.neutral[i], [float(x) for x in raw[i]])
    assert "jawOpen" in ict_rig.shape_names and "generic_neutral_mesh" not in ict_rig.shape_names
    assert np.abs(ict_rig.deltas[ict_rig.shape_index("jawOpen")]).max() > 1.0  # centimetres


def _bad_folder(tmp_path, mutate):
    folder = tmp_path / "bad"
    write_rig_folder(folder)
    mutate(folder)
    return folder


def _expect(folder, *words, neutral=None):
    with pytest.raises(RigInputError) as info:
        load_rig(folder, neutral=neutral)
    msg = str(info.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg
    return msg


def test_wrong_vertex_count(tmp_path):
    verts, faces = grid(6)
    folder = _bad_folder(tmp_path, lambda f: (f / "extra.obj").write_text(obj_text(verts[:-1], [])))
    _expect(folder, "extra.obj", "35 vertices", "36")


def test_different_face_list(tmp_path):
    verts, faces = grid(6)
    faces[3] = faces[3][::-1]
    folder = _bad_folder(tmp_path, lambda f: (f / "flipped.obj").write_text(obj_text(verts, faces)))
    _expect(folder, "flipped.obj", "face list differs")


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_non_finite_coordinate(tmp_path, value):
    def mutate(f):
        text = (f / "raise.obj").read_text().splitlines()
        text[4] = f"v 1.0 {value} 0.0"
        (f / "raise.obj").write_text("\n".join(text) + "\n")
    _expect(_bad_folder(tmp_path, mutate), "raise.obj", "vertex 4", "NaN or infinite")


def test_empty_file(tmp_path):
    _expect(_bad_folder(tmp_path, lambda f: (f / "push.obj").write_text("")), "push.obj", "empty")


def test_truncated_file(tmp_path):
    def mutate(f):
        data = (f / "push.obj").read_text()
        (f / "push.obj").write_text(data[: len(data) // 3])
    _expect(_bad_folder(tmp_path, mutate), "push.obj")


def test_truncated_neutral_mid_line(tmp_path):
    def mutate(f):
        lines = (f / "neutral.obj").read_text().splitlines()
        (f / "neutral.obj").write_text("\n".join(lines[:10]) + "\nv 1.0")
    _expect(_bad_folder(tmp_path, mutate), "neutral.obj", "truncated")


def test_binary_file(tmp_path):
    _expect(_bad_folder(tmp_path, lambda f: (f / "push.obj").write_bytes(b"\x00\x01\x02binary" * 50)),
            "push.obj", "binary")


def test_non_utf8_file(tmp_path):
    def mutate(f):
        (f / "push.obj").write_bytes(b"# caf\xe9\n" + (f / "push.obj").read_bytes())
    _expect(_bad_folder(tmp_path, mutate), "push.obj", "UTF-8")


def test_no_neutral_and_two_neutrals(tmp_path):
    folder = _bad_folder(tmp_path, lambda f: (f / "neutral.obj").rename(f / "base.obj"))
    _expect(folder, "no OBJ has 'neutral'")
    assert load_rig(folder, neutral="base.obj").n_shapes == 2  # --neutral names it
    folder2 = _bad_folder(tmp_path / "two", lambda f: (f / "push.obj").rename(f / "neutral_open.obj"))
    _expect(folder2, "more than one OBJ could be the neutral")


def test_an_obj_name_that_is_not_a_file_is_named(tmp_path):
    """A folder (or a dangling link) named like a shape was passed over: the rig opened one shape short without a
    word; a folder named neutral.obj read as "no OBJ has 'neutral' in its name". Each is one sentence naming it."""
    write_rig_folder(tmp_path / "rig")
    (tmp_path / "rig" / "raise.obj").unlink()
    (tmp_path / "rig" / "raise.obj").mkdir()
    with pytest.raises(RigInputError, match=r"^.*raise\.obj: is a folder, not a file\.$"):
        load_rig(tmp_path / "rig")
    write_rig_folder(tmp_path / "rig2")
    (tmp_path / "rig2" / "neutral.obj").unlink()
    (tmp_path / "rig2" / "neutral.obj").mkdir()
    with pytest.raises(RigInputError, match=r"^.*rig2/neutral\.obj: is a folder, not a file\.$"):
        load_rig(tmp_path / "rig2")
    write_rig_folder(tmp_path / "rig3")
    (tmp_path / "rig3" / "smile.obj").symlink_to(tmp_path / "gone.obj")
    with pytest.raises(RigInputError, match=r"^.*smile\.obj: does not exist\.$"):
        load_rig(tmp_path / "rig3")


def test_duplicate_shape_names(tmp_path):
    folder = _bad_folder(tmp_path, lambda f: (f / "Push.OBJ").write_bytes((f / "push.obj").read_bytes()))
    _expect(folder, "duplicate shape names")


def test_unknown_format_and_missing_path(tmp_path):
    p = tmp_path / "rig.fbx"
    p.write_text("x")
    _expect(p, "unknown rig format")
    _expect(tmp_path / "nope", "does not exist")


def test_write_obj_keeps_order_and_polygons(tmp_path):
    verts, faces = grid(5)
    counts = np.full(len(faces), 4)
    write_obj(tmp_path / "o.obj", verts, counts, np.concatenate(faces))
    back = read_obj(tmp_path / "o.obj")
    np.testing.assert_allclose(back.vertices, verts)
    assert back.face_indices.tolist() == np.concatenate(faces).tolist()


def test_presets_json_beside_the_objs(tmp_path):
    write_rig_folder(tmp_path / "rig")
    (tmp_path / "rig" / "presets.json").write_text('{"lift": {"raise": 1.0, "push": 0.5}}')
    assert load_rig(tmp_path / "rig").presets == {"lift": {"raise": 1.0, "push": 0.5}}
    (tmp_path / "rig" / "presets.json").write_text('{"lift": {"smile": 1.0}}')
    _expect(tmp_path / "rig", "presets.json", "smile")


def test_sample_folder_carries_its_presets(tmp_path):
    from resources.sample_rig import build_sample_rig, write_sample
    write_sample(tmp_path / "s")
    assert load_rig(tmp_path / "s").presets == build_sample_rig().presets
