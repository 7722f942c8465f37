"""Exports other tools play: one entry point, ``export_rig``, and the content every format shares.

``export_rig(rig, path, weights=None, animation=None, units=None, up="y")`` dispatches on the extension:
``.glb``/``.gltf`` (model.export_gltf), ``.usd``/``.usda``/``.usdc`` (model.export_usd) and ``.obj`` (the
posed surface, with the source's UVs, normals and groups). glTF and USD carry the same content
(``ExportContent``): the rig's shapes plus each corrective as an extra blend shape whose weight is its
activation ``a_c(w)`` (0 when muted), so a player that only sums blend shapes reproduces the application's
pose exactly at every frame; the current pose as the default weights; and the animation sampled per frame.
Coordinates are converted to ``units`` (default metres for glTF and USD, the rig's own for OBJ) and to the
``up`` axis (the rig is taken as Y-up, glTF's convention; ``up="z"`` turns it Z-up for Z-up pipelines).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import RigInputError
from .input_files import regular_file
from .rig import Rig, unit_scale

UP_AXES = ("y", "z")
# Y-up to Z-up: +Y becomes +Z and the face's front (+Z) becomes -Y, Blender's front view.
_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass
class WeightAnimation:
    """Per-frame weights of the rig's shapes: ``times`` (F,) seconds, strictly increasing; ``weights`` (F, K)."""

    times: np.ndarray
    weights: np.ndarray
    source: str = ""
    warnings: list[str] = field(default_factory=list)     # what reading it decided (a rate assumed)

    def __post_init__(self) -> None:
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        self.weights = np.asarray(self.weights, dtype=np.float64)
        where = self.source or "the animation"
        if self.weights.ndim != 2 or self.weights.shape[0] != self.times.size or self.times.size == 0:
            raise RigInputError(f"{where}: needs one row of weights per frame time (and at least one frame).")
        if not (np.isfinite(self.times).all() and np.isfinite(self.weights).all()):
            raise RigInputError(f"{where}: has NaN or infinite times or weights.")
        if np.any(np.diff(self.times) <= 0):
            raise RigInputError(f"{where}: its frame times do not increase (frame "
                                f"{int(np.argmax(np.diff(self.times) <= 0)) + 1}).")

    @property
    def n_frames(self) -> int:
        return int(self.times.size)


def animation_for_rig(rig: Rig, names: list[str], weights: np.ndarray, times: np.ndarray,
                      source: str = "") -> WeightAnimation:
    """Per-frame weights given for ``names`` placed in the rig's shape order (shapes not named stay 0)."""
    from .weights_csv import check_shapes_known
    check_shapes_known(source or "the animation", names, rig.shape_names)
    W = np.zeros((np.asarray(weights).shape[0], rig.n_shapes))
    W[:, [rig.shape_index(n) for n in names]] = weights
    return WeightAnimation(times=times, weights=W, source=source)


def animation_from_timeline(timeline, rate: float = 30.0, *, deltas=None, blend=None) -> WeightAnimation:
    """Keyframes (model.keyframes.Timeline) sampled at every frame from the first key to the last. A timeline of
    regional poses (per-region weights blended by ``blend``) becomes, frame by frame, the global weights whose
    surface is closest to it (``solvers.surface_fit``; pass the rig's ``deltas`` and the keys' ``blend``)."""
    if not len(timeline):
        raise RigInputError("The timeline has no keys to export.")
    if not rate > 0:
        raise RigInputError(f"The frame rate must be positive, not {rate}.")
    T = timeline.times
    frames = np.arange(int(np.floor((T[-1] - T[0]) * rate + 1e-9)) + 1)
    times = T[0] + frames / rate
    from .keyframes import keyed_global_weights
    W = keyed_global_weights(timeline, times, deltas, blend)
    return WeightAnimation(times=times - T[0], weights=W, source="keyframes")


