"""The ``.bsproj`` project file: one zip holding a JSON manifest plus ``.npy`` arrays (DESIGN.md).

The rig (neutral, faces, deltas, correctives, presets), the current pose (global, or per region with the
partition of unity of its segmentation level) and one JSON-able section per
feature (segmentation settings, markers, keyframes, takes, solve settings). Arrays are deflated at level 1
(ICT FaceKit: 38 MB stored, 8 MB deflated; saving about 0.5 s, reopening about 0.25 s, where level 6 saves
only another 1 MB for three times the saving time). Older uncompressed projects open as before.
Saved atomically (model.atomic): a crash mid-save leaves the previous file intact.
"""
from __future__ import annotations

import io
import json
import tokenize
import zlib
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from .atomic import atomic_write_with
from .errors import RigInputError, shown
from .input_files import regular_file
from .json_file import MAX_JSON_BYTES, parse_json_text
from .pages import memory_shortfall, small_pages_for
from .rig import MAX_WEIGHT, Rig, finite_range

FORMAT = "blendshape-studio-project"
VERSION = 1
MANIFEST = "manifest.json"


@dataclass
class Project:
    """Everything a user saves: the rig, the current pose and per-feature sections.

    ``sections`` maps a feature name ('segmentation', 'markers', 'keyframes', 'takes', 'solve', ...)
    to JSON-able data; ``arrays`` holds the feature arrays those sections refer to by name.
    """

    rig: Rig
    weights: np.ndarray | None = None
    sections: dict[str, Any] = field(default_factory=dict)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    # A regional current pose (DESIGN.md "Pose"): (R+1, K) weights per region of segmentation level
    # ``region_level``, with that level's (V, R+1) blend; None for a global pose (``weights`` alone).
    region_weights: np.ndarray | None = None
    region_blend: sp.csr_matrix | None = None
    region_level: int | None = None
    # The antagonist pairs the user edited (Rig ▸ Antagonist Pairs…), as (name, name) of the rig's shapes: never both
    # strongly on in a drag solve or a take solve. None: the pairs found from the rig (``model.antagonists``).
    antagonists: list[tuple[str, str]] | None = None

    def __post_init__(self) -> None:
        if self.weights is None:
            self.weights = np.zeros(self.rig.n_shapes)
        self.weights = np.asarray(self.weights, dtype=np.float64)
        if self.weights.shape != (self.rig.n_shapes,):
            raise RigInputError(f"the pose has {self.weights.size} weights for {self.rig.n_shapes} shapes.")
        if not np.isfinite(self.weights).all() or (self.weights.size and np.abs(self.weights).max() > MAX_WEIGHT):
            raise RigInputError(f"the pose holds a weight that is not a number within ±{MAX_WEIGHT:g}.")
        if self.region_weights is not None:
            self.region_weights = np.asarray(self.region_weights, dtype=np.float64)
            self.region_blend = sp.csr_matrix(self.region_blend)
            R1 = self.region_blend.shape[1]
            if self.region_blend.shape[0] != self.rig.n_vertices or self.region_weights.shape != (R1, self.rig.n_shapes):
                raise RigInputError(f"the regional pose ({self.region_weights.shape[0]} regions x "
                                    f"{self.region_weights.shape[-1]} weights, blend {list(self.region_blend.shape)}) "
                                    f"does not fit the rig ({self.rig.n_vertices} vertices, {self.rig.n_shapes} shapes).")
            if (not np.isfinite(self.region_weights).all() or not np.isfinite(self.region_blend.data).all()
                    or np.abs(self.region_weights).max(initial=0) > MAX_WEIGHT):
                raise RigInputError("the regional pose holds NaN or infinite values.")
        if self.antagonists is not None:
            self.antagonists = checked_antagonists(self.antagonists, self.rig.shape_names)

    def antagonist_pairs(self) -> list[tuple[str, str]]:
        """The pairs the solves keep apart: the user's (``antagonists``), else those found from the rig."""
        if self.antagonists is not None:
            return list(self.antagonists)
        from .antagonists import rig_antagonists
        return rig_antagonists(self.rig)


