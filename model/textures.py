"""Per-shape textures of a rig: where they are, reading them, checking them against the rig's UVs.

A rig's textures are found by name next to it (``jawOpen.png`` beside ``jawOpen.obj``; the neutral's beside
the neutral OBJ, ``neutral.png`` or ``<neutral stem>.png``; for a glTF/project, ``<file stem>.png``), or listed
in the project's ``textures`` section (paths relative to the project). Optional: normal maps
``<name>_normal.png`` and a keep mask ``texture_mask.png`` (white where the texture must stay the
neutral's: hair, neck, ears). Images are PNG, JPEG, TIFF or BMP (Pillow), read once as float32 RGB in
[0, 1]; a shape's texture must have the neutral's size.

Texture trouble never stops the geometry: ``load_texture_set`` returns the usable textures and one
sentence per problem (a missing or unreadable file, a wrong size, UVs outside 0–1 or missing).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import RigInputError, shown
from .rig import CornerAttributes, Rig

SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
NORMAL_SUFFIX = "_normal"
MASK_NAME = "texture_mask"
MAX_SIDE = 8192          # texels; 8K is the largest texture a DCC bakes for a face
SECTION = "textures"


@dataclass
class TextureFiles:
    """Where a rig's textures are (paths; None or absent when there is none)."""
    neutral: Path | None = None
    shapes: dict[str, Path] = field(default_factory=dict)
    normal_maps: dict[str, Path] = field(default_factory=dict)   # "neutral" or a shape name
    mask: Path | None = None

    @property
    def empty(self) -> bool:
        return self.neutral is None and not self.shapes


@dataclass
class TextureSet:
    """The textures a blend uses, float32 in [0, 1]: ``neutral`` (H, W, 3), ``shapes`` by name (same size),
    ``keep`` (H, W) or None, ``normal_maps`` by name ('neutral' or a shape), and the problems met reading them."""
    neutral: np.ndarray
    shapes: dict[str, np.ndarray] = field(default_factory=dict)
    keep: np.ndarray | None = None
    normal_maps: dict[str, np.ndarray] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    origin: str = ""

    def shape_list(self, shape_names: list[str]) -> list[np.ndarray | None]:
        """One texture per shape of the rig, None for those without their own (the neutral's stays)."""
        return [self.shapes.get(n) for n in shape_names]


def read_texture(path: str | Path, *, gray: bool = False) -> np.ndarray:
    """An image file as float32 in [0, 1]: (H, W, 3) RGB, or (H, W) with ``gray``. RigInputError naming the
    file and the problem when it is missing, not an image, or too large."""
    from PIL import Image, UnidentifiedImageError
    path = Path(path)
    if not path.is_file():
        raise RigInputError(f"{path}: the texture does not exist." if not path.exists()
                            else f"{path}: the texture is not a regular file.")
    try:
        with Image.open(path) as im:
            w, h = im.size
            if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
                raise RigInputError(f"{path}: the texture is {w}x{h} texels; up to {MAX_SIDE}x{MAX_SIDE} can be used.")
            im.load()
            if im.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
                a = np.asarray(im, dtype=np.float32)
                a = a / (65535.0 if im.mode.startswith("I;16") or a.max(initial=0) > 255 else 255.0)
                a = a if gray else np.repeat(a[..., None], 3, axis=2)
            else:
                a = np.asarray(im.convert("L" if gray else "RGB"), dtype=np.float32) / 255.0
    except RigInputError:
        raise
    except UnidentifiedImageError:
        raise RigInputError(f"{path}: is not an image Pillow can read (PNG, JPEG, TIFF or BMP).") from None
    except (OSError, ValueError, SyntaxError) as exc:   # truncated or damaged image data
        raise RigInputError(f"{path}: the texture is damaged ({shown(exc, 80)}).") from None
    except Image.DecompressionBombError:
        raise RigInputError(f"{path}: the texture declares too many texels; it is damaged or hostile.") from None
    if not np.isfinite(a).all():
        raise RigInputError(f"{path}: the texture holds NaN or infinite values.")
    return np.clip(a, 0.0, 1.0).astype(np.float32)


