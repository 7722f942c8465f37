"""The ``blendshape-studio`` command's entry point: ``app.cli.main``, except that a ``batch`` on the local cluster
starts the cluster's fork server (``model.fork_server``) before anything else is imported, so that its imports of
what the workers need (~2 s of CPU: Dask, the solver, VTK) overlap the command's own imports (~0.3 s) and the rig's
load on the other core. Standard library only until then; then scipy's array-API layer is imported without the
numpy submodules it would load for nothing (``model.scipy_import``), before the command's own imports.
"""
from __future__ import annotations

import os
import sys

from app.command_line import opens_window


def starts_local_cluster(argv: list[str]) -> bool:
    """Whether the command line is a ``batch`` that will run on a local cluster (not ``--scheduler``, not help)."""
    return bool(argv) and argv[0] == "batch" and not any(
        a in ("-h", "--help") or a == "--scheduler" or a.startswith("--scheduler=") for a in argv[1:])


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    from app.runtime import quiet_numeric_warnings
    quiet_numeric_warnings()      # before the batch's fork server starts: its workers inherit it
    if not opens_window(argv):
        # A command's large arrays (the rig's deltas, the dense cache's blocks) are written once and dropped: numpy's
        # request for transparent huge pages (madvise) for every array of 4 MB or more then costs more in the
        # kernel's compaction and zeroing on first touch than the pages save (solve --cache --report on ICT: 0.20-0.24
        # s of system time without, 0.22-0.48 s with; the batch's workers ask the same, ``model.batch_env``). The
        # window keeps them: its arrays live for the session. Read by numpy when it is imported, below.
        os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
    if starts_local_cluster(argv):
        from app.batch_preload import BATCH_PRELOAD
        from model.fork_server import start_fork_server
        start_fork_server(BATCH_PRELOAD)
    import model.scipy_import  # noqa: F401  (scipy's array-API layer without numpy's f2py, testing ...: ~0.07 s)
    from app.cli import main as cli_main
    return cli_main(argv)


if __name__ == "__main__":
    sys.exit(main())