class DetachedEdit:
    """An edit run on a copy of a project away from the one in use, then taken over (``adopt``).

    ``project`` is the copy: its own Project and Rig objects and ``arrays`` dict, sharing every array and value
    with the original. An edit that replaces what it changes (``model.shape_edits``' list edits: every array,
    list and dict they change is a new one) leaves the original as it was, so another thread may run it while
    the original is read and drawn. ``adopt`` then sets on the original (and on its very Rig object, which the
    views and evaluators know) the attributes and arrays the edit replaced, and only those: a few assignments,
    nothing copied, and what changed in the original meanwhile (the pose a playback set) is not put back."""

    def __init__(self, project: Project) -> None:
        self._start = dict(project.__dict__)
        self._rig_start = dict(project.rig.__dict__)
        self._arrays_start = dict(project.arrays)
        rig = object.__new__(type(project.rig))
        rig.__dict__.update(self._rig_start)
        copy = object.__new__(type(project))
        copy.__dict__.update(self._start)
        copy.rig, copy.arrays = rig, dict(self._arrays_start)
        self.project = copy

    def adopt(self, project: Project) -> None:
        """Set on ``project`` what the edit replaced in the copy."""
        edited = self.project
        for name, value in edited.rig.__dict__.items():
            if self._rig_start.get(name, _UNSET) is not value:
                setattr(project.rig, name, value)
        for name, value in edited.__dict__.items():
            if name not in ("rig", "arrays") and self._start.get(name, _UNSET) is not value:
                setattr(project, name, value)
        for key, value in edited.arrays.items():
            if self._arrays_start.get(key, _UNSET) is not value:
                project.arrays[key] = value
        for key in self._arrays_start.keys() - edited.arrays.keys():
            project.arrays.pop(key, None)


_UNSET = object()


MAX_PAIRS = 100_000   # more pairs than any rig's K(K-1)/2 of a few hundred shapes: a damaged file


def checked_antagonists(value, shape_names: list[str]) -> list[tuple[str, str]]:
    """Antagonist pairs as a list of (name, name) of two different shapes of the rig, each pair once; one
    sentence (RigInputError) for anything else (a hand-edited or damaged project)."""
    if not isinstance(value, (list, tuple)) or len(value) > MAX_PAIRS:
        raise RigInputError("the antagonist pairs are not a list of shape-name pairs.")
    names = set(shape_names)
    out, seen = [], set()
    for p in value:
        if (not isinstance(p, (list, tuple)) or len(p) != 2
                or not all(isinstance(n, str) for n in p)):
            raise RigInputError(f"the antagonist pair {shown(p, 60)} is not two shape names.")
        a, b = p
        for n in (a, b):
            if n not in names:
                raise RigInputError(f"the antagonist pair {shown(a, 40)}+{shown(b, 40)} names "
                                    f"{shown(n, 40)}, which the rig does not have.")
        if a == b:
            raise RigInputError(f"the antagonist pair {shown(a, 40)}+{shown(b, 40)} pairs a shape with itself.")
        key = frozenset((a, b))
        if key not in seen:
            seen.add(key)
            out.append((a, b))
    return out


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


ARRAY_DTYPES = ("<f8", "<f4", "<i4", "<i8", "<u4", "<u8", "|b1", "|u1", "<i2", "<u2")


def _read_into(f, buf: memoryview, chunk: int = 16 << 20) -> int:
    """Fill ``buf`` from ``f`` in chunks; returns the bytes read. (A zip member's ``readinto`` reads the whole
    request as one bytes object and then copies it: twice the array's memory at the peak.)"""
    got = 0
    while got < len(buf):
        n = f.readinto(buf[got:got + chunk])
        if not n:
            break
        got += n
    return got


