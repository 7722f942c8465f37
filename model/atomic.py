"""Atomic file writes: write a temporary file in the same folder, fsync, then os.replace.

A crash mid-save leaves the previous file intact (DESIGN.md, Project). A target that cannot be a file (a
folder, a device, a path through a file) is refused in one sentence before anything is written
(``check_output_file``; the command line checks every output option with it before any work). The file gets
the permissions a plain ``open(path, "w")`` would give (0666 minus the user's umask), so a team on a shared
drive can read it; ``mkstemp`` alone would leave it readable by its owner only (0600).
"""
from __future__ import annotations

import errno
import json
import os
import secrets
import shutil
import stat
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, IO

from .errors import RigInputError


def current_umask() -> int:
    """The process's umask, read without changing it where Linux tells it (/proc), else set-and-restore."""
    try:
        with open("/proc/self/status", "rb") as f:
            for line in f:
                if line.startswith(b"Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


class OutputPathError(RigInputError, OSError):
    """A path that cannot be written as asked (``check_output_file``, ``check_output_folder``): bad input, one
    sentence naming it (the command line's exit code 2), and an OSError to the callers that catch a failed write as
    one (the window's Save shows it as it showed IsADirectoryError)."""


class DiskWriteError(RigInputError, OSError):
    """A write the disk failed part-way (``disk_error``: full, over quota, a file too large for it, an input/output
    error): one sentence naming the output and the problem, bad output to the command line (exit code 2, no crash
    log) and an OSError to the callers that catch a failed write as one. ``errno`` and ``strerror`` are the
    original error's; ``str()`` is the sentence."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


DISK_ERRNOS = tuple(getattr(errno, name) for name in ("ENOSPC", "EDQUOT", "EFBIG", "EIO") if hasattr(errno, name))


def disk_error(path: str | Path | None, exc: BaseException, rename: bool = False) -> DiskWriteError | None:
    """``exc`` (raised while ``path`` was written) as one sentence naming ``path`` when the disk failed the write
    (``DISK_ERRNOS``), else None. A full disk says how much is free. A DiskWriteError is kept as it is, unless
    ``rename`` (it names one file of the output ``path``, a folder written whole)."""
    if isinstance(exc, DiskWriteError) and not rename:
        return exc
    words = disk_problem(path if path is not None else getattr(exc, "filename", None), exc)
    if words is None:
        return None
    problem, fix = words
    return disk_write_error(f"{path if path is not None else exc.filename or 'An output'}: {problem}; nothing was "
                            f"written; {fix}.", exc)


def disk_write_error(sentence: str, exc: OSError) -> DiskWriteError:
    out = DiskWriteError(sentence)
    out.errno, out.strerror = exc.errno, exc.strerror
    return out


def disk_problem(path, exc: BaseException) -> tuple[str, str] | None:
    """(the problem, what to do) in words when ``exc`` is the disk's failure to write ``path``, else None."""
    code = getattr(exc, "errno", None) if isinstance(exc, OSError) else None
    if code not in DISK_ERRNOS:
        return None
    if code == errno.ENOSPC:
        return f"the disk is full{_free_on(path)}", "free some space or write to another disk"
    if code == getattr(errno, "EDQUOT", None):
        return "your disk quota is used up", "free some of your space or write to another disk"
    if code == errno.EFBIG:
        return "the file is larger than its disk (or your limits) allow one file to be", "write to another disk"
    return "the disk reported an input/output error", "check the disk or write to another"


def _free_on(path) -> str:
    """' (3.2 MB free)' on the disk of ``path`` (or of the nearest folder above it that exists); '' if unknown."""
    from .free_space import existing_folder, human_size
    try:
        return f" ({human_size(shutil.disk_usage(existing_folder(Path(path))).free)} free)"
    except (OSError, TypeError, ValueError):
        return ""


def write_error(path: str | Path, exc: OSError) -> RigInputError:
    """The one sentence of a failed write of ``path``: its own for a RigInputError (``OutputPathError``,
    ``DiskWriteError``), the disk's problem (``disk_error``), else the system's words."""
    if isinstance(exc, RigInputError):
        return exc
    return disk_error(path, exc) or RigInputError(f"{path}: could not be written ({exc.strerror or exc}).")


def check_output_file(path: str | Path) -> Path:
    """``path`` as a file to write, or RigInputError (one sentence naming it) before anything is written: an
    existing folder (or a name ending in a slash), a device, pipe or socket, a path through a file, or a folder that
    takes no new file (``_check_writable``)."""
    text = os.fspath(path)
    if not text:
        raise OutputPathError("An output file name is empty.")
    p = Path(path)
    try:
        st = os.stat(p)
    except OSError:
        st = None
    if (st is not None and stat.S_ISDIR(st.st_mode)) or text.endswith(("/", os.sep)):
        raise OutputPathError(f"{text}: is a folder, not a file.")
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise OutputPathError(f"{text}: is not a regular file (a device, pipe or socket); nothing was written.")
    _check_folders_above(text, p)
    return p


def check_output_folder(path: str | Path) -> Path:
    """``path`` as a folder to write into (made if missing), or RigInputError (one sentence naming it): an
    existing file, a path through a file, or a folder that takes no new file (``_check_writable``)."""
    text = os.fspath(path)
    if not text:
        raise OutputPathError("An output folder name is empty.")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputPathError(f"{text}: is a file, not a folder.")
    if p.is_dir():
        _check_writable(text, p)
    else:
        _check_folders_above(text, p)
    return p


def _check_folders_above(text: str, p: Path) -> None:
    for parent in p.parents:               # the nearest that exists must be a folder (mkdir makes the rest)
        if os.path.lexists(parent):
            if not parent.is_dir():
                raise OutputPathError(f"{text}: {parent} is a file, not a folder.")
            _check_writable(text, parent)
            return


def _check_writable(text: str, folder: Path) -> None:
    """The folder an output goes into (or the nearest one above it that exists, in which the rest are made) must
    take new files: one on a read-only disk, or one the user may not write in, is refused before any work (it was
    found out at the very end, as an unexpected error with a crash log)."""
    if os.access(folder, os.W_OK | os.X_OK):
        return
    shown_folder = "the current folder" if str(folder) == "." else str(folder)
    try:
        read_only = bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        read_only = False
    why = "is on a read-only disk" if read_only else "is a folder you may not write in"
    where = "" if os.path.abspath(text) == os.path.abspath(folder) else f"cannot be written: {shown_folder} "
    raise OutputPathError(f"{text}: {where}{why}; nothing was written.")


def atomic_write(path: str | Path, data: bytes) -> None:
    atomic_write_with(path, lambda f: f.write(data))


def atomic_write_with(path: str | Path, writer: Callable[[IO[bytes]], object]) -> None:
    """Call writer(file) on a temporary file beside path and move it into place when complete."""
    path = check_output_file(path)      # a folder, a device or a path through a file: refused before writing
    with disk_errors(path):
        path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path.parent)
    tmp = write_temporary(path, writer)
    try:
        with disk_errors(path):
            os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def disk_errors(path: str | Path):
    """An OSError of the disk (``disk_error``) raised inside is raised again as one sentence naming ``path``."""
    try:
        yield
    except OSError as exc:
        error = disk_error(path, exc)
        if error is None or error is exc:
            raise
        raise error from exc


