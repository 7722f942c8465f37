"""BLAS thread limits: the app and the command line run numpy's and scipy's BLAS single-threaded."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from app.runtime import blas_threads

# In a fresh interpreter without the limit's environment variables, start as the `blendshape-studio` script
# does (app.cli.main): a command, or the GUI (its start replaced by a report once the window's modules, Qt
# and VTK, are loaded). scipy's own BLAS is loaded after the limit was set; every library is reported.
_PROBE = """
import json, sys
import app.gui
from app.cli import main
from app.runtime import blas_threads

def report():
    import scipy.linalg
    print(json.dumps(blas_threads()))

def gui_started(path):
    import app.main_window
    report()
    return 0

app.gui.run_gui = gui_started
if sys.argv[1] == "gui":
    main([])
else:
    main(["sample", "-o", sys.argv[2]])
    report()
"""


def test_the_test_session_runs_blas_single_threaded():
    import scipy.linalg  # noqa: F401
    threads = blas_threads()
    assert len(threads) >= 2 and set(threads.values()) == {1}, threads   # numpy's and scipy's


@pytest.mark.parametrize("start", ["command", "gui"])
def test_the_app_limits_every_blas_library(tmp_path, start):
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", _PROBE, start, str(tmp_path / "sample")], capture_output=True,
                         text=True, env=env, check=True, timeout=300).stdout
    threads = json.loads(out.strip().splitlines()[-1])
    assert len(threads) >= 2 and set(threads.values()) == {1}, threads
    assert any("numpy" in path for path in threads) and any("scipy" in path for path in threads)
