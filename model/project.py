"""The ``.bsproj`` project file: one zip holding a JSON manifest plus ``.npy`` arrays (DESIGN.md).

The rig (neutral, faces, deltas, correctives, presets), the current pose and one JSON-able section per
feature (segmentation settings, markers, keyframes, takes, solve settings). Arrays are stored
uncompressed, so saving and opening ICT FaceKit (36 MB of deltas) takes a fraction of a second.
Saved atomically (model.atomic): a crash mid-save leaves the previous file intact.
"""
from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_write_with
from .errors import RigInputError
from .rig import Rig

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

    def __post_init__(self) -> None:
        if self.weights is None:
            self.weights = np.zeros(self.rig.n_shapes)
        self.weights = np.asarray(self.weights, dtype=np.float64)


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


def save_project(project: Project, path: str | Path) -> None:
    """Write the project to ``path`` atomically."""
    rig = project.rig
    arrays: dict[str, np.ndarray] = {
        "rig/neutral": rig.neutral,
        "rig/face_counts": rig.face_counts,
        "rig/face_indices": rig.face_indices,
        "rig/deltas": rig.deltas,
        "pose/weights": project.weights,
    }
    correctives = []
    for i, c in enumerate(rig.correctives):
        key = f"correctives/{i}"
        arrays[key] = np.asarray(c.delta, dtype=np.float64)
        correctives.append({"name": c.name, "drivers": list(c.drivers), "rule": c.rule, "delta": key})
    for name, a in project.arrays.items():
        arrays[f"extra/{name}"] = np.asarray(a)
    manifest = {
        "format": FORMAT,
        "version": VERSION,
        "rig": {"name": rig.name, "units": rig.units, "shape_names": rig.shape_names,
                "presets": rig.presets, "source": rig.source},
        "correctives": correctives,
        "sections": project.sections,
        "arrays": {k: [list(v.shape), str(v.dtype)] for k, v in arrays.items()},
    }

    def write(f):
        with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_STORED) as z:
            z.writestr(MANIFEST, json.dumps(manifest, indent=1))
            for key, a in arrays.items():
                z.writestr(f"{key}.npy", _npy_bytes(a))

    atomic_write_with(path, write)


def load_project(path: str | Path) -> Project:
    """Read a project; a damaged file raises RigInputError naming the file and the problem."""
    path = Path(path)
    try:
        z = zipfile.ZipFile(path)
    except FileNotFoundError:
        raise RigInputError(f"{path}: does not exist.") from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise RigInputError(f"{path}: is not a readable project (damaged zip: {exc}).") from None
    with z:
        try:
            manifest = json.loads(z.read(MANIFEST).decode("utf-8"))
        except KeyError:
            raise RigInputError(f"{path}: the project has no manifest.json; it is damaged.") from None
        except (ValueError, UnicodeDecodeError, zipfile.BadZipFile) as exc:
            raise RigInputError(f"{path}: the project manifest is damaged ({exc}).") from None
        if manifest.get("format") != FORMAT:
            raise RigInputError(f"{path}: is not a Blendshape Studio project.")
        if int(manifest.get("version", 0)) > VERSION:
            raise RigInputError(f"{path}: was saved by a newer Blendshape Studio (format "
                                f"{manifest.get('version')}); update to open it.")
        declared = manifest.get("arrays", {})

        def array(key: str) -> np.ndarray:
            try:
                with z.open(f"{key}.npy") as f:
                    a = np.load(io.BytesIO(f.read()), allow_pickle=False)
            except KeyError:
                raise RigInputError(f"{path}: the project is missing the array '{key}'.") from None
            except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
                raise RigInputError(f"{path}: the array '{key}' is damaged ({exc}).") from None
            shape = declared.get(key, [None])[0]
            if shape is not None and list(a.shape) != list(shape):
                raise RigInputError(f"{path}: the array '{key}' has shape {list(a.shape)}, "
                                    f"the manifest says {shape}.")
            return a

        try:
            meta = manifest["rig"]
            rig = Rig(neutral=array("rig/neutral"), face_counts=array("rig/face_counts"),
                      face_indices=array("rig/face_indices"), shape_names=meta["shape_names"],
                      deltas=array("rig/deltas"), units=meta.get("units", "cm"), name=meta.get("name", path.stem),
                      source=str(path), presets=meta.get("presets", {}))
            if manifest.get("correctives"):
                from .correctives import Corrective, set_correctives
                set_correctives(rig, [Corrective(name=c["name"], drivers=list(c["drivers"]), rule=c["rule"],
                                                 delta=array(c["delta"])) for c in manifest["correctives"]])
            for c in rig.correctives:
                if c.delta.shape != rig.neutral.shape:
                    raise RigInputError(f"{path}: corrective '{c.name}' has {c.delta.shape[0]} vertices, "
                                        f"the rig has {rig.n_vertices}.")
            weights = array("pose/weights")
            if weights.shape != (rig.n_shapes,):
                raise RigInputError(f"{path}: the saved pose has {weights.size} weights for {rig.n_shapes} shapes.")
            extras = {k[len("extra/"):]: array(k) for k in declared if k.startswith("extra/")}
        except RigInputError as exc:
            msg = str(exc)
            raise RigInputError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from None
        except (KeyError, TypeError) as exc:
            raise RigInputError(f"{path}: the project manifest is incomplete (missing {exc}).") from None
    return Project(rig=rig, weights=weights, sections=manifest.get("sections", {}), arrays=extras)