def load_animation(path: str | Path, rig: Rig, rate: float | None = None) -> WeightAnimation:
    """A weights CSV (``frame,time,<shapes>``, as ``solve`` writes, or ``frame,<shapes>`` at ``rate`` frames a second
    (``model.take_data.given_rate``), else ``model.weights_csv.UNTIMED_RATE`` with a warning) or a Live Link Face
    CSV, for ``rig``. A file with its own times keeps them (a warning when ``rate`` is given)."""
    from .take_data import rate_not_used
    path = regular_file(path)   # a missing file, a folder, a FIFO or a device: one sentence, nothing read
    if path.suffix.lower() != ".csv":
        raise RigInputError(f"{path}: an animation is a weights CSV or a Live Link Face CSV.")
    from .livelink import is_livelink_csv
    if is_livelink_csv(path):
        from .livelink import read_livelink_csv
        take = read_livelink_csv(path, rig.shape_names)
        times = np.asarray(take.times(), dtype=np.float64)   # the frame times from the timecodes
        animation = WeightAnimation(times=times - times[0], weights=take.weights, source=str(path))
        animation.warnings = rate_not_used(path, take.rate, rate)
        return animation
    from .weights_csv import UNTIMED_RATE, read_weights_table, times_rate
    frames, times, names, W = read_weights_table(path)
    warnings = []
    if times is None:           # frame,<shapes>: no time column
        times = (frames - (frames[0] if frames.size else 0)) / (rate or UNTIMED_RATE)
        if rate is None:
            warnings.append(f"{path}: has no time column; {UNTIMED_RATE:g} frames a second assumed.")
    elif times.size > 1:
        warnings += rate_not_used(path, times_rate(times), rate)
    animation = animation_for_rig(rig, names, W, times - (times[0] if times.size else 0.0), source=str(path))
    animation.warnings = warnings
    return animation


class ShapeDeltas:
    """(K + N + C, V, 3) blend shape offsets in an export's units and axes, each made from the rig's own as it is read
    (``rows[k] @ transform.T``): the writers take a shape at a time, so an export holds no second copy of the rig's
    deltas (a 422k-vertex, 228-shape rig's peaked at 3.2x its deltas with two). ``np.asarray`` gives the whole array."""

    def __init__(self, rows: list[np.ndarray], transform: np.ndarray) -> None:
        self.rows, self.transform = rows, np.asarray(transform, dtype=np.float64)

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, k: int) -> np.ndarray:
        return self.rows[k] @ self.transform.T

    def __iter__(self):
        return (self[k] for k in range(len(self)))

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = np.empty((len(self), *(self.rows[0].shape if self.rows else (0, 3))))
        for k, d in enumerate(self.rows):
            np.matmul(d, self.transform.T, out=out[k])
        return out if dtype is None else out.astype(dtype)


@dataclass
class ExportContent:
    """What glTF and USD exports hold, in the export's units and axes.

    names    K shape names, N in-between names ("<shape>@<weight>"), then C corrective names (unique).
    neutral  (V, 3) rest surface.
    deltas   (K + N + C, V, 3) blend shape offsets (shapes, in-betweens, then correctives): ``ShapeDeltas``.
    pose     (K + N + C,) default weights: the current pose, its in-betweens' and correctives' weights.
    times    (F,) seconds and ``frames`` (F, K + N + C) weights per frame, or None without an animation.
    A shape's in-betweens are morph targets of their own, keyed with piecewise linear weights (a glTF or USD
    viewer blends them linearly, so every keyed frame is the evaluator's surface exactly; between keys the
    viewer interpolates the coefficients). Muted and unsoloed shapes are keyed at 0.
    """

    names: list[str]
    neutral: np.ndarray
    deltas: ShapeDeltas
    pose: np.ndarray
    face_counts: np.ndarray
    face_indices: np.ndarray
    units: str
    up: str
    name: str
    times: np.ndarray | None = None
    frames: np.ndarray | None = None
    uvs: np.ndarray | None = None   # (V, 2) one UV per vertex (v up, as OBJ), when the rig has them so
    parts: object = None            # the rig's parts (model.parts.Parts: faces by material, colours) or None