def read_npy_member(z: zipfile.ZipFile, name: str, path: Path, key: str) -> np.ndarray:
    """One ``.npy`` member, checked before anything is allocated: a plain numeric dtype, and the header's
    shape matching the bytes the member holds (so a declared 10¹² elements or a member that inflates far
    beyond its header is refused, never allocated); floats finite."""
    try:
        info = z.getinfo(name)
    except KeyError:
        raise RigInputError(f"{path}: the project is missing the array '{key}'.") from None
    try:
        with z.open(info) as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f, max_header_size=10000)
            elif version in ((2, 0), (3, 0)):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f, max_header_size=10000)
            else:
                raise ValueError(f"npy version {version}")
            if dtype.str not in ARRAY_DTYPES:
                raise RigInputError(f"{path}: the array '{key}' is stored as {shown(dtype, 20)}, not a plain number type.")
            count = 1
            for n in shape:
                count *= int(n)
            nbytes = count * dtype.itemsize
            header = f.tell()
            if header + nbytes != info.file_size:
                raise RigInputError(f"{path}: the array '{key}' declares {count} values but holds "
                                    f"{max(info.file_size - header, 0) // max(dtype.itemsize, 1)}; it is damaged.")
            short = memory_shortfall(nbytes)     # a member that deflates to more than the machine holds
            if short:
                raise RigInputError(f"{path}: the array '{key}' needs {short}.")
            a = np.empty(shape, dtype=dtype, order="F" if fortran else "C")   # read straight into it: one copy
            got = _read_into(f, memoryview(a.reshape(-1, order="A")).cast("B")) if nbytes else 0
            extra = f.read(1)
    except RigInputError:
        raise
    except (ValueError, OSError, zipfile.BadZipFile, EOFError, SyntaxError, TypeError, tokenize.TokenError,
            zlib.error) as exc:
        raise RigInputError(f"{path}: the array '{key}' is damaged ({shown(exc, 80)}).") from None
    if got != nbytes or extra:
        raise RigInputError(f"{path}: the array '{key}' is truncated.")
    if a.dtype.kind == "f" and finite_range(a) is None:
        raise RigInputError(f"{path}: the array '{key}' holds NaN or infinite values.")
    return a


def _shape_settings_entry(rig: Rig, arrays: dict) -> dict:
    """The Shapes list's per-shape settings for the manifest (``rig.shapes``; absent when none, so projects
    without them are written as before): muted, solo, ranges and in-betweens (their offsets as arrays)."""
    entry: dict = {}
    if rig.muted:
        entry["muted"] = list(rig.muted)
    if rig.solo:
        entry["solo"] = list(rig.solo)
    if rig.ranges:
        entry["ranges"] = {n: [float(lo), float(hi)] for n, (lo, hi) in rig.ranges.items()}
    if rig.inbetweens:
        inb, i = {}, 0
        for name, items in rig.inbetweens.items():
            inb[name] = []
            for ib in items:
                key = f"inbetweens/{i}"
                arrays[key] = np.asarray(ib.delta, dtype=np.float64)
                inb[name].append({"weight": float(ib.weight), "array": key})
                i += 1
        entry["inbetweens"] = inb
    return entry


def _read_shape_settings(rig: Rig, entry, array, declared) -> None:
    """Put a manifest's ``rig.shapes`` on ``rig`` (checked by ``Rig.validate``): a wrong type is one sentence."""
    from .rig import Inbetween
    if not isinstance(entry, dict):
        raise RigInputError("the shape settings are not an object.")
    ranges = entry.get("ranges", {})
    inb = entry.get("inbetweens", {})
    if not isinstance(ranges, dict) or not isinstance(inb, dict):
        raise RigInputError("the shape ranges and in-betweens must be objects keyed by shape name.")
    if any(not isinstance(r, list) or len(r) != 2 for r in ranges.values()):
        raise RigInputError("a shape's range is not a [min, max] pair.")
    rig.muted, rig.solo = entry.get("muted", []), entry.get("solo", [])
    rig.ranges = dict(ranges)
    inbetweens = {}
    for name, items in inb.items():
        if not isinstance(items, list) or not all(isinstance(i, dict) and isinstance(i.get("array"), str)
                                                  and i["array"].startswith("inbetweens/") and i["array"] in declared
                                                  for i in items):
            raise RigInputError(f"the in-betweens of {shown(name, 40)} do not name their stored arrays.")
        inbetweens[name] = [Inbetween(weight=i.get("weight"), delta=array(i["array"])) for i in items]
    rig.inbetweens = inbetweens
    rig.validate()


def save_project(project: Project, path: str | Path) -> None:
    """Write the project to ``path`` atomically."""
    atomic_write_with(path, project_writer(project))


