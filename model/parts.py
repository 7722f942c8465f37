"""A rig's parts: its faces grouped by material, each material's colour, and which parts a view hides.

An OBJ names a material before its faces (``usemtl M_Face``) and the library of materials it uses
(``mtllib ICTFaceModelMaterial.mtl``, a file beside it whose ``Kd r g b`` is each material's diffuse colour); a
glTF gives each primitive a material with a ``baseColorFactor``. ``Rig.corners.records`` keeps the ``usemtl``
lines with the face they come before, and ``Rig.materials`` the colours by name, so a view can draw each part in
its own colour -- teeth white, gums red, irises dark -- as a DCC shows the file.

Face rigs also carry helper shells: thin surfaces laid over the eyes and along the lids that their renderer draws
translucent, for the shadow of the lids on the eyeball and the wet line of the lid (ICT FaceKit's
``M_EyeOcclusion``, ``M_EyeBlend`` and ``M_LacrimalFluid``; a MetaHuman's ``eyeshell``, ``eyeEdge`` and
``cartilage``). Drawn opaque, as a plain viewport draws everything, they cover the eyeballs and the eyes read as
closed lids. ``default_hidden`` names them; a view leaves their faces out (never their vertices: vertex order is
sacred, and shapes still move them).

The MTL file is read only when it is a plain file name beside the OBJ that names it (never a path elsewhere),
and problems with it never stop the rig loading: the colours are left out with one sentence saying why.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import RigInputError, shown

MAX_MTL_BYTES = 4 * 2**20        # a material library is a few kB; a DCC's with many materials a few hundred
# helper shells by the names the face rigs we know give them (ICT FaceKit, MetaHuman, Character Creator)
HELPER_SHELL = re.compile(r"occlusion|lacrimal|eye_?blend|tear_?line|eye_?shell|eye_?edge|cartilage|meniscus",
                          re.IGNORECASE)


@dataclass
class Parts:
    """names       the materials in the order their faces first come (a face before any has part -1).
    face_part   (F,) int32: each face's part, an index into ``names`` or -1.
    colors      (M, 3) float32 in [0, 1]; NaN rows: the file gives that material no colour."""

    names: list[str]
    face_part: np.ndarray
    colors: np.ndarray

    def faces(self, name: str) -> np.ndarray:
        """The face indices of part ``name``."""
        return np.flatnonzero(self.face_part == self.names.index(name))


def rig_parts(rig) -> Parts | None:
    """The rig's parts from its ``usemtl`` records (``Rig.corners``) and colours (``Rig.materials``); None when
    its faces name no material (one part: nothing to tell apart or hide)."""
    records = rig.corners.records if rig.corners is not None else []
    marks = [(int(f), line.split(None, 1)[1].strip()) for f, line in records
             if line.startswith("usemtl") and len(line.split(None, 1)) == 2]
    if not marks:
        return None
    n_faces = int(rig.face_counts.size)
    names: list[str] = []
    face_part = np.full(n_faces, -1, dtype=np.int32)
    for i, (start, name) in enumerate(marks):
        end = marks[i + 1][0] if i + 1 < len(marks) else n_faces
        if name not in names:
            names.append(name)
        face_part[max(0, start):max(0, min(end, n_faces))] = names.index(name)
    used = [n for k, n in enumerate(names) if (face_part == k).any()]
    if len(used) < 2 and not (face_part < 0).any() and not any(n in rig.materials for n in used):
        return None
    if used != names:     # a usemtl with no face after it: not a part
        remap = np.array([used.index(n) if n in used else -1 for n in names] + [-1], dtype=np.int32)
        face_part = remap[face_part]
        names = used
    colors = np.array([rig.materials.get(n, (np.nan,) * 3) for n in names], dtype=np.float32).reshape(-1, 3)
    return Parts(names, face_part, colors)


def default_hidden(names: list[str]) -> list[str]:
    """The parts a view hides until the user shows them: the helper shells (see the module's text)."""
    return [n for n in names if HELPER_SHELL.search(n)]


def checked_hidden(parts: Parts | None, names: list[str], where: str = "--hide") -> list[str]:
    """``names`` if each is a part of the rig and one part at least stays shown; else RigInputError."""
    known = parts.names if parts is not None else []
    unknown = [n for n in names if n not in known]
    if unknown:
        have = f"its parts are {shown(', '.join(known), 300)}" if known else "its faces name no materials"
        raise RigInputError(f"{where}: the rig has no part named {shown(', '.join(unknown), 80)} ({have}).")
    if known and set(names) >= set(known):
        raise RigInputError(f"{where}: hides every part of the rig; one at least must stay shown.")
    return list(names)


def shown_faces(parts: Parts | None, hidden) -> np.ndarray | None:
    """The face indices a view draws with the parts named in ``hidden`` left out; None: every face."""
    if parts is None:
        return None
    off = [k for k, n in enumerate(parts.names) if n in set(hidden)]
    if not off:
        return None
    return np.flatnonzero(~np.isin(parts.face_part, off)).astype(np.int64)


def drawn_faces(rig, hidden: list[str] | None = None, parts: Parts | None | bool = False):
    """(faces or None, counts, indices): the polygons a picture of ``rig`` draws with the parts ``hidden`` left
    out (default: ``default_hidden``), as ``shown_faces`` and ``subset_faces`` give them (``render``, batch
    previews). ``parts``: the rig's ``rig_parts`` when the caller has them."""
    parts = rig_parts(rig) if parts is False else parts
    if hidden is None:
        hidden = default_hidden(parts.names) if parts is not None else []
    faces = shown_faces(parts, hidden)
    return (faces, *subset_faces(rig.face_counts, rig.face_indices, faces))


def subset_faces(face_counts: np.ndarray, face_indices: np.ndarray, faces: np.ndarray | None):
    """(counts, indices) of the polygons ``faces`` (indices into the rig's faces, in order); all when None."""
    if faces is None:
        return face_counts, face_indices
    counts = np.asarray(face_counts, dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    n = counts[faces]
    corner = np.repeat(starts[faces], n) + (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n))
    return np.asarray(face_counts)[faces], np.asarray(face_indices)[corner]


def vertex_colors(parts: Parts | None, face_counts: np.ndarray, face_indices: np.ndarray, n_vertices: int,
                  fallback: tuple[float, float, float]) -> np.ndarray | None:
    """(V, 3) uint8: each vertex in the colour of the part of a face it belongs to (``fallback`` for a part
    without one); None when no part has a colour of its own (the view's one surface colour then)."""
    if parts is None or np.isnan(parts.colors).all():
        return None
    table = np.where(np.isnan(parts.colors), np.asarray(fallback, np.float32), parts.colors)
    table = np.vstack([table, np.asarray(fallback, np.float32)])            # part -1: the fallback
    rgb = np.round(np.clip(table, 0.0, 1.0) * 255).astype(np.uint8)
    part_of_corner = np.repeat(parts.face_part, np.asarray(face_counts, dtype=np.int64))
    out = np.empty((n_vertices, 3), dtype=np.uint8)
    out[:] = rgb[-1]
    out[np.asarray(face_indices)] = rgb[part_of_corner]
    return out


def read_mtl(path: Path) -> tuple[dict[str, tuple[float, float, float]], str | None]:
    """({material: Kd (r, g, b) in [0, 1]}, None) from a Wavefront material library, or ({}, one sentence) when
    it cannot be used. A material without a usable ``Kd`` is left out (its part takes the view's colour)."""
    try:
        if not path.is_file():
            return {}, f"{path}: the material library the OBJ names is not there; its parts keep one colour."
        if path.stat().st_size > MAX_MTL_BYTES:
            return {}, f"{path}: the material library is over {MAX_MTL_BYTES >> 20} MB; its colours are left out."
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        return {}, f"{path}: the material library is not UTF-8 text; its colours are left out."
    except OSError as exc:
        return {}, f"{path}: the material library cannot be read ({exc.strerror or exc}); its colours are left out."
    out: dict[str, tuple[float, float, float]] = {}
    name = None
    for line in text.splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "newmtl":
            name = line.strip()[len("newmtl"):].strip() or None
        elif words[0] == "Kd" and name is not None and len(words) >= 2:
            try:
                rgb = [float(w) for w in words[1:4]]
            except ValueError:
                continue
            rgb = (rgb * 3)[:3] if len(rgb) == 1 else rgb      # "Kd 0.5" is grey
            if len(rgb) == 3 and all(np.isfinite(rgb)):
                out[name] = tuple(float(min(1.0, max(0.0, c))) for c in rgb)
    return out, None


def mtl_bytes(names: list[str], colors: dict, title: str) -> bytes:
    """A Wavefront material library, as bytes: ``newmtl`` for each of ``names``, with ``Kd`` where ``colors`` has
    one (what ``read_mtl`` reads back)."""
    lines = [f"# Blendshape Studio materials of {title}"]
    for name in names:
        lines.append(f"newmtl {name}")
        if name in colors:
            lines.append("Kd " + " ".join(f"{c:.6f}" for c in colors[name]))
    return ("\n".join(lines) + "\n").encode("utf-8")


def obj_materials(obj_path: Path, records: list[tuple[int, str]]) -> tuple[dict, list[str]]:
    """The colours of the materials an OBJ's ``mtllib`` records name (files beside ``obj_path`` only), and one
    sentence per library that could not be used."""
    colors: dict[str, tuple[float, float, float]] = {}
    notes: list[str] = []
    folder = obj_path.parent
    for _, line in records:
        if not line.startswith("mtllib"):
            continue
        for name in line.split()[1:]:
            lib = folder / name
            try:
                beside = lib.resolve().parent == folder.resolve()
            except (OSError, RuntimeError):
                beside = False
            if not beside or Path(name).name != name:
                notes.append(f"{obj_path}: names the material library '{shown(name, 60)}' outside its folder; "
                             "it is not read.")
                continue
            found, problem = read_mtl(lib)
            colors.update(found)
            if problem:
                notes.append(problem)
    return colors, notes