def write_png(path: str | Path, pixels, compress_level: int | None = None) -> None:
    """``pixels`` ((H, W, 3) or (H, W, 4) uint8) as a PNG at ``path``, written atomically (``atomic_write_with``);
    ``compress_level``: zlib's 0-9 (Pillow's default 6 if None: a 3840x2160 picture encodes in ~1.6 s here)."""
    import numpy as np
    from PIL import Image
    image = Image.fromarray(np.ascontiguousarray(pixels))
    options = {} if compress_level is None else {"compress_level": compress_level}
    atomic_write_with(path, lambda f: image.save(f, format="PNG", **options))


def write_temporary(path: Path, writer: Callable[[IO[bytes]], object]) -> Path:
    """Write a new temporary beside ``path`` completely (``writer(file)``, flushed and fsynced, the user's umask)
    and return it; on any failure it is removed and the error raised. Moving it into place is the caller's."""
    tmp = temp_path(path)
    with disk_errors(path):             # a full disk, a quota, a file too large, an I/O error: one sentence
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666 & ~current_umask())
        try:
            with os.fdopen(fd, "wb") as f:
                writer(f)
                f.flush()
                os.fsync(f.fileno())
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    return tmp


# --- temporaries -----------------------------------------------------------------------------------------
TEMP_MARK = ".bs-tmp-"   # every temporary this application writes: .<target>.bs-tmp-<pid>.<random><suffix>
JOURNAL_SUFFIX = ".bs-set.json"   # a set's journal of moves (``model.output_set``), beside its first file


def temp_path(path: str | Path, suffix: str = ".tmp") -> Path:
    """A new temporary name beside ``path`` that says it is ours and which process writes it."""
    path = Path(path)
    return path.with_name(f".{path.name}{TEMP_MARK}{os.getpid()}.{secrets.token_hex(4)}{suffix}")


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` of this machine still runs (ours always does)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def remove_stale_temporaries(folder: str | Path) -> int:
    """Remove this application's temporaries in ``folder`` whose writing process is gone (a kill or a crash
    mid-write); other files, temporaries a live process is still writing and those a set's journal there still
    moves in (``model.output_set``: a set whose moves stopped part-way) are left alone."""
    n = 0
    try:
        candidates = list(Path(folder).glob(f".*{TEMP_MARK}*"))
        journals = list(Path(folder).glob(f".*{JOURNAL_SUFFIX}")) if candidates else []
    except OSError:
        return 0
    kept = set()
    for journal in journals:
        try:
            kept.update(os.path.realpath(tmp) for tmp, _ in json.loads(journal.read_text())["moves"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    for tmp in candidates:
        if os.path.realpath(tmp) in kept:
            continue
        try:
            pid = int(tmp.name.rsplit(TEMP_MARK, 1)[1].split(".")[0])
        except (IndexError, ValueError):
            continue
        if not process_alive(pid):
            try:
                tmp.unlink()
                n += 1
            except OSError:
                pass
    return n
