"""Exports other tools play (model/export.py): glTF and USD with named blend shapes, the pose, an animation
and correctives as extra shapes; OBJ keeping the source's UVs and groups; files with the user's umask."""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
from collections import Counter

import numpy as np
import pytest

from model.correctives import Corrective, add_corrective, corrective_activations
from model.errors import RigInputError
from model.export import WeightAnimation, export_rig, load_animation
from model.obj_io import read_obj
from model.pose import PoseEvaluator
from model.readers import load_rig
from tests.cli_runner import run_cli
from tests.rig_files import material_of_each_face, mtl_kd
from tests.gltf_reference import reference_animation, reference_mesh
from tests.gltf_rules import read_gltf_file, violations

DRIVERS = ["jawOpen", "mouthSmile_L"]


@pytest.fixture(scope="module")
def rig_with_corrective(ict_rig):
    """ICT plus a corrective on jawOpen x mouthSmile_L: a smooth 3 mm bump between the drivers' peaks."""
    rig = ict_rig.copy()
    centre = np.mean([rig.neutral[np.argmax(np.linalg.norm(rig.deltas[rig.shape_index(d)], axis=1))]
                      for d in DRIVERS], axis=0)
    r2 = ((rig.neutral - centre) ** 2).sum(axis=1)
    delta = 0.3 * np.exp(-r2 / 2.0 ** 2)[:, None] * np.array([0.0, 0.6, 0.8])
    delta[np.abs(delta).max(axis=1) < 1e-9] = 0.0
    add_corrective(rig, Corrective(drivers=DRIVERS, delta=delta, rule="product"))
    return rig


@pytest.fixture(scope="module")
def performance(rig_with_corrective, llf_csv):
    return load_animation(llf_csv, rig_with_corrective)


@pytest.fixture(scope="module")
def exported(rig_with_corrective, performance, tmp_path_factory):
    """ICT with the corrective, the Live Link Face performance and a pose, as .glb, .gltf, .usda and .usdc."""
    out = tmp_path_factory.mktemp("export")
    pose = rig_with_corrective.weights_from_dict({"jawOpen": 0.7, "mouthSmile_L": 0.5})
    paths = {}
    for suffix in (".glb", ".gltf", ".usda", ".usdc"):
        paths[suffix] = export_rig(rig_with_corrective, out / f"ict{suffix}", pose, performance)
    return paths, pose


_EVALUATORS: dict = {}


def dense(rig, weights) -> np.ndarray:
    """The application's pose evaluation (model.pose), float64 (one evaluator per rig)."""
    if id(rig) not in _EVALUATORS:
        _EVALUATORS[id(rig)] = (rig, PoseEvaluator(rig, dtype=np.float64))
    return _EVALUATORS[id(rig)][1].evaluate(weights)


def test_the_performance_really_drives_the_corrective(rig_with_corrective, performance):
    a = np.array([corrective_activations(rig_with_corrective.correctives, rig_with_corrective.shape_names, w)[0]
                  for w in performance.weights])
    assert performance.n_frames == 328 and a.max() > 0.05 and (a > 0).sum() > 20


def test_glb_plays_the_applications_pose_at_every_frame(exported, rig_with_corrective, performance):
    path = exported[0][".glb"]
    rig = rig_with_corrective
    verts, tris, names, deltas = reference_mesh(path)  # pygltflib + numpy
    assert names == rig.shape_names + [rig.correctives[0].name]
    assert len(verts) == rig.n_vertices == 26719
    assert np.array_equal(tris, rig.triangles())
    # metres by default: the rest surface is the OBJ's in cm / 100
    assert np.abs(verts * 100 - rig.neutral).max() < 1e-4
    times, W = reference_animation(path)
    assert np.allclose(times, performance.times, atol=1e-6)
    assert W.shape == (328, rig.n_shapes + 1)
    D = deltas.reshape(len(names), -1)
    worst = worst_without = 0.0
    for start in range(0, len(W), 64):
        block = slice(start, start + 64)
        played = (verts.reshape(-1) + W[block] @ D) * 100  # in cm, as the rig
        without = (verts.reshape(-1) + W[block, :-1] @ D[:-1]) * 100
        for f, w in enumerate(performance.weights[block]):
            expected = dense(rig, w).reshape(-1)
            worst = max(worst, np.abs(played[f] - expected).max())
            worst_without = max(worst_without, np.abs(without[f] - expected).max())
    assert worst < 1e-5
    # the corrective's animated weight is its activation: without it the frames would be off by the bump
    assert worst_without > 0.01


def test_gltf_holds_what_the_glb_holds(exported):
    glb, gltf = exported[0][".glb"], exported[0][".gltf"]
    for a, b in zip(reference_mesh(glb) + reference_animation(glb), reference_mesh(gltf) + reference_animation(gltf)):
        assert a == b if isinstance(a, list) else np.array_equal(a, b)


