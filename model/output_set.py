"""Writing several files as one set: after a crash or a kill, either every file is the new one or every
file is the old one (issue 17: a killed ``solve`` left a new weights CSV beside the old cache and report).

Each file is first written completely to a temporary file beside its target (fsynced). Then a journal
(``.<first target>.bs-set.json``) lists the moves, and the moves are made; the journal is removed last.
If the process dies before the journal exists, the old files are untouched and the temporaries are
leftovers (removed by ``finish_interrupted_sets``); if it dies after, the next ``finish_interrupted_sets`` of
that folder (every ``write_set`` call runs it first, and ``batch`` on its output folder) completes the moves:
the new set. Any atomic write to the folder also removes the orphaned temporaries (``model.atomic``).
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import IO, Callable

from .atomic import (JOURNAL_SUFFIX, atomic_write, check_output_file, disk_errors, disk_problem, disk_write_error,
                     remove_stale_temporaries, write_temporary)
from .errors import RigInputError


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_set(writers: dict[str | Path, Callable[[IO[bytes]], object]]) -> None:
    """Write every ``path: writer(file)`` as one set (all in their own folders; one journal beside the first).
    Every target is checked first (``check_output_file``: not a folder, a device or a path through a file; no
    two the same file): a set that cannot be written whole is refused in one sentence before anything is
    written, not found out after some of its files were replaced."""
    items = [(Path(p), w) for p, w in writers.items()]
    if not items:
        return
    seen: dict[str, Path] = {}
    for path, _ in items:
        check_output_file(path)
        key = os.path.realpath(path)
        if key in seen:
            raise RigInputError(f"{path}: is named for two of the files written together ({seen[key]} too).")
        seen[key] = path
    for folder in {p.parent for p, _ in items}:
        with disk_errors(items[0][0]):
            folder.mkdir(parents=True, exist_ok=True)
        finish_interrupted_sets(folder)
    temps: list[tuple[Path, Path]] = []
    try:
        for path, writer in items:
            temps.append((write_temporary(path, writer), path))
        first = items[0][0]
        journal = first.with_name(f".{first.name}{JOURNAL_SUFFIX}")
        atomic_write(journal, json.dumps({"moves": [[str(t), str(p)] for t, p in temps]}).encode())
        _fsync_dir(journal.parent)          # the journal in place is the commit point: the new set wins
    except BaseException:
        for tmp, _ in temps:
            tmp.unlink(missing_ok=True)
        raise
    _complete(journal)


def _complete(journal: Path) -> None:
    try:
        moves = json.loads(journal.read_text())["moves"]
    except (OSError, ValueError, KeyError, TypeError):
        journal.unlink(missing_ok=True)
        return
    folders = set()
    for i, (tmp, final) in enumerate(moves):
        tmp, final = Path(tmp), Path(final)
        try:
            if tmp.exists():
                os.replace(tmp, final)
        except OSError as exc:   # the journal stays: the rest are moved in by the next look at the folder
            words = disk_problem(final, exc)
            if words is None:
                raise
            raise disk_write_error(f"{final}: {words[0]} while the {len(moves)} files written together were moved "
                                   f"into place ({i} of them are new); the rest become new the next time a set is "
                                   f"written to {journal.parent}; {words[1]}.", exc) from exc
        folders.add(final.parent)
    for folder in folders:
        _fsync_dir(folder)
    journal.unlink(missing_ok=True)


def finish_interrupted_sets(folder: str | Path) -> int:
    """Complete the sets whose journal was written (the new files win), then remove this application's
    temporaries left by writers that are gone. Returns the number of files finished or removed."""
    folder = Path(folder)
    n = 0
    if not folder.is_dir():
        return 0
    for journal in folder.glob(f".*{JOURNAL_SUFFIX}"):
        _complete(journal)
        n += 1
    return n + remove_stale_temporaries(folder)
