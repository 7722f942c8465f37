"""Outputs that would land among what an input folder's reader reads (``check_beside``): a posed OBJ written into
the rig's OBJ folder is read as one more shape the next time the rig is opened (and an existing one there is
overwritten), an OBJ among the scans as one more scan; and the files a ``.gltf`` input refers to (``gltf_files``: its
external buffers and images), which an output written over would destroy. One rule, without Qt, for the command
line's output checks (``app.cli_common.check_not_an_input``) and the window's File ▸ Export Pose as OBJ
(``check_not_in_rig_folder``)."""
from __future__ import annotations

import json
import os
from pathlib import Path
from urllib.parse import unquote

from .errors import RigInputError
from .textures import MASK_NAME, NORMAL_SUFFIX, SUFFIXES as IMAGE_SUFFIXES


def check_beside(out: str, folder: str, reads: str, start: str, end: str) -> None:
    """An output ``out`` in the ``folder`` an input is read from (``reads``: "rig" or "scans"): refused, in the
    sentence ``start`` ... ``end``, if the folder's reader reads it: an OBJ (a shape, or a scan), and for a rig its
    ``presets.json``, its materials (an existing ``.mtl``) and a picture named after a shape's OBJ or the neutral's
    (that one's texture, ``model.textures``) or the keep mask. Any other file there (a render's ``preview.png``, a
    ``regions.json``) is no part of the rig."""
    from .readers import PRESETS_FILE
    name = os.path.basename(out)
    stem, suffix = os.path.splitext(name)
    suffix, exists = suffix.lower(), os.path.exists(out)
    shape = stem[:-len(NORMAL_SUFFIX)] if stem.endswith(NORMAL_SUFFIX) else stem
    if suffix == ".obj":
        read_as = f"one more {'shape' if reads == 'rig' else 'scan'}"
    elif reads != "rig":
        return
    elif name == PRESETS_FILE:
        read_as = "the rig's presets"
    elif suffix in IMAGE_SUFFIXES and (shape == MASK_NAME or os.path.isfile(os.path.join(folder, shape + ".obj"))):
        read_as = "the texture keep mask" if shape == MASK_NAME else f"the texture of {shape}"
    elif suffix == ".mtl" and exists:
        read_as = "the rig's materials"
    else:
        return
    raise RigInputError(f"{start} {'overwrite a file it reads' if exists else f'be read there as {read_as}'}{end}")


def check_not_in_rig_folder(path: str | Path, rig_source: str | Path | None) -> None:
    """The window's exports: refuse ``path`` when it is in the OBJ folder the rig was read from (``rig_source``, a
    folder; anything else, a glTF or a project, has no folder of shapes) and that folder's reader reads it."""
    if not rig_source or not os.path.isdir(rig_source):
        return
    folder, out = os.path.realpath(rig_source), os.path.realpath(path)
    if os.path.dirname(out) == folder:
        check_beside(out, folder, "rig", f"{path}: is in {rig_source}, the folder the rig is read from, and would",
                     "; choose a file elsewhere.")


def gltf_files(path: str | Path) -> list[tuple[str, str, str]]:
    """The files a ``.gltf`` at ``path`` refers to beside it: (kind "buffer" or "image", its ``uri``, its real
    path) for each ``buffers[].uri`` and ``images[].uri`` that is a relative file name (not a ``data:`` URI nor a
    URL). Nothing for any other file, for a file that is no glTF JSON, or for a uri no file can have (a NUL): the
    reader says what is wrong with those."""
    path = Path(path)
    if path.suffix.lower() != ".gltf" or not path.is_file():
        return []
    try:
        with open(path, "rb") as f:
            gltf = json.loads(f.read().decode("utf-8-sig"))
    except (OSError, ValueError):
        return []
    folder = os.path.dirname(os.path.realpath(path))
    found = []
    for kind, key in (("buffer", "buffers"), ("image", "images")):
        items = gltf.get(key) if isinstance(gltf, dict) else None
        for item in items if isinstance(items, list) else []:
            uri = item.get("uri") if isinstance(item, dict) else None
            name = unquote(uri) if isinstance(uri, str) else ""
            if not name or "\0" in name or uri.startswith("data:") or "://" in uri:
                continue
            found.append((kind, uri, os.path.realpath(os.path.join(folder, name))))
    return found
