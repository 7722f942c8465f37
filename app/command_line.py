"""The ``blendshape-studio`` command's names, and whether a command line opens the window instead: shared by the entry
point (``app.launch``, standard library only) and the parser (``app.cli``)."""
from __future__ import annotations

COMMANDS = {"info", "take-info", "render", "export", "sample", "segment", "solve", "corrective", "pairs",
            "personalize", "batch"}


def opens_window(argv: list[str]) -> bool:
    """Whether the command line opens the window (no arguments, or a rig or project to open) rather than running a
    command."""
    return not argv or (argv[0] not in COMMANDS and not argv[0].startswith("-"))