def test_gltf_default_weights_are_the_current_pose(exported, rig_with_corrective):
    paths, pose = exported
    doc, _, _ = read_gltf_file(paths[".glb"])
    w = np.array(doc["meshes"][0]["weights"])
    expected = np.append(pose, 0.7 * 0.5)  # product rule: the corrective at jawOpen 0.7 x smile 0.5
    assert np.allclose(w, expected, atol=1e-7)


def test_glb_carries_smooth_normals_their_morph_offsets_and_a_dielectric_material(exported, rig_with_corrective,
                                                                                  ict_dir):
    """A glTF client shades a primitive without NORMAL flat (glTF 2.0, 3.7.2.1: Blender 3.4 imported every face of
    ICT flat) and one without a material fully metallic (dark). Read with pygltflib: unit NORMALs, the area-weighted
    vertex normals of the file's own positions (float64 reference), and each morph target's NORMAL offset the
    normals of its surface at weight 1 less those (jawOpen, a smile, the corrective); a double-sided dielectric
    material in the colour of ICT's largest part (its MTL Kd)."""
    from solvers.normals import vertex_normals
    from tests.gltf_reference import reference_accessors
    g, values = reference_accessors(exported[0][".glb"])
    prim = g.meshes[0].primitives[0]
    pos, nrm = values(prim.attributes.POSITION), values(prim.attributes.NORMAL)
    tris = values(prim.indices)[:, 0].astype(int).reshape(-1, 3)
    ref = vertex_normals(pos, tris)
    used = np.linalg.norm(ref, axis=1) > 0
    assert used.sum() > 26000
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-6)
    assert np.abs(nrm[used] - ref[used]).max() < 1e-4
    names = g.meshes[0].extras["targetNames"]
    for name in ("jawOpen", "mouthSmile_L", rig_with_corrective.correctives[0].name):
        t = prim.targets[names.index(name)]
        d, dn = values(t["POSITION"]), values(t["NORMAL"])
        moved = vertex_normals(pos + d, tris)
        assert np.abs((nrm + dn)[used] - moved[used]).max() < 1e-4
        assert np.abs(dn).max() > 0.05, name                    # the shape turns the surface: offsets not zero
    material = g.materials[prim.material]
    assert material.doubleSided and material.pbrMetallicRoughness.metallicFactor == 0.0
    largest = Counter(material_of_each_face(ict_dir / "generic_neutral_mesh.obj")).most_common(1)[0][0]
    assert material.name == largest
    assert material.pbrMetallicRoughness.baseColorFactor == pytest.approx(
        [*mtl_kd(ict_dir / "ICTFaceModelMaterial.mtl")[largest], 1.0], abs=1e-6)


def test_glb_reads_back_in_trimesh_with_the_same_vertices(exported, rig_with_corrective):
    trimesh = pytest.importorskip("trimesh")
    scene = trimesh.load(exported[0][".glb"], process=False)
    (mesh,) = scene.geometry.values()
    assert np.abs(np.asarray(mesh.vertices) * 100 - rig_with_corrective.neutral).max() < 1e-4
    assert np.array_equal(np.asarray(mesh.faces), rig_with_corrective.triangles())


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_gltf_follows_the_validators_rules(exported, suffix):
    doc, blob, container = read_gltf_file(exported[0][suffix])
    assert container == [] and violations(doc, blob) == []


def test_the_rules_check_catches_broken_files(exported):
    """The Python rules are worth something: each of these edits is an error for the Khronos validator too."""
    doc, blob, _ = read_gltf_file(exported[0][".glb"])
    pos = doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
    anim_in = doc["animations"][0]["samplers"][0]["input"]
    edits = [lambda d: d["accessors"][pos].pop("max"),
             lambda d: d["accessors"][pos].update(max=[1.0, 1.0, 1.0]),
             lambda d: d["meshes"][0]["weights"].pop(),
             lambda d: d["meshes"][0]["extras"]["targetNames"].pop(),
             lambda d: d["accessors"][d["animations"][0]["samplers"][0]["output"]].update(count=5),
             lambda d: d["bufferViews"][0].update(byteStride=10),
             lambda d: d["buffers"][0].update(byteLength=len(blob) + 8)]
    for edit in edits:
        d = json.loads(json.dumps(doc))
        edit(d)
        assert violations(d, blob), edit
    times = np.frombuffer(blob, "<f4", doc["accessors"][anim_in]["count"],
                          doc["bufferViews"][doc["accessors"][anim_in]["bufferView"]]["byteOffset"]).copy()
    assert violations(doc, blob) == []
    reversed_blob = bytearray(blob)
    off = doc["bufferViews"][doc["accessors"][anim_in]["bufferView"]]["byteOffset"]
    reversed_blob[off:off + times.nbytes] = times[::-1].tobytes()
    assert violations(doc, bytes(reversed_blob))