def full_weights(rig: Rig, weights: np.ndarray) -> np.ndarray:
    """(K + N + C,) blend shape weights of one pose: the shape weights, the in-betweens' (each a morph target of
    its own, weighted piecewise linearly), then each corrective's activation -- the pose evaluator's rows
    (``model.shape_weights``: ranges, mute and solo applied)."""
    from .shape_weights import ShapeWeights
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    return np.array(ShapeWeights(rig).row_weights(w, rig.correctives, rig.shape_names), dtype=np.float64)


def export_content(rig: Rig, weights: np.ndarray | None = None, animation: WeightAnimation | None = None,
                   units: str = "m", up: str = "y") -> ExportContent:
    """The shapes, correctives, pose and animation of ``rig`` in ``units`` and ``up`` axis (module docstring)."""
    if up not in UP_AXES:
        raise RigInputError(f"Unknown up axis '{up}': use one of {', '.join(UP_AXES)}.")
    s = unit_scale(rig.units, units)
    A = s * (_Y_TO_Z if up == "z" else np.eye(3))
    from .shape_weights import ShapeWeights
    sw = ShapeWeights(rig)
    names = list(rig.shape_names)
    taken = set(names)
    for n in sw.inbetween_names:   # in-betweens as morph targets of their own, "<shape>@<weight>"
        while n in taken:
            n += "_"
        names.append(n)
        taken.add(n)
    for c in rig.correctives:
        n, i = c.name or "+".join(c.drivers), 2
        while n in taken:
            n, i = f"{c.name}_{i}", i + 1
        names.append(n)
        taken.add(n)
    deltas = ShapeDeltas([*rig.deltas, *sw.inbetween_deltas, *(c.delta for c in rig.correctives)], A)
    w = np.zeros(rig.n_shapes) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.shape != (rig.n_shapes,):
        raise RigInputError(f"{w.size} weights given for a rig of {rig.n_shapes} shapes.")
    content = ExportContent(names=names, neutral=rig.neutral @ A.T, deltas=deltas, pose=full_weights(rig, w),
                            face_counts=rig.face_counts, face_indices=rig.face_indices, units=units, up=up,
                            name=rig.name or "rig")
    from .textures import per_vertex_uvs
    content.uvs = per_vertex_uvs(rig)
    from .parts import rig_parts
    content.parts = rig_parts(rig)
    if animation is not None:
        if animation.weights.shape[1] != rig.n_shapes:
            raise RigInputError(f"{animation.source or 'the animation'}: has {animation.weights.shape[1]} "
                                f"weights per frame for a rig of {rig.n_shapes} shapes.")
        content.times = animation.times.copy()
        content.frames = np.stack([full_weights(rig, wf) for wf in animation.weights])
    return content


def write_posed_obj(rig: Rig, path: str | Path, weights: np.ndarray | None = None, *, units: str | None = None,
                    up: str = "y") -> None:
    """The posed surface (the application's pose evaluation) as an OBJ with the source's UVs, groups and
    materials (``write_surface_obj``).

    The source's normals are kept for the rest pose only: a posed surface gets none (clients compute them, smooth:
    without the source's own smoothing records the file says ``s 1``).
    """
    from .pose import PoseEvaluator
    if up not in UP_AXES:
        raise RigInputError(f"Unknown up axis '{up}': use one of {', '.join(UP_AXES)}.")
    w = np.zeros(rig.n_shapes) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    R = _Y_TO_Z if up == "z" else np.eye(3)
    points = PoseEvaluator(rig, dtype=np.float64).evaluate(w) @ (unit_scale(rig.units, units or rig.units) * R.T)
    header = f"Blendshape Studio export of {rig.name}\nweights: " + ", ".join(
        f"{n}={v:g}" for n, v in zip(rig.shape_names, w) if v != 0)
    write_surface_obj(rig, path, points, header=header, normals=not np.any(w != 0), rotation=R)


