"""Reading JSON files the user names, with one clear sentence for each way they can be bad."""
from __future__ import annotations

import json
from pathlib import Path

from .errors import RigInputError


def read_json_file(path: str | Path):
    """The parsed content of a JSON file; a missing, empty or invalid file raises RigInputError."""
    path = Path(path)
    if not path.is_file():
        raise RigInputError(f"{path}: does not exist.")
    text = path.read_text(encoding="utf-8", errors="replace")
    if not text.strip():
        raise RigInputError(f"{path}: the file is empty.")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise RigInputError(f"{path}: is not valid JSON ({exc.msg} at line {exc.lineno}).") from None