def _validator():
    """A command running the Khronos glTF validator (npm gltf-validator) on a file, or None."""
    node = shutil.which("node")
    if not node:
        return None
    paths = [p for p in os.environ.get("NODE_PATH", "").split(os.pathsep) if p]
    npm = shutil.which("npm")
    if npm:
        try:
            paths.append(subprocess.run([npm, "root", "-g"], capture_output=True, text=True, timeout=60).stdout.strip())
        except (OSError, subprocess.SubprocessError):
            pass
    env = dict(os.environ, NODE_PATH=os.pathsep.join(paths))
    probe = subprocess.run([node, "-e", "require('gltf-validator')"], capture_output=True, env=env, timeout=60)
    if probe.returncode != 0:
        return None
    script = ("const fs=require('fs'),v=require('gltf-validator');"
              "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[1])),{maxIssues:0,writeTimestamp:false})"
              ".then(r=>console.log(JSON.stringify(r))).catch(e=>{console.error(String(e));process.exit(3)});")
    return lambda path: json.loads(subprocess.run([node, "-e", script, str(path)], capture_output=True, text=True,
                                                  env=env, timeout=600, check=True).stdout)


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_khronos_validator_reports_no_errors(exported, suffix, tmp_path):
    validate = _validator()
    if validate is None:
        pytest.skip("node or the gltf-validator npm module is not available "
                    "(npm install gltf-validator in a folder on NODE_PATH)")
    report = validate(exported[0][suffix])
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:10]
    assert report["info"]["animationCount"] == 1 and report["info"]["hasMorphTargets"]
    assert report["info"]["totalVertexCount"] == 26719
    # and it does fail a broken file (the positions' max removed), as the Python rules do
    doc, blob, _ = read_gltf_file(exported[0][".glb"])
    doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]].pop("max")
    from model.export_gltf import CHUNK_BIN, CHUNK_JSON, _pad4
    import struct
    js = _pad4(json.dumps(doc).encode(), b" ")
    body = struct.pack("<II", len(js), CHUNK_JSON) + js + struct.pack("<II", len(blob), CHUNK_BIN) + blob
    (tmp_path / "broken.glb").write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    assert validate(tmp_path / "broken.glb")["issues"]["numErrors"] > 0


# --- USD ------------------------------------------------------------------------------------------
def _usd_frames(path):
    """(names, rest points, {time code: deformed points}) as usd-core's UsdSkel evaluates the file."""
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom, UsdSkel
    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    mesh_prim = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(stage.GetDefaultPrim()), Usd.TraverseInstanceProxies())
    skinning = cache.GetSkinningQuery(mesh_prim)
    skel = UsdSkel.Skeleton(skinning.GetSkeleton() if hasattr(skinning, "GetSkeleton") else
                            stage.GetPrimAtPath("/Root/Skeleton"))
    anim = cache.GetSkelQuery(skel).GetAnimQuery()
    shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh_prim))
    rest = UsdGeom.Mesh(mesh_prim).GetPointsAttr().Get()
    names = [shapes.GetBlendShape(i).GetPrim().GetCustomDataByKey("name") or shapes.GetBlendShape(i).GetPrim().GetName()
             for i in range(shapes.GetNumBlendShapes())]

    def posed(code):
        w = anim.ComputeBlendShapeWeights(code)
        mapper = skinning.GetBlendShapeMapper()
        w = mapper.Remap(w) if mapper is not None else w
        sub, shape_idx, sub_idx = shapes.ComputeSubShapeWeights(w)
        pts = UsdGeom.Mesh(mesh_prim).GetPointsAttr().Get()
        assert shapes.ComputeDeformedPoints(sub, shape_idx, sub_idx, shapes.ComputeBlendShapePointIndices(),
                                            shapes.ComputeSubShapePointOffsets(), pts)
        return np.array(pts, dtype=np.float64)

    return stage, names, np.array(rest, dtype=np.float64), anim, posed, UsdGeom.Mesh(mesh_prim)


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_holds_the_same_content_and_plays_the_same_pose(exported, rig_with_corrective, performance, suffix):
    from pxr import Usd, UsdGeom
    rig = rig_with_corrective
    stage, names, rest, anim, posed, mesh = _usd_frames(exported[0][suffix])
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert names == rig.shape_names + [rig.correctives[0].name]
    assert np.abs(rest * 100 - rig.neutral).max() < 1e-4
    assert np.array_equal(np.array(mesh.GetFaceVertexCountsAttr().Get()), rig.face_counts)  # polygons as in the file
    assert np.array_equal(np.array(mesh.GetFaceVertexIndicesAttr().Get()), rig.face_indices)
    codes = anim.GetBlendShapeWeightTimeSamples()
    assert len(codes) == 328 and stage.GetTimeCodesPerSecond() == 60.0
    assert np.allclose(np.array(codes) / 60.0, performance.times, atol=1e-9)
    for f in (0, 60, 150, int(np.argmax(performance.weights[:, rig.shape_index("jawOpen")])), 327):
        got = posed(Usd.TimeCode(codes[f])) * 100
        assert np.abs(got - dense(rig, performance.weights[f])).max() < 1e-5, f
    pose = exported[1]
    assert np.abs(posed(Usd.TimeCode.Default()) * 100 - dense(rig, pose)).max() < 1e-5
    st = mesh.GetPrim().GetAttribute("primvars:st")
    assert st and len(st.Get()) == 28911  # the OBJ's UVs, face-varying through its own indices


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_binds_each_part_its_material_on_the_faces_the_obj_gives_it(exported, ict_dir, suffix):
    """ICT's twelve materials in the USD export: usd-core's own binding resolution (ComputeBoundMaterial on each
    GeomSubset) gives every face the material of the usemtl line before it in the source OBJ, whose colour is the
    MTL's Kd; the subsets partition the faces (a valid materialBind family) and the mesh keeps its vertices."""
    from pxr import Usd, UsdGeom, UsdShade
    stage = Usd.Stage.Open(str(exported[0][suffix]))
    mesh = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    expected = material_of_each_face(ict_dir / "generic_neutral_mesh.obj")
    subsets = UsdShade.MaterialBindingAPI(mesh).GetMaterialBindSubsets()
    assert len(subsets) == 12
    assert UsdGeom.Subset.ValidateFamily(UsdGeom.Imageable(mesh), UsdGeom.Tokens.face, "materialBind")[0]
    assert UsdShade.MaterialBindingAPI(mesh).GetMaterialBindSubsetsFamilyType() == UsdGeom.Tokens.partition
    kd = mtl_kd(ict_dir / "ICTFaceModelMaterial.mtl")
    got = [None] * len(expected)
    for subset in subsets:
        material, _ = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()
        name = material.GetPrim().GetCustomDataByKey("name") or material.GetPrim().GetName()
        for f in subset.GetIndicesAttr().Get():
            got[f] = name
        shader, _, _ = material.ComputeSurfaceSource()
        assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
        assert list(shader.GetInput("diffuseColor").Get()) == pytest.approx(kd[name], abs=1e-6), name
    wrong = [f for f, (a, b) in enumerate(zip(got, expected)) if a != b]
    assert len(got) == len(expected) and not wrong, f"{len(wrong)} faces bound to another material, e.g. {wrong[:5]}"
    assert len(UsdGeom.Mesh(mesh).GetPointsAttr().Get()) == 26719


