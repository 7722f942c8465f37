"""Per-shape textures and Joshi's band-pass blending (issue 22): the blend against an independent reference,
the forehead lines keeping their contrast on the sample face, UVs surviving round trips, bad input."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from model.errors import RigInputError
from model.textures import (TextureFiles, display_split, files_from_section, find_texture_files,
                            load_texture_set, per_vertex_uvs, read_texture, uv_problems, write_texture)
from solvers.texture_blend import TextureBlender, blend_once, low_pass

SAMPLE_POSE = {"browInnerUp_L": 0.5, "browInnerUp_R": 0.5, "mouthSmile_L": 0.5, "mouthSmile_R": 0.5}


# --- an independent reference: its own Gaussian (explicit kernel, edges repeated) and per-texel choice ----
def _ref_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    r = int(3.0 * sigma + 0.5)
    x = np.arange(-r, r + 1)
    k = np.exp(-x ** 2 / (2 * sigma ** 2))
    k /= k.sum()
    out = img.astype(np.float64)
    for axis in (0, 1):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (r, r)
        p = np.pad(out, pad, mode="edge")
        acc = np.zeros_like(out)
        for i, kv in enumerate(k):
            sl = [slice(None)] * out.ndim
            sl[axis] = slice(i, i + out.shape[axis])
            acc += kv * p[tuple(sl)]
        out = acc
    return out


def _reference(neutral, shapes, w, sigma, mode, detail, keep):
    """Joshi §5 written out texel by texel from the formula (no boxes, no state)."""
    L0 = _ref_blur(neutral, sigma)
    D0 = neutral - L0
    low = L0.copy()
    textured = [(k, s) for k, s in enumerate(shapes) if s is not None]
    for k, s in textured:
        low += w[k] * (_ref_blur(s, sigma) - L0)
    if mode == "linear":
        out = neutral + sum(w[k] * (s - neutral) for k, s in textured)
    else:
        H, W = neutral.shape[:2]
        D = D0.copy()
        if detail == "dominant":
            cands = [(w[k], -k, k, s) for k, s in textured if w[k] > 0]
            if cands:
                _, _, k, s = max(cands)
                D = s - _ref_blur(s, sigma)
        elif detail == "regional":
            m = {k: np.clip(_ref_blur(np.abs(s - neutral).max(axis=2), sigma) / (1 / 64), 0, 1) for k, s in textured}
            dk = {k: s - _ref_blur(s, sigma) for k, s in textured}
            for i in range(H):
                for j in range(W):
                    best, src = 0.0, None
                    for k, s in textured:
                        score = np.float32(w[k]) * np.float32(m[k][i, j])
                        if w[k] > 0 and score > best:
                            best, src = score, k
                    if src is not None:
                        D[i, j] = dk[src][i, j]
        out = low + D
    if keep is not None:
        out = out + keep[..., None] * (neutral - out)
    return out


def _local_textures(rng, H=40, W=56, K=5):
    neutral = rng.uniform(0.2, 0.8, (H, W, 3)).astype(np.float32)
    shapes = []
    for k in range(K):
        if k == 2:
            shapes.append(None)   # a shape without its own texture
            continue
        img = neutral.copy()
        r0, c0 = rng.integers(0, H - 15), rng.integers(0, W - 20)
        img[r0:r0 + 12, c0:c0 + 18] = rng.uniform(0, 1, (12, 18, 3))   # local wrinkles, overlapping boxes
        shapes.append(img)
    keep = np.zeros((H, W), np.float32)
    keep[:5] = 1.0
    keep[5:8] = 0.5
    return neutral, shapes, keep


@pytest.mark.parametrize("mode,detail", [("band-pass", "regional"), ("band-pass", "dominant"),
                                         ("band-pass", "neutral"), ("linear", "regional")])
def test_live_blend_matches_the_reference_formula_through_a_sequence_of_poses(mode, detail):
    rng = np.random.default_rng(7)
    neutral, shapes, keep = _local_textures(rng)
    b = TextureBlender(neutral, shapes, sigma=1.5, keep=keep, mode=mode, detail=detail)
    poses = [np.array([0.5, 0.0, 0.9, 0.2, 0.0]), np.array([0.5, 0.7, 0.9, 0.2, 0.0]),   # one weight changes
             np.array([0.1, 0.7, 0.0, 0.8, 0.4]), np.array([0.0, 0.0, 0.0, 0.0, 0.0]),
             np.array([1.2, -0.3, 0.5, 0.6, 0.6])]
    for w in poses:
        b.set_weights(w)
        ref = _reference(neutral, shapes, w, 1.5, mode, detail, keep)
        np.testing.assert_allclose(b.image, ref, atol=2e-5)
        assert np.abs(b.image8.astype(int) - np.clip(np.round(ref * 255), 0, 255)).max() <= 1
        low, det = b.bands()
        np.testing.assert_allclose(low + det, b.image, atol=1e-6)


def test_one_weight_change_rewrites_only_that_shapes_box():
    rng = np.random.default_rng(3)
    neutral, shapes, _ = _local_textures(rng, H=60, W=80)
    b = TextureBlender(neutral, shapes, sigma=1.0)
    b.set_weights(np.array([0.3, 0.3, 0.0, 0.3, 0.3]))
    before = b.image.copy()
    boxes = b.set_weights(np.array([0.3, 0.3, 0.0, 0.3, 0.9]))
    assert len(boxes) >= 1
    changed = np.abs(b.image - before).max(axis=2) > 0
    inside = np.zeros(changed.shape, bool)
    for r, c in boxes:
        inside[r, c] = True
    assert changed.any() and not (changed & ~inside).any()
    area = sum((r.stop - r.start) * (c.stop - c.start) for r, c in boxes)
    assert area < 0.5 * changed.size


def test_neutral_weights_show_the_neutral_and_a_shape_alone_shows_its_own_texture():
    rng = np.random.default_rng(11)
    neutral, shapes, _ = _local_textures(rng)
    for mode in ("band-pass", "linear"):
        out = blend_once(neutral, shapes, np.zeros(5), mode=mode, sigma=1.5)
        np.testing.assert_allclose(out, neutral, atol=1e-6)
        w = np.zeros(5)
        w[3] = 1.0
        np.testing.assert_allclose(blend_once(neutral, shapes, w, mode=mode, sigma=1.5), shapes[3], atol=1e-5)


# --- the sample face -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sample_textures_set(sample_rig_module):
    from resources.sample_textures import sample_textures
    return sample_textures()


@pytest.fixture(scope="module")
def sample_rig_module():
    from resources.sample_rig import build_sample_rig
    return build_sample_rig()


def _forehead_contrast(blend: np.ndarray, neutral: np.ndarray, region, sigma: float) -> float:
    """RMS of the detail band (image − its blur) of the lines, i.e. of what the blend adds to the neutral."""
    d = blend - neutral
    return float(np.sqrt(np.mean(((d - low_pass(d, sigma))[region]) ** 2)))


def test_band_pass_keeps_the_forehead_lines_while_linear_halves_them(sample_rig_module, sample_textures_set):
    rig = sample_rig_module
    neutral, shapes, keep = sample_textures_set
    w = rig.weights_from_dict(SAMPLE_POSE)
    lines = shapes["browInnerUp_L"]
    # the forehead lines of the dominant shape there (browInnerUp_L): where its texture differs from the neutral
    region = np.abs(lines - neutral).max(axis=2) > 0.02
    assert region.sum() > 2000
    b = TextureBlender(neutral, [shapes.get(n) for n in rig.shape_names], keep=keep)
    own = _forehead_contrast(lines, neutral, region, b.sigma)
    b.set_mode("band-pass", "regional")
    b.set_weights(w)
    band = _forehead_contrast(b.image, neutral, region, b.sigma)
    b.set_mode("linear")
    lin = _forehead_contrast(b.image, neutral, region, b.sigma)
    assert 0.9 <= (band / own) ** 2 <= 1.1, (band, own)      # detail energy within 10 % of the shape's
    assert 0.45 <= lin / own <= 0.55, (lin, own)              # contrast halved
    # the mouth's texture still blends: the smile's nasolabial fold shows in both modes
    fold = np.abs(shapes["mouthSmile_L"] - neutral).max(axis=2) > 0.05
    assert np.abs(b.image - neutral)[fold].mean() > 0.01


def test_masked_regions_keep_the_neutral_texture(sample_rig_module, sample_textures_set):
    rig = sample_rig_module
    neutral, shapes, keep = sample_textures_set
    b = TextureBlender(neutral, [shapes.get(n) for n in rig.shape_names], keep=keep)
    b.set_weights(np.full(rig.n_shapes, 1.0))
    full = keep >= 1.0
    assert full.sum() > 10000
    np.testing.assert_allclose(b.image[full], neutral[full], atol=1e-6)
    # a mask over the forehead keeps the lines out; without it they are there
    forehead = np.abs(shapes["browInnerUp_L"] - neutral).max(axis=2) > 0.02
    assert np.abs(b.image - neutral)[forehead].mean() > 0.02
    b.set_keep(np.maximum(keep, forehead))
    np.testing.assert_allclose(b.image[forehead], neutral[forehead], atol=1e-6)


def test_sample_textures_are_deterministic_and_wrinkle_where_the_issue_says(sample_textures_set):
    from resources.sample_textures import WRINKLED, face_coordinates, sample_textures
    neutral, shapes, keep = sample_textures_set
    assert set(shapes) == set(WRINKLED)
    sample_textures.cache_clear()
    again = sample_textures()
    np.testing.assert_array_equal(again[0], neutral)
    np.testing.assert_array_equal(again[1]["browDown_L"], shapes["browDown_L"])
    from resources.sample_rig import sample_geometry
    g = sample_geometry()
    x, y, skin = face_coordinates()

    def centre(name):
        d = np.abs(shapes[name] - neutral).max(axis=2)
        m = d > 0.05
        return float(x[m].mean()), float(y[m].mean())

    assert centre("browInnerUp_L")[1] > g.eye_y + 2.0 and centre("browInnerUp_L")[0] > 0       # forehead, left
    assert centre("browInnerUp_R")[0] < 0
    assert g.eye_y + 0.8 < centre("browDown_L")[1] < g.eye_y + 3.0 and abs(centre("browDown_L")[0]) < 1.2  # glabella
    assert g.eye_y - 2.2 < centre("noseSneer_L")[1] < g.eye_y - 0.5 and abs(centre("noseSneer_L")[0]) < 1.2
    assert centre("eyeSquint_L")[0] > 4.5                                                     # crow's feet
    sx, sy = centre("mouthSmile_L")
    assert sx > 1.5 and sy < g.eye_y                                                          # fold + feet


# --- UVs and files -------------------------------------------------------------------------------------
def test_sample_written_as_a_folder_finds_its_textures_by_name(written_sample, sample_rig_module):
    from model.readers import load_rig
    folder = written_sample
    rig = load_rig(folder)
    np.testing.assert_array_equal(rig.face_indices, sample_rig_module.face_indices)
    np.testing.assert_allclose(per_vertex_uvs(rig), per_vertex_uvs(sample_rig_module), atol=1e-6)
    files = find_texture_files(rig)
    assert files.neutral == folder / "neutral.png" and files.mask == folder / "texture_mask.png"
    assert files.shapes["browInnerUp_L"] == folder / "browInnerUp_L.png" and "jawOpen" not in files.shapes
    tex, problems = load_texture_set(rig, files)
    assert problems == [] and tex.neutral.shape == (1024, 1024, 3) and len(tex.shapes) == 14


def test_obj_uvs_survive_obj_project_obj_exactly(tmp_path, sample_rig_module):
    from model.obj_io import read_obj, write_obj
    from model.project import Project, load_project, save_project
    from model.readers import load_rig
    from resources.sample_rig import write_sample
    folder = write_sample(tmp_path / "face")
    rig = load_rig(folder)
    save_project(Project(rig=rig), tmp_path / "p.bsproj")
    back = load_project(tmp_path / "p.bsproj").rig
    np.testing.assert_array_equal(back.corners.uvs, rig.corners.uvs)
    np.testing.assert_array_equal(back.corners.corner_uv, rig.corners.corner_uv)
    write_obj(tmp_path / "out.obj", back.neutral, back.face_counts, back.face_indices, corners=back.corners)
    src, out = (p.read_text().splitlines() for p in (folder / "neutral.obj", tmp_path / "out.obj"))
    assert [l for l in src if l.startswith(("vt ", "f "))] == [l for l in out if l.startswith(("vt ", "f "))]
    again = read_obj(tmp_path / "out.obj")
    np.testing.assert_array_equal(again.corners.uvs, rig.corners.uvs)


def test_gltf_uvs_survive_gltf_project_gltf_exactly(tmp_path, sample_rig_module):
    import json

    from model.gltf import load_gltf, write_gltf
    from model.project import Project, load_project, save_project
    write_gltf(sample_rig_module, tmp_path / "a.gltf")
    first = load_gltf(tmp_path / "a.gltf")
    uv1 = per_vertex_uvs(first)
    assert uv1 is not None and uv1.shape == (sample_rig_module.n_vertices, 2)
    np.testing.assert_allclose(uv1, per_vertex_uvs(sample_rig_module), atol=1e-6)   # float32 in the file
    save_project(Project(rig=first), tmp_path / "a.bsproj")
    write_gltf(load_project(tmp_path / "a.bsproj").rig, tmp_path / "b.glb")
    second = load_gltf(tmp_path / "b.glb")
    np.testing.assert_array_equal(per_vertex_uvs(second), uv1)
    # the TEXCOORD_0 values are the same float32 numbers in both files, read by an independent reader
    pygltflib = pytest.importorskip("pygltflib")

    def texcoords(path):
        g = pygltflib.GLTF2().load(str(path))
        acc = g.accessors[g.meshes[0].primitives[0].attributes.TEXCOORD_0]
        view = g.bufferViews[acc.bufferView]
        blob = g.binary_blob() if str(path).endswith(".glb") else g.get_data_from_buffer_uri(g.buffers[0].uri)
        return np.frombuffer(blob[view.byteOffset:view.byteOffset + view.byteLength], "<f4").reshape(-1, 2)

    t1, t2 = texcoords(tmp_path / "a.gltf"), texcoords(tmp_path / "b.glb")
    np.testing.assert_array_equal(t1, t2)
    # glTF's v runs down the image: the forehead (high y, high OBJ v) has a small glTF v
    top = int(np.argmax(sample_rig_module.neutral[:, 1]))
    assert t1[top, 1] < 0.2
    assert json.loads((tmp_path / "a.gltf").read_text())["accessors"]


def test_ict_uv_corners_are_read_without_touching_its_vertices(ict_dir, ict_rig):
    from model.obj_io import read_obj
    rig = ict_rig
    assert rig.n_vertices == 26719
    assert rig.corners.uvs.shape[0] == 28911
    assert rig.corners.corner_uv.shape == rig.face_indices.shape and rig.corners.corner_uv.min() >= 0
    # the vertices are the file's 'v' records in order
    v = np.array([[float(t) for t in line.split()[1:4]] for line in
                  (ict_dir / "generic_neutral_mesh.obj").read_text().splitlines() if line.startswith("v ")])
    np.testing.assert_allclose(rig.neutral, v, atol=1e-9)
    assert read_obj(ict_dir / "generic_neutral_mesh.obj").vertices.shape == (26719, 3)
    # for drawing only, split at the seams: every display point is a rig vertex with one of its UVs
    split = display_split(rig)
    assert 26719 < len(split.vertex) <= 26719 + 28911
    assert set(np.unique(split.vertex)) == set(np.unique(rig.face_indices))
    corner_uv = rig.corners.uvs[rig.corners.corner_uv, :2]
    np.testing.assert_array_equal(split.vertex[split.face_indices], rig.face_indices)
    np.testing.assert_array_equal(split.uv[split.face_indices], corner_uv)
    assert per_vertex_uvs(rig) is None   # ICT has seams: no per-vertex UV


# --- bad input: a clear sentence, the geometry still loads ----------------------------------------------
@pytest.fixture(scope="module")
def written_sample(tmp_path_factory):
    from resources.sample_rig import write_sample
    from resources.sample_textures import write_sample_textures
    folder = write_sample(tmp_path_factory.mktemp("sample") / "face")
    write_sample_textures(folder)
    return folder


@pytest.fixture()
def textured_folder(tmp_path, written_sample):
    import shutil
    return Path(shutil.copytree(written_sample, tmp_path / "face"))


def test_texture_of_the_wrong_size_is_left_out_with_a_sentence(textured_folder):
    from model.readers import load_rig
    write_texture(textured_folder / "browDown_L.png", np.zeros((100, 80, 3)))
    rig = load_rig(textured_folder)
    tex, problems = load_texture_set(rig, find_texture_files(rig))
    assert "browDown_L" not in tex.shapes and "browInnerUp_L" in tex.shapes
    assert len(problems) == 1 and "browDown_L.png" in problems[0] and "80x100" in problems[0] \
        and "1024x1024" in problems[0] and "\n" not in problems[0]


def test_file_that_is_not_an_image_and_a_missing_texture(textured_folder, tmp_path):
    from model.readers import load_rig
    (textured_folder / "noseSneer_L.png").write_text("not a picture")
    rig = load_rig(textured_folder)
    tex, problems = load_texture_set(rig, find_texture_files(rig))
    assert tex is not None and "noseSneer_L" not in tex.shapes
    assert any("noseSneer_L.png" in p and "not an image" in p for p in problems), problems
    # listed in a project but gone
    files, section_problems = files_from_section({"neutral": "neutral.png", "shapes": {"jawOpen": "gone.png",
                                                                                       "nope": "x.png"}},
                                                 textured_folder, rig.shape_names)
    tex, problems = load_texture_set(rig, files)
    assert any("gone.png" in p and "does not exist" in p for p in problems), problems
    assert any("'nope'" in p for p in section_problems)
    # no neutral texture: textures off, one sentence
    (textured_folder / "neutral.png").unlink()
    tex, problems = load_texture_set(rig, find_texture_files(rig))
    assert tex is None and any("no neutral texture" in p for p in problems)


def test_damaged_png_is_one_sentence(tmp_path):
    write_texture(tmp_path / "t.png", np.ones((64, 64, 3)) * 0.5)
    data = (tmp_path / "t.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[:len(data) // 2])
    with pytest.raises(RigInputError) as err:
        read_texture(tmp_path / "t.png")
    assert str(err.value).startswith(str(tmp_path / "t.png")) and "\n" not in str(err.value)


def test_uvs_out_of_range_or_not_numbers_are_reported_and_the_geometry_loads(textured_folder):
    from model.readers import load_rig
    obj = textured_folder / "neutral.obj"
    lines = obj.read_text().splitlines()
    vt = [i for i, l in enumerate(lines) if l.startswith("vt ")]
    lines[vt[0]] = "vt 1.5 -0.25"
    obj.write_text("\n".join(lines) + "\n")
    rig = load_rig(textured_folder)
    probs = uv_problems(rig)
    assert len(probs) == 1 and "outside 0–1" in probs[0]
    tex, problems = load_texture_set(rig, find_texture_files(rig))
    assert tex is not None and problems == probs
    lines[vt[1]] = "vt nan 0.5"
    obj.write_text("\n".join(lines) + "\n")
    rig = load_rig(textured_folder)
    assert rig.n_vertices == 12651 and rig.corners.uvs is None
    tex, problems = load_texture_set(rig, find_texture_files(rig))
    assert tex is None and any("NaN" in p for p in problems) and any("no texture coordinates" in p for p in problems)


def test_gltf_with_a_bad_texcoord_accessor_loads_its_geometry(tmp_path, sample_rig_module):
    import json

    from model.gltf import load_gltf, write_gltf
    write_gltf(sample_rig_module, tmp_path / "a.gltf")
    doc = json.loads((tmp_path / "a.gltf").read_text())
    prim = doc["meshes"][0]["primitives"][0]
    prim["attributes"]["TEXCOORD_0"] = prim["attributes"]["POSITION"]   # VEC3 where VEC2 belongs
    (tmp_path / "b.gltf").write_text(json.dumps(doc))
    rig = load_gltf(tmp_path / "b.gltf")
    assert rig.n_vertices == sample_rig_module.n_vertices and rig.corners.uvs is None
    assert any("TEXCOORD_0" in p and "left out" in p for p in uv_problems(rig))
    prim["attributes"]["TEXCOORD_0"] = 999
    (tmp_path / "c.gltf").write_text(json.dumps(doc))
    rig = load_gltf(tmp_path / "c.gltf")
    assert rig.corners.uvs is None and any("cannot be read" in p for p in uv_problems(rig))


def test_project_with_a_damaged_uv_table_is_refused_in_one_sentence(tmp_path, sample_rig_module):
    import io
    import zipfile

    from model.project import Project, load_project, save_project
    save_project(Project(rig=sample_rig_module.copy()), tmp_path / "p.bsproj")
    with zipfile.ZipFile(tmp_path / "p.bsproj") as src, zipfile.ZipFile(tmp_path / "q.bsproj", "w") as dst:
        for n in src.namelist():
            b = src.read(n)
            if n == "rig/uvs.npy":
                buf = io.BytesIO()
                np.save(buf, np.zeros(7))
                b = buf.getvalue()
            if n == "manifest.json":
                b = b.replace(b'"rig/uvs": [\n   [\n    12651,\n    2\n   ]', b'"rig/uvs": [\n   [\n    7\n   ]')
            dst.writestr(n, b)
    with pytest.raises(RigInputError) as err:
        load_project(tmp_path / "q.bsproj")
    assert str(err.value).startswith(str(tmp_path / "q.bsproj")) and "\n" not in str(err.value)


def test_empty_texture_files_and_a_section_that_is_not_an_object(sample_rig_module, tmp_path):
    tex, problems = load_texture_set(sample_rig_module, TextureFiles())
    assert tex is None and problems == []
    files, problems = files_from_section(["a.png"], tmp_path, sample_rig_module.shape_names)
    assert files.empty and len(problems) == 1 and "not an object" in problems[0]
    files, problems = files_from_section({"neutral": 5, "shapes": {"jawOpen": "\0bad"}}, tmp_path,
                                         sample_rig_module.shape_names)
    assert files.empty and len(problems) == 2
