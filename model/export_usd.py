"""USD writer (``.usda`` text, ``.usdc``/``.usd`` crate) with usd-core's ``pxr``: UsdSkel blend shapes.

The content is ``model.export.ExportContent``, the same as the glTF export: a ``SkelRoot`` (the default
prim) holding a ``Skeleton`` with one root joint and a ``Mesh`` (the rig's polygons as in the file, not
triangulated) bound to it through ``UsdSkelBindingAPI`` (every vertex fully on the root joint), one
``BlendShape`` per shape and corrective (offsets and point indices of the vertices it moves), and a
``SkelAnimation`` (the skeleton's animation source) with the blend shape names and their weights: the
current pose as the default value and, with an animation, one time sample per frame (time codes are
frames at ``timeCodesPerSecond``, the animation's frame rate; uneven times keep their exact seconds).
Stage metadata: ``upAxis`` and ``metersPerUnit`` from the export's ``up`` and ``units``. When the source
OBJ's UVs are on the rig and every corner has one, they are written as the face-varying primvar ``st``.
Blend shape prims need identifier names: a name like ``browInnerUp_L+browInnerUp_R`` is made valid
(``browInnerUp_L_browInnerUp_R``) and the original kept in the prim's ``customData`` (``name``).
A rig whose faces name materials (``model.parts``: an OBJ's ``usemtl``, a glTF's primitive materials) gets one
``UsdShade.Material`` per part under ``/Root/Materials`` (a ``UsdPreviewSurface``, its ``diffuseColor`` the
material's colour where the file gave one) bound to the part's faces through a ``GeomSubset`` of the mesh's
``materialBind`` family, as Maya's and Houdini's USD exports bind per-face materials: the vertices and faces
are untouched, so vertex order survives, and a DCC gets one material slot per part.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .atomic import atomic_write
from .errors import RigInputError
from .rig import UNIT_IN_METRES


def _pxr():
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt
    except ImportError:
        raise RigInputError("Writing USD needs the usd-core package (pip install usd-core).") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt


def usd_names(names: list[str]) -> list[str]:
    """Unique USD identifiers for blend shape names (prim names and the tokens that bind them)."""
    from pxr import Tf
    out, taken = [], set()
    for n in names:
        base = Tf.MakeValidIdentifier(n)
        ident, i = base, 2
        while ident in taken:
            ident, i = f"{base}_{i}", i + 1
        taken.add(ident)
        out.append(ident)
    return out


def frame_rate(times: np.ndarray) -> tuple[float, bool]:
    """(frames per second, evenly spaced) of per-frame times; (24, True) for one frame. Evenly spaced times (to a
    tenth of a frame: times rounded to milliseconds or printf's 6 decimals) have the weights CSV take's rate
    (``model.weights_csv.times_rate``: 1/24 s written 0.041667 is 24 fps, not 23.9998); others the median step."""
    from .weights_csv import times_rate
    times = np.asarray(times, dtype=np.float64)
    if times.size < 2:
        return 24.0, True
    rate = times_rate(times)
    if rate is not None:
        return rate, True
    rate = float(1.0 / np.median(np.diff(times)))
    return (float(round(rate)) if abs(rate - round(rate)) < 1e-6 * rate else rate), False


def usd_stage(content, corners=None):
    """An in-memory stage holding ``content`` (an ``ExportContent``); ``corners`` adds UVs (see above)."""
    Gf, Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt = _pxr()
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if content.up == "z" else UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, UNIT_IN_METRES[content.units])
    root = UsdSkel.Root.Define(stage, "/Root")
    stage.SetDefaultPrim(root.GetPrim())
    skel = UsdSkel.Skeleton.Define(stage, "/Root/Skeleton")
    skel.CreateJointsAttr(["root"])
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))

    mesh = UsdGeom.Mesh.Define(stage, "/Root/" + Tf.MakeValidIdentifier(content.name))
    points = np.ascontiguousarray(content.neutral, dtype=np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points))
    mesh.CreateFaceVertexCountsAttr(_ints(content.face_counts))
    mesh.CreateFaceVertexIndicesAttr(_ints(content.face_indices))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    # The extent covers every pose the blend shapes can reach at weights in [0, 1].
    down, up = np.zeros(points.shape), np.zeros(points.shape)   # summed a shape at a time: no (K, V, 3) temporaries
    for d in content.deltas:
        down += np.minimum(d, 0)
        up += np.maximum(d, 0)
    reach = points + down, points + up
    lo = np.minimum(points.min(axis=0), reach[0].min(axis=0)) if len(points) else np.zeros(3)
    hi = np.maximum(points.max(axis=0), reach[1].max(axis=0)) if len(points) else np.zeros(3)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]))
    if corners is not None and corners.uvs is not None and corners.corner_uv is not None \
            and corners.corner_uv.size and corners.corner_uv.min() >= 0:
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                     UsdGeom.Tokens.faceVarying)
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(corners.uvs[:, :2], dtype=np.float32)))
        st.SetIndices(_ints(corners.corner_uv))

    if content.parts is not None:
        _bind_part_materials(stage, mesh, content.parts)

    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([0]))
    binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    idents = usd_names(content.names)
    targets = []
    for name, ident, d in zip(content.names, idents, content.deltas):
        moved = np.flatnonzero(np.abs(d).max(axis=1) > 0).astype(np.int32)
        shape = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(ident))
        shape.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(d[moved], dtype=np.float32)))
        shape.CreatePointIndicesAttr(_ints(moved))
        if name != ident:
            shape.GetPrim().SetCustomDataByKey("name", name)
        targets.append(shape.GetPath())
    binding.CreateBlendShapesAttr(idents)
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)

    anim = UsdSkel.Animation.Define(stage, skel.GetPath().AppendChild("Animation"))
    anim.CreateJointsAttr(["root"])
    anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0.0)]))
    anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1.0)]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1.0)]))
    anim.CreateBlendShapesAttr(idents)
    weights = anim.CreateBlendShapeWeightsAttr()
    weights.Set(Vt.FloatArray.FromNumpy(np.asarray(content.pose, dtype=np.float32)))
    if content.times is not None:
        rate, even = frame_rate(content.times)
        # evenly spaced: one frame apart from the first (not 1.000008 for a time written 0.041667); uneven times
        # keep their own
        codes = content.times[0] * rate + np.arange(content.times.size) if even else content.times * rate
        whole = np.round(codes)
        codes = np.where(np.abs(codes - whole) < 1e-6, whole, codes)  # frame numbers, not 1.0000000000000036
        stage.SetTimeCodesPerSecond(rate)
        stage.SetFramesPerSecond(rate)
        stage.SetStartTimeCode(float(codes[0]))
        stage.SetEndTimeCode(float(codes[-1]))
        frames = np.asarray(content.frames, dtype=np.float32)
        for code, w in zip(codes.tolist(), frames):
            weights.Set(Vt.FloatArray.FromNumpy(w), Usd.TimeCode(code))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    return stage


def _bind_part_materials(stage, mesh, parts) -> None:
    """One material per part, bound to its faces by a ``materialBind`` GeomSubset (module docstring)."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade
    UsdGeom.Scope.Define(stage, "/Root/Materials")
    idents = usd_names(parts.names)
    api = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    for k, (name, ident) in enumerate(zip(parts.names, idents)):
        material = UsdShade.Material.Define(stage, f"/Root/Materials/{ident}")
        shader = UsdShade.Shader.Define(stage, material.GetPath().AppendChild("PreviewSurface"))
        shader.CreateIdAttr("UsdPreviewSurface")
        if not np.isnan(parts.colors[k]).any():
            shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*map(float, parts.colors[k])))
        shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
        material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        if name != ident:
            material.GetPrim().SetCustomDataByKey("name", name)
        faces = np.flatnonzero(parts.face_part == k).astype(np.int32)
        subset = api.CreateMaterialBindSubset(ident, _ints(faces), UsdGeom.Tokens.face)
        UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(material)
    # every face in a part: a partition of the mesh's faces; faces before any usemtl stay unbound
    api.SetMaterialBindSubsetsFamilyType(UsdGeom.Tokens.partition if (parts.face_part >= 0).all()
                                         else UsdGeom.Tokens.nonOverlapping)


def _ints(values: np.ndarray):
    """A ``VtIntArray`` of ``values``."""
    from pxr import Vt
    return Vt.IntArray.FromNumpy(np.ascontiguousarray(values, dtype=np.int32))


def write_usd_content(content, path: str | Path, corners=None) -> None:
    """Write an ``ExportContent`` as ``.usda`` (text) or ``.usdc``/``.usd`` (crate), atomically."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".usd", ".usda", ".usdc"):
        raise RigInputError(f"{path}: write USD to a .usd, .usda or .usdc file.")
    stage = usd_stage(content, corners)
    with tempfile.TemporaryDirectory(prefix="bss-usd-") as tmp:
        out = os.path.join(tmp, "export" + suffix)
        if not stage.GetRootLayer().Export(out):
            raise RigInputError(f"{path}: usd-core could not write the stage.")
        data = Path(out).read_bytes()
    atomic_write(path, data)