def _usd_errors(path):
    """Errors of usd-core's compliance checker (UsdUtils.ComplianceChecker, replaced by the validation
    framework in usd-core 26; whichever this usd-core has)."""
    from pxr import Usd, UsdUtils
    if hasattr(UsdUtils, "ComplianceChecker"):
        checker = UsdUtils.ComplianceChecker(arkit=False, skipARKitRootLayerCheck=False, rootPackageOnly=False,
                                             skipVariants=False, verbose=False)
        checker.CheckCompliance(str(path))
        return list(checker.GetErrors()) + list(checker.GetFailedChecks())
    from pxr import UsdValidation
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    return [e.GetMessage() for e in context.Validate(Usd.Stage.Open(str(path)))
            if e.GetType() == UsdValidation.ValidationErrorType.Error]


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_passes_the_compliance_checker(exported, suffix, tmp_path):
    pytest.importorskip("pxr")
    assert _usd_errors(exported[0][suffix]) == []
    # and the checker does fail a stage that is not well formed (no metersPerUnit, no default prim)
    from pxr import Usd
    stage = Usd.Stage.Open(str(exported[0][".usda"]))  # kept alive: the layer dies with its stage
    text = stage.GetRootLayer().ExportToString()
    broken = tmp_path / "broken.usda"
    broken.write_text(text.replace("metersPerUnit = 1", "").replace('defaultPrim = "Root"', ""))
    assert _usd_errors(broken)


def test_usd_units_and_up_axis_options(tmp_path, rig_with_corrective):
    from pxr import UsdGeom
    export_rig(rig_with_corrective, tmp_path / "cm_z.usda", units="cm", up="z")
    stage, names, rest, *_ = _usd_frames(tmp_path / "cm_z.usda")
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z and UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    n = rig_with_corrective.neutral
    assert np.allclose(rest, np.stack([n[:, 0], -n[:, 2], n[:, 1]], axis=1), atol=1e-4)  # Y-up turned Z-up


def test_usd_keys_a_weights_csv_with_rounded_times_on_whole_frames_at_its_rate(tmp_path, sample_rig):
    """``export --animation`` of a weights CSV whose times another tool rounded (printf's %f): the USD plays at the
    take's rate, one time code per frame (it was 23.9998 fps with time codes 1.000008, ..., 46.9996 for 24 fps)."""
    from pxr import Usd
    name = sample_rig.shape_names[0]
    for rate, frames in ((24, 48), (60, 358)):
        csv = tmp_path / f"w{rate}.csv"
        csv.write_text(f"frame,time,{name}\n" + "".join(f"{k},{k / rate:.6f},{k / frames:.6f}\n"
                                                       for k in range(frames)))
        export_rig(sample_rig, tmp_path / f"w{rate}.usda", animation=load_animation(csv, sample_rig))
        stage = Usd.Stage.Open(str(tmp_path / f"w{rate}.usda"))
        assert stage.GetTimeCodesPerSecond() == rate and stage.GetFramesPerSecond() == rate
        assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, frames - 1)
        attr = stage.GetPrimAtPath("/Root/Skeleton/Animation").GetAttribute("blendShapeWeights")
        assert attr.GetTimeSamples() == list(range(frames))
        assert attr.Get(frames - 1)[0] == pytest.approx((frames - 1) / frames, abs=1e-6)


