"""Reading JSON files the user names, with one clear sentence for each way they can be bad."""
from __future__ import annotations

import json
from pathlib import Path

from .errors import RigInputError
from .input_files import regular_file

MAX_JSON_BYTES = 256 << 20   # far above any manifest, map or preset file; a larger one is refused unread


def _no_constants(name: str):
    raise ValueError(f"{name} is not a JSON number")


def parse_json_text(text: str, where: str):
    """Parsed JSON; NaN/Infinity, nesting deeper than Python can follow and invalid text each raise one
    RigInputError sentence naming ``where``."""
    try:
        return json.loads(text, parse_constant=_no_constants)
    except json.JSONDecodeError as exc:
        what = exc.msg.removesuffix(" at")   # "Unterminated string starting at" read "starting at at line 8"
        raise RigInputError(f"{where}: is not valid JSON ({what} at line {exc.lineno}).") from None
    except RecursionError:
        raise RigInputError(f"{where}: is nested too deeply to be a file this application wrote or reads.") from None
    except ValueError as exc:   # NaN, Infinity, or an integer too long to convert
        raise RigInputError(f"{where}: is not valid JSON ({str(exc)[:80]}).") from None


def read_json_file(path: str | Path):
    """The parsed content of a JSON file; a missing, special, huge, empty or invalid file raises RigInputError."""
    path = regular_file(path)
    size = path.stat().st_size
    if size > MAX_JSON_BYTES:
        raise RigInputError(f"{path}: is {size / 2**20:.0f} MB, too large for a JSON file of this application.")
    with open(path, "rb") as f:
        data = f.read(MAX_JSON_BYTES + 1)
    text = data.decode("utf-8", errors="replace")
    if not text.strip():
        raise RigInputError(f"{path}: the file is empty.")
    return parse_json_text(text, str(path))
