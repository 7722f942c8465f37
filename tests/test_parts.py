"""A rig's parts (its faces by material, model.parts): read from ICT FaceKit's OBJ and MTL, from glTF files other
tools wrote, kept by projects, hidden and coloured by ``render``; a material library that is missing, hostile or
outside the rig's folder never stops the rig loading."""
from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from model.parts import default_hidden, read_mtl, rig_parts, shown_faces, subset_faces, vertex_colors
from model.project import Project, load_project, save_project
from model.readers import load_rig
from tests.cli_runner import run_cli
from tests.rig_files import material_of_each_face, mtl_kd

HELPERS = ["M_LacrimalFluid", "M_EyeBlend", "M_EyeOcclusion"]


def _faces_per_material(obj_path) -> Counter:
    """An independent count: the face lines after each ``usemtl`` line of the file."""
    return Counter(material_of_each_face(obj_path))


def test_ict_parts_are_its_materials_with_their_faces_and_colours(ict_dir, ict_rig):
    parts = rig_parts(ict_rig)
    expected = _faces_per_material(ict_dir / "generic_neutral_mesh.obj")
    assert len(parts.names) == 12 and set(parts.names) == set(expected)
    assert {n: len(parts.faces(n)) for n in parts.names} == dict(expected)
    assert (parts.face_part >= 0).all() and parts.face_part.size == ict_rig.n_faces
    color = dict(zip(parts.names, parts.colors.tolist()))
    assert color["M_Teeth"] == pytest.approx([0.8] * 3) and color["M_EyeLashes"] == [0.0, 0.0, 0.0]
    assert color["M_GumsTongue"] == pytest.approx([0.30, 0.03, 0.06])
    assert default_hidden(parts.names) == HELPERS


def test_hiding_parts_leaves_out_exactly_their_polygons_and_keeps_every_vertex(ict_rig):
    parts = rig_parts(ict_rig)
    faces = shown_faces(parts, HELPERS)
    hidden = np.concatenate([parts.faces(n) for n in HELPERS])
    assert faces.size == ict_rig.n_faces - hidden.size == ict_rig.n_faces - (326 + 30 + 256)
    assert not np.isin(hidden, faces).any()
    counts, indices = subset_faces(ict_rig.face_counts, ict_rig.face_indices, faces)
    starts = np.concatenate(([0], np.cumsum(ict_rig.face_counts)[:-1]))
    polygons = [tuple(ict_rig.face_indices[starts[f]:starts[f] + ict_rig.face_counts[f]]) for f in faces[::997]]
    kept = np.split(indices, np.cumsum(counts)[:-1])[::997]
    assert polygons == [tuple(p) for p in kept]
    assert shown_faces(parts, []) is None and shown_faces(None, HELPERS) is None


def test_vertex_colours_take_their_part_colour_and_the_view_colour_where_the_file_gives_none(ict_rig):
    parts = rig_parts(ict_rig)
    rgb = vertex_colors(parts, ict_rig.face_counts, ict_rig.face_indices, ict_rig.n_vertices, (1.0, 0.5, 0.0))
    starts = np.concatenate(([0], np.cumsum(ict_rig.face_counts)[:-1]))
    iris = ict_rig.face_indices[starts[parts.faces("M_IrisLeft")[0]]]
    gums = ict_rig.face_indices[starts[parts.faces("M_GumsTongue")[0]]]
    assert rgb[iris].tolist() == [51, 51, 51] and rgb[gums].tolist() == [76, 8, 15]
    parts.colors[parts.names.index("M_Teeth")] = np.nan      # a material the MTL does not colour
    rgb = vertex_colors(parts, ict_rig.face_counts, ict_rig.face_indices, ict_rig.n_vertices, (1.0, 0.5, 0.0))
    tooth = ict_rig.face_indices[starts[parts.faces("M_Teeth")[0]]]
    assert rgb[tooth].tolist() == [255, 128, 0]
    parts.colors[:] = np.nan
    assert vertex_colors(parts, ict_rig.face_counts, ict_rig.face_indices, ict_rig.n_vertices, (1, 1, 1)) is None