# --- glTF options and the command line --------------------------------------------------------------
def test_gltf_units_and_up_options(tmp_path, sample_rig):
    export_rig(sample_rig, tmp_path / "mm_z.glb", units="mm", up="z")
    verts, *_ = reference_mesh(tmp_path / "mm_z.glb")
    n = sample_rig.neutral * 10  # sample rig: cm -> mm
    assert np.allclose(verts, np.stack([n[:, 0], -n[:, 2], n[:, 1]], axis=1), atol=1e-3)
    with pytest.raises(RigInputError, match="up axis 'x'"):
        export_rig(sample_rig, tmp_path / "x.glb", up="x")
    with pytest.raises(RigInputError, match=r"unknown export format '\.fbx'"):
        export_rig(sample_rig, tmp_path / "x.fbx")
    with pytest.raises(RigInputError, match="an OBJ holds one surface"):
        export_rig(sample_rig, tmp_path / "x.obj", animation=WeightAnimation([0.0], np.zeros((1, sample_rig.n_shapes))))


def test_cli_export_glb_with_animation_from_a_weights_csv(tmp_path, sample_rig):
    from model.weights_csv import write_weights_csv
    from resources.sample_rig import write_sample
    folder = write_sample(tmp_path / "rig")
    rig = load_rig(folder)
    W = np.clip(np.sin(np.arange(12)[:, None] * 0.4 + np.arange(rig.n_shapes)), 0, 1)
    write_weights_csv(tmp_path / "take.csv", W[:, ::-1], rig.shape_names[::-1], rate=24)  # any column order
    out = tmp_path / "anim.glb"
    proc = run_cli("export", folder, "-o", out, "--animation", tmp_path / "take.csv", "--weights",
                   f"{rig.shape_names[0]}=0.5", "--out-units", "cm")
    assert "12 frames" in proc.stdout
    verts, _, names, deltas = reference_mesh(out)
    times, played = reference_animation(out)
    assert names == rig.shape_names and np.allclose(times, np.arange(12) / 24)
    for f in range(12):
        assert np.abs(verts + played[f] @ deltas.reshape(len(names), -1).reshape(len(names), -1, 3).transpose(1, 0, 2)
                      - dense(rig, W[f])).max() < 1e-5
    doc, _, _ = read_gltf_file(out)
    assert doc["meshes"][0]["weights"][0] == 0.5
    bad = run_cli("export", folder, "-o", tmp_path / "x.glb", "--animation", tmp_path / "nope.csv", check=False)
    assert bad.returncode == 2 and "nope.csv: does not exist" in bad.stderr


# --- OBJ: the source's UVs, normals and groups ------------------------------------------------------
def test_obj_export_says_smooth_only_where_the_source_says_nothing_of_shading(sample_rig, tmp_path):
    """An OBJ export adds a smoothing group ("s 1") only when the file would otherwise say nothing of its shading:
    the source's own "s" records are kept as they are, and a rest pose written with the source's normals needs
    none."""
    import dataclasses

    from model.rig import CornerAttributes
    rig = sample_rig.copy()
    rig.corners = CornerAttributes()
    export_rig(rig, tmp_path / "plain.obj")
    assert read_obj(tmp_path / "plain.obj").corners.records == [(0, "s 1")]
    rig.corners = CornerAttributes(records=[(0, "g face"), (3, "s off")])
    export_rig(rig, tmp_path / "said.obj", rig.weights_from_dict({"jawOpen": 0.5}))
    assert read_obj(tmp_path / "said.obj").corners.records == [(0, "g face"), (3, "s off")]
    n = np.tile([0.0, 0.0, 1.0], (rig.face_indices.size, 1))
    rig.corners = dataclasses.replace(CornerAttributes(), normals=n, corner_normal=np.arange(rig.face_indices.size))
    export_rig(rig, tmp_path / "normals.obj")                       # the rest pose: the source's normals
    back = read_obj(tmp_path / "normals.obj").corners
    assert back.records == [] and back.normals is not None
    export_rig(rig, tmp_path / "posed.obj", rig.weights_from_dict({"jawOpen": 0.5}))   # posed: none, smooth
    back = read_obj(tmp_path / "posed.obj").corners
    assert back.records == [(0, "s 1")] and back.normals is None