def write_surface_obj(rig: Rig, path: str | Path, points: np.ndarray, *, header: str, normals: bool = False,
                      rotation: np.ndarray | None = None) -> None:
    """``points`` (V, 3) on the rig's polygons as an OBJ, with the source's UVs, groups and material records, and
    (when the rig knows its materials' colours) its material library beside it: ``<name>.mtl`` with each
    material's ``Kd``, named by the OBJ's ``mtllib`` line, so a DCC -- or this application -- reading the OBJ
    shows each part in its colour. ``normals``: keep the source's normals (turned by ``rotation``)."""
    import dataclasses

    from .atomic import atomic_write
    from .obj_io import obj_bytes
    corners = rig.corners
    if corners is not None and rotation is not None and corners.normals is not None:
        corners = dataclasses.replace(corners, normals=corners.normals @ np.asarray(rotation).T)
    path = Path(path)
    library = material_library(rig, path)
    if library is not None:
        from .parts import mtl_bytes, rig_parts
        parts = rig_parts(rig)
        mtl = mtl_bytes(parts.names if parts is not None else list(rig.materials), rig.materials, rig.name)
        records = [r for r in corners.records if not r[1].startswith("mtllib")]
        corners = dataclasses.replace(corners, records=[(0, f"mtllib {library.name}")] + records)
    corners = _smooth_unless_said(corners, normals)
    obj = obj_bytes(points, rig.face_counts, rig.face_indices, header=header, corners=corners, normals=normals)
    if library is None:
        atomic_write(path, obj)
    else:
        from .output_set import write_set
        write_set({path: lambda f: f.write(obj), library: lambda f: f.write(mtl)})   # both new, or both as they were


def material_library(rig: Rig, path: str | Path) -> Path | None:
    """The material library an OBJ written to ``path`` gets beside it (``write_surface_obj``): ``<stem>.mtl`` (blanks
    as underscores) when the rig knows its materials' colours, else None."""
    import re
    if not (rig.materials and rig.corners is not None):
        return None
    path = Path(path)
    return path.with_name(re.sub(r"\s+", "_", path.stem) + ".mtl")


def check_files_beside(rig: Rig, path: str | Path, check) -> None:
    """``check(file)`` (the front end's rule for its outputs: not over an input, ``model.beside_inputs``) on the files
    an export to ``path`` writes beside it: an OBJ's material library (``material_library``), which overwrote a file
    already there unchecked (the rig's own materials too). Its sentence says which export writes the file."""
    library = material_library(rig, path) if Path(path).suffix.lower() == ".obj" else None
    if library is None:
        return
    try:
        check(library)
    except RigInputError as exc:
        text = str(exc)
        said = text[len(f"{library}: "):] if text.startswith(f"{library}: ") else text
        raise RigInputError(f"{library} (the material library written with {path}): {said}") from None


def _smooth_unless_said(corners, normals: bool):
    """``corners`` with a smoothing group (``s 1``) before the first face when the OBJ written from them would say
    nothing of its shading: no ``s`` record of the source's and no normals written. Blender's and Maya's importers
    shade such an OBJ flat (Blender 3.4: every face of ICT's, whose files have neither); a face is smooth."""
    import dataclasses

    from .rig import CornerAttributes
    c = corners or CornerAttributes()
    if any(line.split(None, 1)[0] == "s" for _, line in c.records if line.strip()):
        return corners
    if normals and c.normals is not None:
        return corners
    first = [r for r in c.records if r[0] <= 0]
    return dataclasses.replace(c, records=first + [(0, "s 1")] + [r for r in c.records if r[0] > 0])


EXPORT_SUFFIXES = (".glb", ".gltf", ".usd", ".usda", ".usdc", ".obj")


def export_size(rig: Rig, path: str | Path, n_frames: int = 0, *, units: str | None = None, up: str = "y") -> int:
    """The least an export of ``rig`` to ``path`` with an animation of ``n_frames`` frames takes (bytes, known before
    writing), for ``model.free_space``. glTF: the neutral's float32 positions, each shape's and corrective's offsets
    (float32 for every vertex, or for the vertices it moves with at least a 2-byte index each, whichever is less),
    and a key time and a float32 weight per frame for each; in-betweens, normals and a .gltf's base64 take more
    (ICT: at least 9.6 MB, written 27 MB). USD: ``usd_size`` (``units`` and ``up`` as ``export_rig``'s). 0 for an
    OBJ: it is one surface."""
    suffix = Path(path).suffix.lower()
    if suffix in (".usd", ".usda", ".usdc"):
        return usd_size(export_content(rig, units=units or "m", up=up), suffix, n_frames)
    if suffix not in (".glb", ".gltf"):
        return 0
    V = rig.n_vertices
    moved = [int(np.count_nonzero(np.any(np.asarray(d, dtype=np.float32) != 0, axis=1)))
             for d in [*rig.deltas, *(c.delta for c in rig.correctives)]]
    return V * 12 + sum(min(V * 12, m * 14) for m in moved) + int(n_frames) * (1 + len(moved)) * 4


