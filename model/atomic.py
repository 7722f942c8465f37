"""Atomic file writes: write a temporary file in the same folder, fsync, then os.replace.

A crash mid-save leaves the previous file intact (DESIGN.md, Project). The file gets the permissions a
plain ``open(path, "w")`` would give (0666 minus the user's umask), so a team on a shared drive can read
it; ``mkstemp`` alone would leave it readable by its owner only (0600).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable, IO


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


def atomic_write(path: str | Path, data: bytes) -> None:
    atomic_write_with(path, lambda f: f.write(data))


def atomic_write_with(path: str | Path, writer: Callable[[IO[bytes]], object]) -> None:
    """Call writer(file) on a temporary file beside path and move it into place when complete."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        if hasattr(os, "fchmod"):
            os.fchmod(fd, 0o666 & ~current_umask())
        with os.fdopen(fd, "wb") as f:
            writer(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
