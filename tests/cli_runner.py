"""Run the installed ``blendshape-studio`` command as a user would, in a subprocess."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path


def command() -> list[str]:
    exe = Path(sys.executable).parent / "blendshape-studio"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("blendshape-studio")
    return [found] if found else [sys.executable, "-m", "app.launch"]


def run_cli(*args, check: bool = True, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    full_env = dict(os.environ)
    full_env.update(env or {})
    proc = subprocess.run(command() + [str(a) for a in args], capture_output=True, text=True, env=full_env,
                          timeout=timeout)
    if check and proc.returncode != 0:
        raise AssertionError(f"blendshape-studio {' '.join(map(str, args))} failed ({proc.returncode}):\n{proc.stderr}")
    return proc
