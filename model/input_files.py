"""Opening what the user named, and nothing else: regular files only (a FIFO would block, a link to a
device would be read forever), each refusal one sentence naming the path."""
from __future__ import annotations

import os
import stat
from pathlib import Path

from .errors import RigInputError


def regular_file(path: str | Path) -> Path:
    """``path`` if it names an existing regular file (links to one are fine); else RigInputError."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise RigInputError(f"{path}: does not exist.") from None
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror}).") from None
    if stat.S_ISDIR(st.st_mode):
        raise RigInputError(f"{path}: is a folder, not a file.")
    if not stat.S_ISREG(st.st_mode):
        raise RigInputError(f"{path}: is not a regular file (a device, pipe or socket); nothing was read.")
    return path


def read_input_bytes(path: str | Path) -> bytes:
    """The whole content of a regular file the user named; a missing, special, unreadable or empty file is one
    RigInputError sentence."""
    path = regular_file(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RigInputError(f"{path}: cannot be read ({exc.strerror or exc}).") from None
    if not data:
        raise RigInputError(f"{path}: the file is empty.")
    return data
