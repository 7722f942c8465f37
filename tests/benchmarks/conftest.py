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
