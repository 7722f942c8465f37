"""Outputs that would land among what an input folder's reader reads (``check_beside``): a posed OBJ written into
the rig's OBJ folder is read as one more shape the next time the rig is opened (and an existing one there is
overwritten), an OBJ among the scans as one more scan; and the files a ``.gltf`` input refers to (``gltf_files``: its
external buffers and images), which an output written over would destroy. One rule, without Qt, for the command
line's output checks (``app.cli_common.check_not_an_input``) and the window's exports (``check_not_inputs``)."""
from __future__ import annotations

import json
import os
from pathlib import Path
from urllib.parse import unquote

from .errors import RigInputError
from .textures import MASK_NAME, NORMAL_SUFFIX, SUFFIXES as IMAGE_SUFFIXES


def check_beside(out: str, folder: str, reads: str, start: str, end: str) -> None:
    """An output ``out`` in the ``folder`` an input is read from (``reads``: "rig", "scans" or "takes"): refused, in
    the sentence ``start`` ... ``end``, if the folder's reader reads it: an OBJ (a shape, or a scan), a take file
    (.c3d, .trc, .csv: ``batch`` reads every one in a folder of takes), and for a rig its ``presets.json``, its
    materials (an existing ``.mtl``) and a picture named after a shape's OBJ or the neutral's (that one's texture,
    ``model.textures``) or the keep mask. Any other file there (a render's ``preview.png``, a ``regions.json``) is no
    part of the rig."""
    from .readers import PRESETS_FILE
    from .takes import TAKE_SUFFIXES
    name = os.path.basename(out)
    stem, suffix = os.path.splitext(name)
    suffix, exists = suffix.lower(), os.path.exists(out)
    shape = stem[:-len(NORMAL_SUFFIX)] if stem.endswith(NORMAL_SUFFIX) else stem
    if reads == "takes":
        if suffix not in TAKE_SUFFIXES:
            return
        read_as = "one more take"
    elif suffix == ".obj":
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


def check_not_input(path: str | Path, source: str | Path, name: str, reader: str, fix: str, *, reads: str = "rig",
                    same_ok: bool = False, where: str = "which {name} reads") -> None:
    """Refuse an output ``path`` that is the input ``source`` (a file or a folder; ``same_ok``: that one is allowed),
    a file a ``.gltf`` source refers to (``gltf_files``), or a file the reader of a folder source (``reads``: "rig",
    "scans" or "takes"; for a rig, an ``.obj`` source's folder too) reads there (``check_beside``). The one rule of the
    command line's outputs (``app.cli_common.check_not_an_input``) and of the window's exports (``check_not_inputs``).
    The sentence names ``path`` and the input as ``name`` (``reader``: who reads it; ``where``: what the folder is
    to it); ``fix`` says what to do, formatted with "another file" or "a file elsewhere"."""
    out, real = os.path.realpath(path), os.path.realpath(source)
    if real == out:
        if not same_ok:
            raise RigInputError(f"{path}: is {name} itself, which {reader}; {fix.format('another file')}.")
        return
    for kind, uri, referred in gltf_files(real):   # a .gltf's external buffers and images are input too
        if referred == out:
            raise RigInputError(f"{path}: is the {kind} file '{uri}' that {name} ({source}) reads; "
                                f"{fix.format('another file')}.")
    folder = real if os.path.isdir(real) else \
        os.path.dirname(real) if reads == "rig" and real.lower().endswith(".obj") else None
    if folder and os.path.dirname(out) == folder:
        shown_folder = source if folder == real else os.path.dirname(str(source)) or "."
        check_beside(out, folder, reads, f"{path}: is in {shown_folder}, {where.format(name=name)}, and would",
                     f"; {fix.format('a file elsewhere')}.")


def check_not_inputs(path: str | Path, inputs: list[tuple[str, str | Path | None]], fix: str = "choose {}") -> None:
    """The window's exports (File ▸ Export Rig, Export Pose as OBJ, Export Image, the keyed animation's and the Mocap
    panel's), its personalised project and its batches' files: refuse ``path`` when it is one of the files the window
    has open, ``inputs`` as (what it is: "the rig", "the project", ...; its path, None for none), by
    ``check_not_input``: the file itself, a ``.gltf``'s buffers and images, what an OBJ folder's reader reads there
    (a posed OBJ would be read as one more shape). ``fix``: what to do instead (as ``check_not_input``'s)."""
    for name, source in inputs:
        if source and os.path.exists(source):    # the bundled sample rig, a take since deleted: nothing to keep
            check_not_input(path, source, name, "the window has open", fix, where="the folder {name} is read from")


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