def test_ict_obj_export_keeps_uvs_and_materials(ict_dir, tmp_path):
    src = read_obj(ict_dir / "generic_neutral_mesh.obj")
    run_cli("export", ict_dir, "-o", tmp_path / "neutral.obj")
    back = read_obj(tmp_path / "neutral.obj")
    assert len(back.vertices) == 26719  # not re-indexed at UV seams
    assert np.allclose(back.vertices, src.vertices, atol=1e-6)
    assert np.array_equal(back.face_indices, src.face_indices) and np.array_equal(back.face_counts, src.face_counts)
    assert np.allclose(back.corners.uvs, src.corners.uvs, atol=1e-6)
    assert np.array_equal(back.corners.corner_uv, src.corners.corner_uv)
    # the records as in the source, the material library named by the one written beside the export, and a smoothing
    # group before the first face (ICT's OBJ has no "s" record and no normals: importers would shade it flat)
    kept = [r for r in src.corners.records if not r[1].startswith("mtllib")]
    assert not any(line.startswith("s ") for _, line in kept)
    assert back.corners.records == ([(0, "mtllib neutral.mtl")] + [r for r in kept if r[0] <= 0] + [(0, "s 1")]
                                    + [r for r in kept if r[0] > 0])
    assert (tmp_path / "neutral.mtl").is_file()
    assert [r for r in src.corners.records if r[1].startswith("usemtl")][2] == (14034, "usemtl M_GumsTongue")


def test_obj_round_trip_of_normals_groups_and_mixed_corners(tmp_path):
    from model.readers import load_obj_folder
    from model.export import write_posed_obj
    text = ("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\n"
            "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 0 -1\n"
            "o body\ng front\nusemtl a\ns 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n"
            "g back\nusemtl b\ns off\nf 2//2 5//2 3//2\nf -3/-1/-1 -2/-2/-1 -1/-3/-1\n")
    folder = tmp_path / "rig"
    folder.mkdir()
    (folder / "neutral.obj").write_text(text)
    (folder / "lift.obj").write_text(text.replace("v 2 0 0", "v 2 0 0.5"))
    rig = load_obj_folder(folder)
    c = rig.corners
    assert c.corner_uv.tolist() == [0, 1, 2, 3, -1, -1, -1, 3, 2, 1]
    assert c.corner_normal.tolist() == [0, 0, 0, 0, 1, 1, 1, 1, 1, 1]
    assert [r[0] for r in c.records] == [0, 0, 0, 0, 0, 1, 1, 1] and c.records[-1] == (1, "s off")
    write_posed_obj(rig, tmp_path / "rest.obj")
    back = read_obj(tmp_path / "rest.obj").corners
    for key in ("uvs", "corner_uv", "normals", "corner_normal"):
        assert np.array_equal(getattr(back, key), getattr(c, key)), key
    assert back.records == c.records
    write_posed_obj(rig, tmp_path / "posed.obj", np.array([1.0]))
    posed = read_obj(tmp_path / "posed.obj")
    assert posed.vertices[4].tolist() == [2, 0, 0.5] and posed.corners.normals is None  # rest normals dropped
    assert np.array_equal(posed.corners.corner_uv, c.corner_uv)


def test_bad_vt_index_is_one_sentence(tmp_path):
    p = tmp_path / "bad.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n")
    with pytest.raises(RigInputError, match=r"bad\.obj: a face refers to texture coordinate 2, but the file has 1"):
        read_obj(p)


# --- permissions: the user's umask ------------------------------------------------------------------
@pytest.mark.parametrize("mask", [0o022, 0o002])
def test_files_get_the_users_umask(tmp_path, sample_rig, mask):
    from model.project import Project, save_project
    old = os.umask(mask)
    try:
        written = [export_rig(sample_rig, tmp_path / "a.glb"), export_rig(sample_rig, tmp_path / "a.usda"),
                   export_rig(sample_rig, tmp_path / "a.obj")]
        save_project(Project(rig=sample_rig), tmp_path / "a.bsproj")
        written.append(tmp_path / "a.bsproj")
        run_cli("export", tmp_path / "a.bsproj", "-o", tmp_path / "cli.gltf")  # the CLI inherits the umask
        written.append(tmp_path / "cli.gltf")
    finally:
        os.umask(old)
    for p in written:
        assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~mask, p
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary files left behind


# --- a real client: Blender (optional) ----------------------------------------------------------------
BLENDER_SCRIPT = r"""
import bpy, json, sys
out = {}
for kind, path in (("glb", sys.argv[-2]), ("obj", sys.argv[-1])):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if kind == "glb":
        bpy.ops.import_scene.gltf(filepath=path)
    elif hasattr(bpy.ops.wm, "obj_import"):
        bpy.ops.wm.obj_import(filepath=path)
    else:
        bpy.ops.import_scene.obj(filepath=path, split_mode="OFF")
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    o = max(meshes, key=lambda o: len(o.data.vertices))
    keys = o.data.shape_keys
    action = keys.animation_data.action if keys and keys.animation_data else None
    out[kind] = {"vertices": len(o.data.vertices), "polygons": len(o.data.polygons),
                 "smooth": sum(p.use_smooth for p in o.data.polygons),
                 "shape_keys": [k.name for k in keys.key_blocks] if keys else [],
                 "frame_range": list(action.frame_range) if action else None,
                 "uv_layers": len(o.data.uv_layers), "materials": len(o.data.materials),
                 "fps": bpy.context.scene.render.fps / bpy.context.scene.render.fps_base}
    # each material's faces and the base colour its importer gave it
    used = [0] * max(1, len(o.data.materials))
    for p in o.data.polygons:
        used[p.material_index] += 1
    out[kind]["material_faces"] = {m.name: [n, list(m.diffuse_color)[:3]] for m, n in zip(o.data.materials, used) if m}
print("BLENDER_RESULT " + json.dumps(out))
"""


