"""What the command line and the GUI do with an error nobody expected: one sentence for the user and a
crash log file with the traceback that they can attach to a report. No Qt here: both front ends call it.

Crash logs go to ``$BLENDSHAPE_STUDIO_LOGS`` if set, else the user's state folder
(``$XDG_STATE_HOME/blendshape-studio/crashes``, by default ``~/.local/state/blendshape-studio/crashes``).
"""
from __future__ import annotations

import datetime as _dt
import os
import platform
import sys
import traceback
from pathlib import Path

KEEP_LOGS = 50   # the newest crash logs kept; older ones are removed when a new one is written


def crash_dir() -> Path:
    explicit = os.environ.get("BLENDSHAPE_STUDIO_LOGS")
    if explicit:
        return Path(explicit)
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(state) / "blendshape-studio" / "crashes"


def write_crash_log(exc: BaseException, context: str) -> Path | None:
    """Write the traceback of ``exc`` (raised while doing ``context``) to a new log file and return its
    path; None if even that fails (a read-only home), so reporting never raises in turn."""
    return _write_log(traceback.format_exception(type(exc), exc, exc.__traceback__), context)


def log_unexpected_rows(rows: list[dict], context: str) -> None:
    """Batch rows that failed unexpectedly (``model.batch.solve_and_report``: a ``"traceback"`` from the worker):
    each traceback to a crash log, whose path the row's error then names, as ``describe_unexpected`` does."""
    for row in rows:
        text = row.pop("traceback", None)
        if text:
            log = _write_log([text], f"{context} {row.get('path')}")
            if log is not None and row.get("error"):
                row["error"] = f"{row['error'].rstrip('.')}; the details are in {log}."


def _write_log(traceback_lines: list[str], context: str) -> Path | None:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S-%f")
    try:
        folder = crash_dir()
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"crash-{stamp}-{os.getpid()}.log"
        lines = [f"Blendshape Studio crash log, {_dt.datetime.now().isoformat(timespec='seconds')}",
                 f"while: {context}",
                 f"python {sys.version.split()[0]} on {platform.platform()}",
                 f"command: {' '.join(sys.argv)}", ""]
        lines += traceback_lines
        try:
            with open(path, "w", encoding="utf-8") as f:
                f.write("\n".join(line.rstrip("\n") for line in lines) + "\n")
        except OSError:      # a full disk: no half-written log is left, and none is named
            path.unlink(missing_ok=True)
            raise
        old = sorted(folder.glob("crash-*.log"))[:-KEEP_LOGS]
        for p in old:
            p.unlink(missing_ok=True)
        return path
    except OSError:
        return None


def describe_unexpected(exc: BaseException, context: str) -> str:
    """One sentence for an unexpected error, naming what was being done and where the details are."""
    if isinstance(exc, MemoryError):
        what = "ran out of memory"
    else:
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        what = f"failed unexpectedly ({type(exc).__name__}{': ' + detail[:200] if detail else ''})"
    log = write_crash_log(exc, context)
    where = f"; the details are in {log}" if log else ""
    return f"{context} {what}{where}."
