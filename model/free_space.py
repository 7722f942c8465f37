"""Room for an output on its disk, checked before any work (``check_free_space``): a PC2 cache of a long take
(200,000 frames of ICT: 32 GB) or an animated glTF written to a disk without the room filled it and failed at the
end. The command line sizes what it will write (``model.take_exports.solve_output_sizes``, ``model.export``'s
``export_size``) and refuses, in one sentence naming the file, the size and the space free, what cannot fit."""
from __future__ import annotations

import os
import shutil
from collections.abc import Collection, Mapping
from pathlib import Path

from .errors import RigInputError


def human_size(n: float) -> str:
    """Bytes in the units a file manager shows (decimal: 1 GB = 10⁹ bytes): '31.9 GB', '512 KB', '80 bytes'."""
    if n < 1000:
        return f"{int(n)} bytes"
    for unit in ("KB", "MB", "GB", "TB", "PB"):
        n /= 1000.0
        if n < 1000 or unit == "PB":
            return f"{n:.3g} {unit}" if n < 100 else f"{n:.0f} {unit}"
    raise AssertionError("unreachable")


def existing_folder(path: Path) -> Path:
    """The folder ``path`` will be written in, or the nearest folder above it that exists (the writer makes the
    rest)."""
    folder = path.absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def check_free_space(sizes: Mapping[str | Path, int], lower_bounds: Collection[str | Path] = (),
                     named: str | None = None) -> None:
    """Refuse (RigInputError) outputs ``{path: bytes}`` that do not fit in the free space of their disk: the files
    on one disk together, each written whole beside any old one before replacing it (``model.atomic``), so an old
    file frees nothing. ``lower_bounds``: the outputs whose sizes are the least they will be (the sentence says
    "at least"). ``named``: what the sentence calls the files ("OUTDIR: the caches of ..."), else their paths."""
    bounds = {str(p) for p in lower_bounds}
    by_disk: dict[int, list[tuple[Path, int, Path]]] = {}
    for path, size in sizes.items():
        if size <= 0:
            continue
        folder = existing_folder(Path(path))
        by_disk.setdefault(os.stat(folder).st_dev, []).append((Path(path), int(size), folder))
    for files in by_disk.values():
        folder = files[0][2]
        free = shutil.disk_usage(folder).free
        needed = sum(size for _, size, _ in files)
        if needed <= free:
            continue
        names = named or " and ".join(str(p) for p, _, _ in files) + ":"
        many = named is not None or len(files) > 1
        together = " together" if many else ""
        at_least = any(str(p) in bounds for p, _, _ in files)
        raise RigInputError(f"{names} need{'' if many else 's'}{' at least' if at_least else ''} "
                            f"{human_size(needed)}{together}, but the disk of {folder} has {human_size(free)} free; "
                            "free some space or write to another disk.")