@pytest.fixture
def blender() -> str:
    """The ``blender`` executable (run headless: ``blender -b``); the test skips where it is not installed."""
    path = shutil.which("blender")
    if not path:
        pytest.skip("blender is not installed")
    return path


def test_blender_imports_the_glb_and_the_obj(blender, exported, rig_with_corrective, ict_dir, tmp_path):
    (tmp_path / "script.py").write_text(BLENDER_SCRIPT)
    run_cli("export", ict_dir, "-o", tmp_path / "neutral.obj")
    proc = subprocess.run([blender, "-b", "--factory-startup", "--python", str(tmp_path / "script.py"), "--",
                           str(exported[0][".glb"]), str(tmp_path / "neutral.obj")],
                          capture_output=True, text=True, timeout=900)
    line = next((l for l in proc.stdout.splitlines() if l.startswith("BLENDER_RESULT ")), None)
    assert line, proc.stdout[-2000:] + proc.stderr[-2000:]
    seen = json.loads(line[len("BLENDER_RESULT "):])
    print(seen)
    glb = seen["glb"]
    assert glb["shape_keys"][1:] == rig_with_corrective.shape_names + [rig_with_corrective.correctives[0].name]
    # Blender keys the animation in its scene's frames (24 fps by default): 327 / 60 s of performance
    span = (glb["frame_range"][1] - glb["frame_range"][0]) / glb["fps"]
    assert span == pytest.approx(327 / 60, abs=1.5 / glb["fps"])
    assert glb["polygons"] == len(rig_with_corrective.triangles())
    assert glb["smooth"] == glb["polygons"]       # shaded smooth from the file's normals (without them: all flat)
    assert seen["obj"]["vertices"] == 26719 and seen["obj"]["uv_layers"] == 1 and seen["obj"]["materials"] == 12
    assert seen["obj"]["smooth"] == seen["obj"]["polygons"]   # ICT's OBJ says nothing of smoothing: written "s 1"
    # the OBJ's material library, written beside it: each part's faces in its MTL colour
    faces = Counter(material_of_each_face(ict_dir / "generic_neutral_mesh.obj"))
    kd = mtl_kd(ict_dir / "ICTFaceModelMaterial.mtl")
    got = seen["obj"]["material_faces"]
    assert {n: f for n, (f, _) in got.items()} == dict(faces)
    assert all(rgb == pytest.approx(kd[n], abs=1e-6) for n, (_, rgb) in got.items()), got


BLENDER_PLAY_SCRIPT = r"""
import array, bpy, json, os, sys
# argv after "--": output folder, then "glb" PATH FRAME... or "obj+pc2" OBJ PC2 FRAME...
out, kind, *rest = sys.argv[sys.argv.index("--") + 1:]
bpy.ops.wm.read_factory_settings(use_empty=True)
if kind == "glb":
    path, frames = rest[0], rest[1:]
    bpy.ops.import_scene.gltf(filepath=path)
else:
    path, cache, frames = rest[0], rest[1], rest[2:]
    if hasattr(bpy.ops.wm, "obj_import"):
        bpy.ops.wm.obj_import(filepath=path)
    else:
        bpy.ops.import_scene.obj(filepath=path, split_mode="OFF")
o = max((o for o in bpy.data.objects if o.type == "MESH"), key=lambda o: len(o.data.vertices))
if kind != "glb":               # as a user plays a point cache: a Mesh Cache modifier with its defaults
    mod = o.modifiers.new("cache", "MESH_CACHE")
    mod.cache_format = "PC2"
    mod.filepath = cache


def write(name, mesh):
    co = array.array("f", [0.0]) * (3 * len(mesh.vertices))
    mesh.vertices.foreach_get("co", co)
    with open(os.path.join(out, name + ".f32"), "wb") as f:
        f.write(co.tobytes())


write("rest", o.data)
for frame in frames:
    bpy.context.scene.frame_set(int(frame))
    evaluated = o.evaluated_get(bpy.context.evaluated_depsgraph_get())
    write(frame, evaluated.to_mesh())
    evaluated.to_mesh_clear()
print("BLENDER_FPS", bpy.context.scene.render.fps / bpy.context.scene.render.fps_base)
"""


def _blender_play(blender, tmp_path, kind: str, files: list, frames: list[int]) -> tuple[dict, float]:
    """Blender's surfaces (mesh coordinates, deformed) at scene ``frames``, and its scene's frame rate."""
    script, out = tmp_path / "play.py", tmp_path / kind
    script.write_text(BLENDER_PLAY_SCRIPT)
    out.mkdir()
    proc = subprocess.run([blender, "-b", "--factory-startup", "--python", str(script), "--", str(out), kind,
                           *map(str, files), *map(str, frames)], capture_output=True, text=True, timeout=900)
    fps = next((float(l.split()[1]) for l in proc.stdout.splitlines() if l.startswith("BLENDER_FPS ")), None)
    assert fps, proc.stdout[-2000:] + proc.stderr[-2000:]
    return {name: np.fromfile(out / f"{name}.f32", np.float32).reshape(-1, 3).astype(np.float64)
            for name in ["rest", *map(str, frames)]}, fps