def project_writer(project: Project):
    """``writer(file)`` writing the project's ``.bsproj`` bytes into an open file: ``save_project``'s, or one file of
    a set written together (``model.output_set.write_set``: ``personalize``'s project and report)."""
    rig = project.rig
    arrays: dict[str, np.ndarray] = {
        "rig/neutral": rig.neutral,
        "rig/face_counts": rig.face_counts,
        "rig/face_indices": rig.face_indices,
        "rig/deltas": rig.deltas,
        "pose/weights": project.weights,
    }
    corners = rig.corners
    if corners is not None:  # the source OBJ's UVs, normals and groups, so an OBJ export keeps them
        for key in ("uvs", "corner_uv", "normals", "corner_normal"):
            if getattr(corners, key) is not None:
                arrays[f"rig/{key}"] = getattr(corners, key)
    shapes = _shape_settings_entry(rig, arrays)
    correctives = []
    for i, c in enumerate(rig.correctives):
        key = f"correctives/{i}"
        arrays[key] = np.asarray(c.delta, dtype=np.float64)
        correctives.append(c.to_dict(key))
    for name, a in project.arrays.items():
        arrays[f"extra/{name}"] = np.asarray(a)
    pose = {}
    if project.region_weights is not None:
        blend = sp.csr_matrix(project.region_blend)
        arrays.update({"pose/region_weights": project.region_weights, "pose/blend_data": blend.data,
                       "pose/blend_indices": blend.indices, "pose/blend_indptr": blend.indptr})
        pose = {"region_level": project.region_level, "blend_shape": list(blend.shape)}
    names = set(rig.shape_names)   # a pair of a shape deleted since is not written (the file would be refused)
    antagonists = None if project.antagonists is None else \
        [[a, b] for a, b in project.antagonists if a in names and b in names]
    manifest = {
        "format": FORMAT,
        "version": VERSION,
        "rig": {"name": rig.name, "units": rig.units, "shape_names": rig.shape_names,
                "presets": rig.presets, "source": rig.source,
                "records": [list(r) for r in corners.records] if corners is not None else None,
                **({"materials": {k: list(v) for k, v in rig.materials.items()}} if rig.materials else {}),
                **({"shapes": shapes} if shapes else {})},
        "correctives": correctives,
        "pose": pose,
        **({} if antagonists is None else {"antagonists": antagonists}),
        "sections": project.sections,
        "arrays": {k: [list(v.shape), str(v.dtype)] for k, v in arrays.items()},
    }

    def write(f):
        with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
            z.writestr(MANIFEST, json.dumps(manifest, indent=1))
            for key, a in arrays.items():
                z.writestr(f"{key}.npy", _npy_bytes(a))

    return write


def _materials(entry, path) -> dict[str, tuple[float, float, float]]:
    """The rig's material colours from the manifest: {name: [r, g, b]} with numbers in 0..1."""
    ok = isinstance(entry, dict) and all(
        isinstance(v, list) and len(v) == 3 and all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                                    and 0.0 <= c <= 1.0 for c in v) for v in entry.values())
    if not ok:
        raise RigInputError(f"{path}: the rig's material colours are not three numbers from 0 to 1 each; "
                            "the project is damaged.")
    return {str(k): tuple(float(c) for c in v) for k, v in entry.items()}