def check_export_space(rig: Rig, path: str | Path, n_frames: int = 0, *, units: str | None = None,
                       up: str = "y") -> None:
    """Refuse (RigInputError, ``model.free_space``) an export of ``rig`` to ``path`` whose least size
    (``export_size``) its disk has no room for: the ``export`` command and the window's File ▸ Export Rig."""
    from .free_space import check_free_space
    check_free_space({path: export_size(rig, path, n_frames, units=units, up=up)}, lower_bounds=[path])


def usd_size(content: ExportContent, suffix: str, n_frames: int = 0) -> int:
    """The least ``model.export_usd`` writes for ``content`` as ``suffix``. A .usdc (crate) stores the points and
    each target's offsets (float32 vectors of the vertices it moves) uncompressed, 12 bytes a vector, an array equal
    to one already written once (its integer and float arrays it compresses: not counted). A .usda writes every
    value as text: a vector at least ``(0, 0, 0)`` and a number at least one digit, each with ``, `` between them:
    the points, the offsets, the targets' point indices, the faces, and a weight per target and frame. A .usd is
    crate unless usd-core is set to write text: the lesser of the two."""
    points = np.asarray(content.neutral, dtype=np.float32)
    offsets = []
    for d in content.deltas:
        moved = np.abs(d).max(axis=1) > 0 if len(d) else np.zeros(0, dtype=bool)
        offsets.append(np.asarray(d[moved], dtype=np.float32))

    def text(n: int, each: int) -> int:   # n values of at least ``each`` characters, ", " between them
        return n * (each + 2) - 2 if n else 0
    usda = (text(len(points), 9) + sum(text(len(o), 9) + text(len(o), 1) for o in offsets)
            + text(len(content.face_counts), 1) + text(len(content.face_indices), 1)
            + int(n_frames) * text(len(content.names), 1))
    distinct = {(a + np.float32(0)).tobytes() for a in [points, *offsets] if len(a)}   # -0.0 as 0.0: equal arrays
    usdc = 12 * sum(len(b) // 12 for b in distinct)
    return {".usda": usda, ".usdc": usdc}.get(suffix, min(usda, usdc))


def export_rig(rig: Rig, path: str | Path, weights: np.ndarray | None = None,
               animation: WeightAnimation | None = None, *, units: str | None = None, up: str = "y") -> Path:
    """Write ``rig`` to ``path`` as glTF, USD or OBJ, chosen by the extension; returns the path.

    ``weights`` (K,) is the current pose (default neutral), ``animation`` per-frame weights (glTF and USD;
    an OBJ is one posed surface). ``units`` defaults to metres for glTF and USD, the rig's units for OBJ.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".glb", ".gltf"):
        from .export_gltf import write_gltf_content
        write_gltf_content(export_content(rig, weights, animation, units or "m", up), path)
    elif suffix in (".usd", ".usda", ".usdc"):
        from .export_usd import write_usd_content
        write_usd_content(export_content(rig, weights, animation, units or "m", up), path, corners=rig.corners)
    elif suffix == ".obj":
        if animation is not None:
            raise RigInputError(f"{path}: an OBJ holds one surface, not an animation; export .glb, .gltf or .usd.")
        write_posed_obj(rig, path, weights, units=units or rig.units, up=up)
    else:
        raise RigInputError(f"{path}: unknown export format '{path.suffix}'; write one of "
                            f"{', '.join(EXPORT_SUFFIXES)}.")
    return path