def test_blender_plays_the_glb_animation_as_the_application_poses_it(blender, exported, rig_with_corrective,
                                                                       performance, tmp_path):
    """The Live Link Face performance in the .glb, played by Blender's glTF importer: at a frame of the performance,
    Blender's deformed mesh is the application's pose of that frame's weights, corrective included (in Blender's
    axes and metres: the map is fitted on the rest surface alone, and must be exact there)."""
    rig = rig_with_corrective
    ks = [100, 200, 250]          # performance frames (60 fps) that fall on Blender's whole frames (24 fps)
    seen, fps = _blender_play(blender, tmp_path, "glb", [exported[0][".glb"]], [round(k * 24 / 60) for k in ks])
    assert fps == 24.0
    rest = seen.pop("rest")
    # Blender's axes and units, fitted on the rest surface: metres, and glTF's +Y up turned to Blender's +Z up
    X = np.c_[rig.neutral, np.ones(rig.n_vertices)]
    A, *_ = np.linalg.lstsq(X, rest, rcond=None)
    np.testing.assert_allclose(A, 0.01 * np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0], [0, 0, 0]]), atol=1e-9)
    assert np.abs(X @ A - rest).max() < 1e-6
    for k in ks:
        expected = np.c_[dense(rig, performance.weights[k]), np.ones(rig.n_vertices)] @ A
        played = seen[str(round(k * 24 / 60))]
        assert np.abs(played - rest).max() * 100 > 0.3              # the face moved (cm)
        assert np.abs(played - expected).max() * 100 < 1e-4, k      # as the application poses it (cm)


def test_blender_plays_the_pc2_cache_on_the_obj_as_the_application_solved_it(blender, ict_dir, take_dir, tmp_path):
    """``solve --cache``'s PC2 on ``export``'s OBJ, played in Blender with a Mesh Cache modifier left at its
    defaults: every vertex of a frame where the solve put it (vertex order, frame numbering, units)."""
    from model.pc2 import read_pc2
    run_cli("export", ict_dir, "-o", tmp_path / "neutral.obj")
    run_cli("solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json",
            "-o", tmp_path / "w.csv", "--cache", tmp_path / "take.pc2")
    frames, _, _ = read_pc2(tmp_path / "take.pc2")
    seen, _ = _blender_play(blender, tmp_path, "obj+pc2", [tmp_path / "neutral.obj", tmp_path / "take.pc2"],
                            [0, 180, len(frames) - 1])
    assert np.abs(seen.pop("rest") - load_rig(ict_dir).neutral).max() < 1e-5
    for f, played in seen.items():
        np.testing.assert_array_equal(played, frames[int(f)].astype(np.float64))
    assert np.abs(seen["180"] - seen["0"]).max() > 0.2            # the frames differ (cm)


def test_keyframes_are_sampled_at_every_frame(tmp_path, sample_rig):
    from model.export import animation_from_timeline
    from model.keyframes import Keyframe, Timeline
    K = sample_rig.n_shapes
    timeline = Timeline([Keyframe(0.5, np.zeros(K)), Keyframe(1.0, np.full(K, 0.8)), Keyframe(1.5, np.zeros(K))],
                        interpolation="smooth")
    anim = animation_from_timeline(timeline, rate=24)
    assert anim.n_frames == 25 and np.allclose(anim.times, np.arange(25) / 24)
    assert np.allclose(anim.weights[12], 0.8) and np.allclose(anim.weights[6], timeline.evaluate(0.75))
    export_rig(sample_rig, tmp_path / "keys.glb", animation=anim)
    times, W = reference_animation(tmp_path / "keys.glb")
    assert np.allclose(times, anim.times, atol=1e-6) and np.allclose(W[:, :K], anim.weights, atol=1e-6)


@pytest.mark.parametrize("suffix, most", [(".glb", 1.6), (".usdc", 0.9)])
def test_an_export_holds_no_second_copy_of_the_rigs_deltas(ict_dir, tmp_path, suffix, most):
    """A studio rig's export must fit beside the rig: its shapes' offsets are made a shape at a time as the writer
    takes them (``model.export.ShapeDeltas``) and a .glb is written a buffer view at a time. The peak of what the
    export allocates, over ICT's deltas (35 MB): a .glb holds its own bytes (~1.2x) once, a .usdc less; one more
    copy of the deltas is 1x more (the code before: 3.6x and 2.2x)."""
    import tracemalloc
    rig = load_rig(ict_dir)
    tracemalloc.start()
    try:
        export_rig(rig, tmp_path / f"ict{suffix}")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < most * rig.deltas.nbytes, peak / rig.deltas.nbytes