def write_texture(path: str | Path, image: np.ndarray) -> None:
    """Write a float image in [0, 1] ((H, W, 3) or (H, W)) as an 8-bit PNG, atomically."""
    import io

    from PIL import Image

    from .atomic import atomic_write
    a = np.clip(np.asarray(image, dtype=np.float32) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG", compress_level=1)
    atomic_write(path, buf.getvalue())


def _image_beside(folder: Path, stem: str) -> Path | None:
    for suffix in SUFFIXES:
        for s in (suffix, suffix.upper()):
            p = folder / f"{stem}{s}"
            if p.is_file():
                return p
    return None


def find_texture_files(rig: Rig, folder: str | Path | None = None) -> TextureFiles:
    """The textures beside the rig's files, by name (module docstring); ``folder`` defaults to the folder of
    ``rig.source``."""
    if folder is None:
        src = Path(rig.source) if rig.source else None
        if src is None or not (src.exists()):
            return TextureFiles()
        folder = src if src.is_dir() else src.parent
        stems = ["neutral", src.stem] if not src.is_dir() else ["neutral"]
    else:
        stems = ["neutral"]
    folder = Path(folder)
    neutral_obj = next((p for p in sorted(folder.glob("*.obj")) if "neutral" in p.stem.lower()), None)
    if neutral_obj is not None:
        stems.append(neutral_obj.stem)
    files = TextureFiles()
    for stem in dict.fromkeys(stems):
        files.neutral = files.neutral or _image_beside(folder, stem)
        normal = _image_beside(folder, stem + NORMAL_SUFFIX)
        if normal is not None:
            files.normal_maps.setdefault("neutral", normal)
    for name in rig.shape_names:
        p = _image_beside(folder, name)
        if p is not None:
            files.shapes[name] = p
        n = _image_beside(folder, name + NORMAL_SUFFIX)
        if n is not None:
            files.normal_maps[name] = n
    files.mask = _image_beside(folder, MASK_NAME)
    return files


def files_from_section(section, base: str | Path, shape_names: list[str]) -> tuple[TextureFiles, list[str]]:
    """The files a project's ``textures`` section lists (paths relative to ``base``), and its problems."""
    base = Path(base)
    problems: list[str] = []
    files = TextureFiles()
    if not isinstance(section, dict):
        return files, [f"{base}: the project's texture list is not an object of name: file; it is ignored."]

    def path_of(value, what: str) -> Path | None:
        if not isinstance(value, str) or not value or len(value) > 4096 or "\0" in value:
            problems.append(f"{base}: the project's texture entry for {what} is not a file name; it is ignored.")
            return None
        p = Path(value)
        return p if p.is_absolute() else base / p

    if section.get("neutral") is not None:
        files.neutral = path_of(section["neutral"], "the neutral")
    if section.get("mask") is not None:
        files.mask = path_of(section["mask"], "the mask")
    for key, target in (("shapes", files.shapes), ("normal_maps", files.normal_maps)):
        entries = section.get(key) or {}
        if not isinstance(entries, dict):
            problems.append(f"{base}: the project's texture list '{key}' is not an object; it is ignored.")
            continue
        for name, value in entries.items():
            if name not in shape_names and not (key == "normal_maps" and name == "neutral"):
                problems.append(f"{base}: the project lists a texture for '{shown(name, 40)}', a shape the rig "
                                "does not have; it is ignored.")
                continue
            p = path_of(value, f"'{shown(name, 40)}'")
            if p is not None:
                target[name] = p
    return files, problems


def section_from_files(files: TextureFiles, base: str | Path | None = None) -> dict:
    """The ``textures`` project section listing ``files``: relative to ``base`` where they lie under it, else
    (and without ``base``) absolute paths."""
    base = Path(base).resolve() if base is not None else None

    def rel(p: Path) -> str:
        p = Path(p).resolve()
        if base is not None and p.is_relative_to(base):
            return p.relative_to(base).as_posix()
        return str(p)

    out: dict = {"shapes": {k: rel(p) for k, p in files.shapes.items()},
                 "normal_maps": {k: rel(p) for k, p in files.normal_maps.items()}}
    if files.neutral is not None:
        out["neutral"] = rel(files.neutral)
    if files.mask is not None:
        out["mask"] = rel(files.mask)
    return out


def load_texture_set(rig: Rig, files: TextureFiles) -> tuple[TextureSet | None, list[str]]:
    """Read the textures ``files`` names for ``rig``: (the set, or None when there is no usable neutral
    texture; one sentence per problem). Shape textures of another size than the neutral's are left out. Without
    any texture there is nothing to show and nothing to say (the UVs' problems are about showing one: ICT FaceKit's
    UV tiles were called 'tiles or a damaged file' where no texture repeats)."""
    if files.neutral is None and not files.shapes:
        return None, []
    problems = uv_problems(rig)
    c = rig.corners
    if c is None or c.uvs is None or c.corner_uv is None:
        return None, problems
    if files.neutral is None:
        if files.shapes:
            problems.append(f"{rig.source or rig.name}: shape textures but no neutral texture (neutral.png); "
                            "textures are off.")
        return None, problems
    try:
        neutral = read_texture(files.neutral)
    except RigInputError as exc:
        return None, problems + [f"{exc} Textures are off."]
    H, W = neutral.shape[:2]

    def read_sized(path: Path, what: str, gray: bool = False) -> np.ndarray | None:
        try:
            img = read_texture(path, gray=gray)
        except RigInputError as exc:
            problems.append(f"{exc} {what} keeps the neutral's.")
            return None
        if img.shape[:2] != (H, W):
            problems.append(f"{path}: the texture is {img.shape[1]}x{img.shape[0]}, the neutral's is {W}x{H}; "
                            f"{what} keeps the neutral's.")
            return None
        return img

    shapes = {}
    for name, path in files.shapes.items():
        img = read_sized(path, f"shape '{name}'")
        if img is not None:
            shapes[name] = img
    normals = {}
    for name, path in files.normal_maps.items():
        img = read_sized(path, f"the normal map of '{name}'")
        if img is not None:
            normals[name] = img
    keep = read_sized(files.mask, "the keep mask", gray=True) if files.mask is not None else None
    return TextureSet(neutral, shapes, keep, normals, problems, str(files.neutral.parent)), problems


def uv_problems(rig: Rig) -> list[str]:
    """Sentences about the rig's UVs a texture cannot be shown with: none, missing on corners, outside 0–1."""
    where = rig.source or rig.name
    c = rig.corners
    out = list(c.notes) if c is not None else []
    if c is None or c.uvs is None or c.corner_uv is None:
        return out + [f"{where}: the rig has no texture coordinates (UVs); textures cannot be shown."]
    missing = int((c.corner_uv < 0).sum())
    if missing:
        out.append(f"{where}: {missing:,} face corners have no UV; they show the texture's corner texel.")
    used = c.uvs[c.corner_uv[c.corner_uv >= 0], :2]
    outside = int(((used < 0) | (used > 1)).any(axis=1).sum())
    if outside:
        out.append(f"{where}: {outside:,} face corners have UVs outside 0–1 (tiles or a damaged file); the "
                   "texture repeats there.")
    return out


def per_vertex_uvs(rig: Rig) -> np.ndarray | None:
    """(V, 2) UVs when every vertex has one UV on all its corners (glTF, the sample), else None."""
    c = rig.corners
    if c is None or c.uvs is None or c.corner_uv is None or (c.corner_uv < 0).any():
        return None
    uv = c.uvs[c.corner_uv, :2]
    per = np.full((rig.n_vertices, 2), np.nan)
    per[rig.face_indices] = uv
    if np.isnan(per).any() or not np.array_equal(per[rig.face_indices], uv):
        return None
    return per


def corners_from_vertex_uvs(rig_face_indices: np.ndarray, uvs: np.ndarray) -> CornerAttributes:
    """Corner attributes for one UV per vertex (glTF TEXCOORD_0): the UV table is the vertex list."""
    return CornerAttributes(uvs=np.asarray(uvs, dtype=np.float64), corner_uv=np.array(rig_face_indices, np.int32))


@dataclass
class DisplaySplit:
    """A display-only copy of the surface split at UV seams: display point ``i`` is rig vertex
    ``vertex[i]`` with UV ``uv[i]``; ``face_indices`` index display points (the rig's faces, same order)."""
    vertex: np.ndarray
    uv: np.ndarray
    face_indices: np.ndarray

    def of_faces(self, face_counts: np.ndarray, faces: np.ndarray | None) -> "DisplaySplit":
        """The split of the polygons ``faces`` only (a view that hides parts, ``model.parts``); itself when None."""
        if faces is None:
            return self
        from .parts import subset_faces
        return DisplaySplit(self.vertex, self.uv, subset_faces(face_counts, self.face_indices, faces)[1])


def display_split(rig: Rig) -> DisplaySplit | None:
    """The surface split where a vertex has several UVs (for drawing a texture only: the rig's vertices are
    never reordered; a viewport gathers ``points[vertex]``). None without UVs."""
    c = rig.corners
    if c is None or c.uvs is None or c.corner_uv is None:
        return None
    per = per_vertex_uvs(rig)
    if per is not None:
        return DisplaySplit(np.arange(rig.n_vertices), per, rig.face_indices)
    t = np.where(c.corner_uv >= 0, c.corner_uv, -1).astype(np.int64)
    key = rig.face_indices.astype(np.int64) * (len(c.uvs) + 1) + (t + 1)
    uniq, inverse = np.unique(key, return_inverse=True)
    vertex = (uniq // (len(c.uvs) + 1)).astype(np.int64)
    tex = uniq % (len(c.uvs) + 1) - 1
    uv = np.where((tex >= 0)[:, None], c.uvs[np.maximum(tex, 0), :2], 0.0)
    return DisplaySplit(vertex, uv, inverse.astype(np.int32))
