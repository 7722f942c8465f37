"""Opening rigs and projects off the GUI thread, with progress; what a file dropped on the window is."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from PySide6 import QtCore

from model.errors import RigInputError
from model.gltf import DEFAULT_POSE
from model.project import Project, load_project
from model.readers import load_rig
from model.rig_prep import prepare_rig


def open_project_or_rig(path: str | Path, progress=None) -> Project:
    """A Project from a .bsproj, or a new Project around a rig read from a folder/glTF/OBJ (a glTF posed with its
    mesh's default weights, as Blender and glTF viewers show it)."""
    path = Path(path)
    if path.suffix.lower() == ".bsproj":
        return load_project(path)
    rig = load_rig(path, progress=progress)
    if rig.n_shapes == 0:   # a folder with its neutral alone, a glTF without morph targets: nothing to pose
        what = "no OBJ beside its neutral" if path.is_dir() or path.suffix.lower() == ".obj" else "no morph targets"
        raise RigInputError(f"{path}: has no blendshapes ({what}), so there is nothing to pose; a rig needs at "
                            "least one shape besides its neutral.")
    default = rig.presets.get(DEFAULT_POSE)   # a glTF's default weights: the pose its viewers show it in
    weights = None if default is None else np.array([default.get(n, 0.0) for n in rig.shape_names])
    return Project(rig=rig, weights=weights)


RIG_SUFFIXES = (".bsproj", ".gltf", ".glb", ".obj")
TAKE_SUFFIXES = (".c3d", ".trc", ".csv")
MAP_SUFFIXES = (".json",)
DROP_ORDER = ("rig", "take", "map")   # a rig first (the take and map need it), the take before its map


def dropped_kind(path: str | Path) -> str:
    """What a file or folder dropped on the window is: "rig" (a rig folder, project, glTF or OBJ: File ▸ Open),
    "take" (C3D, TRC or CSV: Mocap ▸ Load Take) or "map" (a marker map, JSON); anything else is one sentence."""
    path = Path(path)
    if path.is_dir():
        return "rig"
    suffix = path.suffix.lower()
    if not path.exists():
        raise RigInputError(f"{path}: does not exist.")
    for kind, suffixes in (("rig", RIG_SUFFIXES), ("take", TAKE_SUFFIXES), ("map", MAP_SUFFIXES)):
        if suffix in suffixes:
            return kind
    raise RigInputError(f"{path}: is not something Blendshape Studio opens (a rig folder, a project, a glTF, "
                        f"an OBJ, a take in C3D, TRC or CSV, or a marker map in JSON).")


def opens_as(path: str | Path) -> str:
    """``dropped_kind`` for a path given to open (the command line, Open Recent): "rig" for what it cannot tell,
    whose loader then says what is wrong with it."""
    try:
        return dropped_kind(path)
    except RigInputError:
        return "rig"


def sort_dropped(paths) -> list[tuple[str, Path]]:
    """(kind, path) for dropped files in the order they must open (``DROP_ORDER``); raises on the first file
    that is not a rig, project, take or marker map."""
    items = [(dropped_kind(p), Path(p)) for p in paths]
    return sorted(items, key=lambda item: DROP_ORDER.index(item[0]))


class LoadWorker(QtCore.QThread):
    """Loads in a thread, and prepares what the window derives from the rig (``model.rig_prep``); the GUI stays
    responsive and shows progress."""

    progress = QtCore.Signal(int, int, str)
    loaded = QtCore.Signal(object, object)   # Project, RigPrep of its rig
    failed = QtCore.Signal(str)

    def __init__(self, path: str | Path, parent=None) -> None:
        super().__init__(parent)
        self.path = Path(path)

    def run(self) -> None:
        try:
            project = open_project_or_rig(self.path, progress=lambda d, t, w: self.progress.emit(d, t, w))
            self.progress.emit(0, 0, "the shapes")
            prep = prepare_rig(project.rig)
        except RigInputError as exc:
            self.failed.emit(str(exc))
        except MemoryError:
            self.failed.emit(f"{self.path}: not enough memory to open it.")
        except Exception as exc:  # an unexpected failure still must not take the open rig down
            self.failed.emit(f"{self.path}: could not be opened ({type(exc).__name__}: {exc}).")
        else:
            self.loaded.emit(project, prep)
