"""Open a rig from any supported source: an OBJ folder, a glTF/GLB file or a .bsproj project."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Optional

import numpy as np

from solvers.parallel import ordered_map

from .errors import RigInputError
from .input_files import regular_file
from .obj_io import read_obj, read_obj_target
from .pages import small_pages_for
from .presets import fitting_presets
from .rig import Rig, checked_presets

Progress = Optional[Callable[[int, int, str], None]]  # (done, total, what) -> None


def find_neutral(paths: list[Path], neutral: str | None, folder: Path) -> Path:
    """The neutral OBJ: named by ``neutral`` (file name or stem), else the one file with 'neutral' in its name."""
    if neutral:
        hits = [p for p in paths if p.name == neutral or p.stem == neutral]
        if not hits:
            raise RigInputError(f"{folder}: has no OBJ named '{neutral}' to use as the neutral.")
        return hits[0]
    hits = [p for p in paths if "neutral" in p.stem.lower()]
    if not hits:
        raise RigInputError(f"{folder}: no OBJ has 'neutral' in its name; name the neutral with --neutral.")
    if len(hits) > 1:
        raise RigInputError(f"{folder}: more than one OBJ could be the neutral ({', '.join(p.name for p in hits)}); "
                            "name one with --neutral.")
    return hits[0]


def load_obj_folder(folder: str | Path, neutral: str | None = None, units: str = "cm",
                    progress: Progress = None) -> Rig:
    """Read a folder of OBJs (one per shape, same vertex order) into a Rig. Shape names are file stems."""
    folder = Path(folder)
    if not folder.is_dir():
        raise RigInputError(f"{folder}: is not a folder.")
    paths = sorted(regular_file(p) for p in folder.iterdir() if p.suffix.lower() == ".obj")   # a folder named
    if not paths:                                     # x.obj is no shape (it was passed over: a shape gone unsaid)
        raise RigInputError(f"{folder}: contains no OBJ files.")
    neutral_path = find_neutral(paths, neutral, folder)
    targets = [p for p in paths if p != neutral_path]
    stems = [p.stem for p in targets]
    lower = [s.lower() for s in stems]
    dup = sorted({s for s in stems if lower.count(s.lower()) > 1})
    if dup:
        raise RigInputError(f"{folder}: duplicate shape names (differing only in case): {', '.join(dup)}.")
    total = len(paths)
    if progress:
        progress(0, total, neutral_path.name)
    base = read_obj(neutral_path)
    if base.face_counts.size == 0:
        raise RigInputError(f"{neutral_path}: the neutral has no faces.")
    shape = (len(targets), len(base.vertices), 3)
    with small_pages_for(int(np.prod(shape)) * 8):   # a studio-scale rig's deltas: ordinary pages (model.pages)
        deltas = np.empty(shape, dtype=np.float64)

    def read_target(k: int) -> None:   # on the machine's cores: the reads and the number parsing release the GIL
        np.subtract(read_obj_target(targets[k], base), base.vertices, out=deltas[k])
    for k, _ in enumerate(ordered_map(read_target, range(len(targets)))):   # the first bad file in order stops it
        if progress:
            progress(k + 1, total, targets[k].name)
    if progress:
        progress(total, total, "done")
    rig = Rig(neutral=base.vertices, face_counts=base.face_counts, face_indices=base.face_indices,
              shape_names=stems, deltas=deltas, units=units, name=folder.name, source=str(folder),
              corners=base.corners)
    own = folder / PRESETS_FILE
    rig.presets = read_presets(own, stems) if own.is_file() else fitting_presets(stems)
    if base.corners is not None:
        from .parts import obj_materials
        rig.materials, notes = obj_materials(neutral_path, base.corners.records)
        base.corners.notes.extend(notes)
    return rig


PRESETS_FILE = "presets.json"


def read_presets(path: Path, shape_names: list[str]) -> dict[str, dict[str, float]]:
    """Optional named weight sets beside the OBJs: {"happy": {"mouthSmile_L": 1.0, ...}, ...}."""
    from .json_file import read_json_file
    if not path.is_file():
        return {}
    data = read_json_file(path)
    return checked_presets(data, shape_names, str(path))


def load_rig(path: str | Path, neutral: str | None = None, units: str | None = None,
             progress: Progress = None, mesh: str | None = None) -> Rig:
    """Open an OBJ folder, a glTF/GLB file or a .bsproj project as a Rig (``mesh``: which glTF mesh)."""
    path = Path(path)
    if not path.exists():
        raise RigInputError(f"{path}: does not exist.")
    if path.is_dir():
        return load_obj_folder(path, neutral=neutral, units=units or "cm", progress=progress)
    suffix = path.suffix.lower()
    if suffix == ".bsproj":
        from .project import load_project
        return load_project(path).rig
    if suffix in (".gltf", ".glb"):
        from .gltf import load_gltf
        return load_gltf(path, units=units or "m", mesh=mesh)
    if suffix == ".obj":
        return load_obj_folder(path.parent, neutral=neutral or path.name, units=units or "cm", progress=progress)
    raise RigInputError(f"{path}: unknown rig format '{path.suffix}'; open an OBJ folder, a .gltf/.glb or a .bsproj.")
