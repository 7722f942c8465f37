"""The benchmarks measure the application as it runs once installed: its modules byte-compiled.

``pip install`` byte-compiles a package when it installs it, and an editable install (``pip install -e``) writes
each module's bytecode on its first import; every later process reads it. Where ``PYTHONDONTWRITEBYTECODE`` is set
(the development machine sets it), nothing writes it, and every process -- the command, the batch's fork server --
compiled each changed module from source again: ~30 ms of the fork server's imports, as much again in the command.
"""
from __future__ import annotations

import compileall
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session", autouse=True)
def installed_bytecode() -> None:
    """The project's modules byte-compiled, as an installation has them (only those not yet or no longer current)."""
    for package in ("app", "model", "solvers", "widgets", "tests"):
        compileall.compile_dir(ROOT / package, quiet=1)


@pytest.fixture(autouse=True)
def closed_windows_let_go():
    """After each benchmark, what a closed main window still holds is let go. A closed window stays alive in this
    process (something outside Python's view still refers to it: its C++ side is gone, the Python object stays), and
    with it its document, rig, caches and views' arrays: a whole benchmark run opens the studio rigs (GBs each) a
    dozen times and ran out of the machine's 24 GB. The application closes its one window as it quits, so only a
    process that opens many windows (this one) has to."""
    yield
    import gc

    from app.main_window import MainWindow
    gc.collect()
    for window in [o for o in gc.get_objects() if isinstance(o, MainWindow)]:
        try:
            if window.isVisible():
                continue
        except RuntimeError:    # its C++ object is deleted: closed
            pass
        owned = [v for v in vars(window).values() if hasattr(v, "__dict__") and not isinstance(v, type)]
        for value in owned:
            vars(value).clear()
        vars(window).clear()
    gc.collect()