def test_gltf_parts_are_the_primitives_materials(tmp_path):
    """Files other tools wrote: MorphStressTest's two primitives (materials Base and TestMaterial, textured: no
    colour of their own), the sparse cube's one material with its base colour; SimpleMorph has none."""
    from tests.conftest import DATA, require_data
    folder = require_data(DATA / "thirdparty" / "gltf")
    stress = folder / "MorphStressTest.gltf"
    doc = json.loads(stress.read_text())
    prims = doc["meshes"][0]["primitives"]
    tris = [doc["accessors"][p["indices"]]["count"] // 3 for p in prims]
    names = [doc["materials"][p["material"]]["name"] for p in prims]
    parts = rig_parts(load_rig(stress))
    assert parts.names == names and [len(parts.faces(n)) for n in names] == tris
    assert np.isnan(parts.colors).all()
    cube = rig_parts(load_rig(folder / "singleBlendshapeCube_sparse.glb"))
    assert cube.names == ["lambert2"] and cube.colors[0] == pytest.approx([0.4] * 3)
    assert rig_parts(load_rig(folder / "SimpleMorph.gltf")) is None


def test_a_project_keeps_the_parts_and_their_colours(ict_rig, tmp_path):
    path = tmp_path / "p.bsproj"
    save_project(Project(rig=ict_rig, weights=np.zeros(ict_rig.n_shapes)), path)
    a, b = rig_parts(ict_rig), rig_parts(load_project(path).rig)
    assert a.names == b.names and np.array_equal(a.face_part, b.face_part)
    assert np.array_equal(a.colors, b.colors)


def _small_rig(folder, mtllib: str | None, mtl_text: str | None = None, mtl_name: str = "m.mtl"):
    folder.mkdir(parents=True, exist_ok=True)
    head = f"mtllib {mtllib}\n" if mtllib else ""
    body = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nusemtl skin\nf 1 2 3\nusemtl eye_occlusion\nf 2 4 3\n"
    (folder / "neutral.obj").write_text(head + body)
    (folder / "smile.obj").write_text(head + body.replace("v 1 1 0", "v 1 1 0.5"))
    if mtl_text is not None:
        (folder / mtl_name).write_bytes(mtl_text.encode() if isinstance(mtl_text, str) else mtl_text)
    return folder


@pytest.mark.parametrize("case", ["missing", "outside", "absolute", "garbage", "nan"])
def test_a_bad_material_library_leaves_the_colours_out_and_the_rig_loads(tmp_path, case):
    secret = tmp_path / "secret.mtl"
    secret.write_text("newmtl skin\nKd 1 0 0\n")
    folder = tmp_path / "rig"
    mtllib, text = {"missing": ("m.mtl", None), "outside": ("../secret.mtl", None),
                    "absolute": (str(secret), None), "garbage": ("m.mtl", b"\xff\xfe\x00garbage" * 50),
                    "nan": ("m.mtl", "newmtl skin\nKd nan 0 0\nnewmtl eye_occlusion\nKd inf 1 1\n")}[case]
    rig = load_rig(_small_rig(folder, mtllib, text))
    parts = rig_parts(rig)
    assert parts.names == ["skin", "eye_occlusion"] and np.isnan(parts.colors).all()
    assert rig.materials == {} and default_hidden(parts.names) == ["eye_occlusion"]
    notes = rig.corners.notes
    if case == "nan":
        assert notes == []
    else:
        assert len(notes) == 1 and (str(folder) in notes[0] or "m.mtl" in notes[0]), notes
        assert "secret" not in notes[0] or "outside its folder" in notes[0]


def test_read_mtl_reads_every_materials_diffuse_colour(tmp_path):
    p = tmp_path / "a.mtl"
    p.write_text("# a comment\nnewmtl A B\n  Kd 0.1 0.2 0.3\nKs 1 1 1\nnewmtl grey\nKd 0.5\nnewmtl none\nd 0.5\n"
                 "newmtl big\nKd 2 -1 0.5\n")
    colors, problem = read_mtl(p)
    assert problem is None
    assert colors == {"A B": pytest.approx((0.1, 0.2, 0.3)), "grey": (0.5, 0.5, 0.5), "big": (1.0, 0.0, 0.5)}


def test_render_hides_the_helper_shells_and_draws_material_colours_on_request(ict_dir, tmp_path):
    """``render`` by default leaves out ICT's helper shells: the picture differs from ``--hide none`` around the
    eyes only (the shells lie over the eyeballs). ``--material-colors`` draws the skin in its MTL grey (0.6) instead
    of the application's skin tone; ``--hide`` with a part the rig lacks is one sentence and exit code 2."""
    from PIL import Image
    out = {k: tmp_path / f"{k}.png" for k in ("default", "all", "colors")}
    run_cli("render", ict_dir, "-o", out["default"], "--size", "400,300")
    run_cli("render", ict_dir, "-o", out["all"], "--size", "400,300", "--hide", "none")
    run_cli("render", ict_dir, "-o", out["colors"], "--size", "400,300", "--material-colors")
    img = {k: np.asarray(Image.open(p).convert("RGB")).astype(int) for k, p in out.items()}
    diff = np.abs(img["default"] - img["all"]).sum(axis=2) > 30
    ys, xs = np.nonzero(diff)
    assert 50 < diff.sum() < 3000
    assert ys.min() > 50 and ys.max() < 100          # the eyes' band of the picture (the face spans rows 0-300)
    forehead = (slice(20, 40), slice(180, 220))
    skin, grey = img["default"][forehead].mean(axis=(0, 1)), img["colors"][forehead].mean(axis=(0, 1))
    assert skin[0] - skin[2] > 30 and np.ptp(grey) < 6, (skin, grey)
    bad = run_cli("render", ict_dir, "-o", tmp_path / "x.png", "--hide", "M_Nose", check=False)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "no part named M_Nose" in bad.stderr
    assert not (tmp_path / "x.png").exists()


def test_an_exported_obj_writes_its_material_library_and_keeps_the_parts(ict_dir, ict_rig, tmp_path):
    """The OBJ export writes the usemtl records back and the rig's colours as a material library beside it, named
    by its mtllib line (``neutral.mtl``), so the OBJ alone -- read back here or in a DCC -- has the same parts in
    the same colours; the source's library is not needed beside it."""
    from model.export import export_rig
    export_rig(ict_rig, tmp_path / "neutral.obj", np.zeros(ict_rig.n_shapes))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["neutral.mtl", "neutral.obj"]
    text = (tmp_path / "neutral.obj").read_text()
    assert [l for l in text.splitlines() if l.startswith("mtllib")] == ["mtllib neutral.mtl"]
    assert _faces_per_material(tmp_path / "neutral.obj") == _faces_per_material(ict_dir / "generic_neutral_mesh.obj")
    written, source = mtl_kd(tmp_path / "neutral.mtl"), mtl_kd(ict_dir / "ICTFaceModelMaterial.mtl")
    assert set(written) == set(rig_parts(ict_rig).names) and written == {n: source[n] for n in written}
    back = load_rig(tmp_path / "neutral.obj")
    a, b = rig_parts(ict_rig), rig_parts(back)
    assert a.names == b.names and np.array_equal(a.face_part, b.face_part) and np.array_equal(a.colors, b.colors)
    assert not back.corners.notes                        # the library was found and read


def test_an_obj_export_and_its_library_are_one_set(ict_rig, tmp_path, monkeypatch):
    """Written as one set (model.output_set): when the OBJ cannot be written, the library beside it is not
    replaced either, so an OBJ never sits beside another export's colours (kill -9 at random moments:
    tests/test_kill_writes.py)."""
    from model import atomic, output_set
    from model.export import export_rig
    rig = ict_rig.copy()
    export_rig(rig, tmp_path / "face.obj")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    rig.materials = dict(rig.materials, M_Face=(1.0, 0.0, 0.0))
    real = atomic.write_temporary

    def disk_full_for_the_obj(path, writer):
        if str(path).endswith(".obj"):
            raise OSError(28, "No space left on device")
        return real(path, writer)

    monkeypatch.setattr(atomic, "write_temporary", disk_full_for_the_obj)
    monkeypatch.setattr(output_set, "write_temporary", disk_full_for_the_obj)
    with pytest.raises(OSError):
        export_rig(rig, tmp_path / "face.obj", np.full(rig.n_shapes, 0.5))
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before     # both as they were, nothing left
    monkeypatch.undo()
    export_rig(rig, tmp_path / "face.obj")
    assert mtl_kd(tmp_path / "face.mtl")["M_Face"] == [1.0, 0.0, 0.0]


def test_gltf_materials_reach_the_obj_export(tmp_path):
    """Other tools' glTF files exported as OBJ: the sparse cube's base colour becomes the material library's Kd;
    MorphStressTest's two textured materials (no colour of their own) keep their parts through the usemtl records
    and write no library (there is nothing to put in it)."""
    from model.export import export_rig
    from tests.conftest import DATA, require_data
    folder = require_data(DATA / "thirdparty" / "gltf")
    cube = load_rig(folder / "singleBlendshapeCube_sparse.glb")
    (tmp_path / "cube").mkdir()
    export_rig(cube, tmp_path / "cube" / "cube.obj")
    kd = mtl_kd(tmp_path / "cube" / "cube.mtl")
    parts = rig_parts(cube)
    assert len(kd) == 1 and kd[parts.names[0]] == pytest.approx(parts.colors[0].tolist(), abs=1e-6)
    assert not np.isnan(parts.colors).any()
    assert rig_parts(load_rig(tmp_path / "cube" / "cube.obj")).colors == pytest.approx(parts.colors, abs=1e-6)
    stress = load_rig(folder / "MorphStressTest.gltf")
    (tmp_path / "stress").mkdir()
    export_rig(stress, tmp_path / "stress" / "stress.obj")
    assert [p.name for p in (tmp_path / "stress").iterdir()] == ["stress.obj"]
    back, parts = rig_parts(load_rig(tmp_path / "stress" / "stress.obj")), rig_parts(stress)
    assert back.names == parts.names == ["Base", "TestMaterial"] and np.array_equal(back.face_part, parts.face_part)


def test_gltf_material_names_become_one_word_each(tmp_path):
    """A glTF's material names are free text; as part names they are written back on an OBJ's usemtl line, so
    spaces and control characters become underscores (a newline would start a new OBJ record)."""
    from tests.conftest import DATA, require_data
    doc = json.loads(require_data(DATA / "thirdparty" / "gltf" / "MorphStressTest.gltf").read_text())
    doc["materials"][0]["name"] = "Base skin\nf 1 2 3\x00"
    doc["materials"][1].pop("name", None)
    (tmp_path / "m.gltf").write_text(json.dumps(doc))
    parts = rig_parts(load_rig(tmp_path / "m.gltf"))
    assert parts.names == ["Base_skin_f_1_2_3_", "material_1"]