def load_project(path: str | Path) -> Project:
    """Read a project; a damaged file raises RigInputError naming the file and the problem."""
    path = regular_file(path)
    try:
        z = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise RigInputError(f"{path}: is not a readable project (damaged zip: {exc}).") from None
    # a studio-scale project's arrays are written once here: ordinary pages for them (model.pages)
    with z, small_pages_for(sum(i.file_size for i in z.infolist() if i.filename.endswith(".npy"))):
        try:
            info = z.getinfo(MANIFEST)
            if info.file_size > MAX_JSON_BYTES:
                raise RigInputError(f"{path}: the project manifest is {info.file_size / 2**20:.0f} MB; it is damaged.")
            manifest = parse_json_text(z.read(MANIFEST).decode("utf-8"), f"{path}: the project manifest")
        except KeyError:
            raise RigInputError(f"{path}: the project has no manifest.json; it is damaged.") from None
        except (ValueError, UnicodeDecodeError, zipfile.BadZipFile, zlib.error, OSError) as exc:
            raise RigInputError(f"{path}: the project manifest is damaged ({exc}).") from None
        if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
            raise RigInputError(f"{path}: is not a Blendshape Studio project.")
        version = manifest.get("version", 0)
        if isinstance(version, bool) or not isinstance(version, int):
            raise RigInputError(f"{path}: the project's format version is not a number.")
        if version > VERSION:
            raise RigInputError(f"{path}: was saved by a newer Blendshape Studio (format "
                                f"{manifest.get('version')}); update to open it.")
        declared = manifest.get("arrays", {})

        def array(key: str) -> np.ndarray:
            a = read_npy_member(z, f"{key}.npy", path, key)
            entry = declared.get(key) if isinstance(declared, dict) else None
            shape = entry[0] if isinstance(entry, list) and entry else None
            if shape is not None and list(a.shape) != list(shape):
                raise RigInputError(f"{path}: the array '{key}' has shape {list(a.shape)}, "
                                    f"the manifest says {shown(shape, 40)}.")
            return a

        try:
            meta = manifest["rig"]
            rig = Rig(neutral=array("rig/neutral"), face_counts=array("rig/face_counts"),
                      face_indices=array("rig/face_indices"), shape_names=meta["shape_names"],
                      deltas=array("rig/deltas"), units=meta.get("units", "cm"), name=meta.get("name", path.stem),
                      source=str(path), presets=meta.get("presets", {}))
            if meta.get("records") is not None:
                from .rig import CornerAttributes
                rig.corners = CornerAttributes(
                    records=[(int(f), str(line)) for f, line in meta["records"]],
                    **{k: array(f"rig/{k}") if f"rig/{k}" in declared else None
                       for k in ("uvs", "corner_uv", "normals", "corner_normal")})
                rig.validate()
            if meta.get("materials") is not None:
                rig.materials = _materials(meta["materials"], path)
            if meta.get("shapes") is not None:
                _read_shape_settings(rig, meta["shapes"], array, declared)
            if manifest.get("correctives"):
                from .correctives import Corrective, set_correctives
                set_correctives(rig, [Corrective.from_entry(c, array) for c in manifest["correctives"]])
            for c in rig.correctives:
                if c.delta.shape != rig.neutral.shape:
                    raise RigInputError(f"{path}: corrective '{c.name}' has {c.delta.shape[0]} vertices, "
                                        f"the rig has {rig.n_vertices}.")
            weights = array("pose/weights")
            if weights.shape != (rig.n_shapes,):
                raise RigInputError(f"{path}: the saved pose has {weights.size} weights for {rig.n_shapes} shapes.")
            extras = {k[len("extra/"):]: array(k) for k in declared if k.startswith("extra/")}
            regional = {}
            pose = manifest.get("pose") or {}
            if pose.get("blend_shape") is not None:
                try:
                    blend = sp.csr_matrix((array("pose/blend_data"), array("pose/blend_indices"),
                                           array("pose/blend_indptr")), shape=tuple(pose["blend_shape"]))
                except RigInputError:
                    raise
                except ValueError as exc:
                    raise RigInputError(f"{path}: the saved regional pose is damaged ({exc}).") from None
                regional = dict(region_weights=array("pose/region_weights"), region_blend=blend,
                                region_level=pose.get("region_level"))
        except RigInputError as exc:
            msg = str(exc)
            raise RigInputError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from None
        except KeyError as exc:
            raise RigInputError(f"{path}: the project manifest is incomplete (missing {shown(exc, 40)}).") from None
        except (TypeError, AttributeError, ValueError) as exc:
            raise RigInputError(f"{path}: the project manifest holds a value of the wrong type ({shown(exc, 80)}).") from None
    try:
        sections = manifest.get("sections", {})
        if not isinstance(sections, dict):
            raise RigInputError("the project's sections are not an object of name: settings.")
        antagonists = manifest.get("antagonists")   # absent in projects saved before it existed
        return Project(rig=rig, weights=weights, sections=sections, arrays=extras, antagonists=antagonists,
                       **regional)
    except RigInputError as exc:
        raise RigInputError(f"{path}: {exc}") from None
