"""BLAS thread limits: the app and the command line run numpy's and scipy's BLAS single-threaded."""
from __future__ import annotations

import json
import os
import subprocess
import sys

from app.runtime import blas_threads

# In a fresh interpreter without the limit's environment variables: start the command line as the
# `blendshape-studio` script does (app.cli.main), then load scipy's BLAS too, and report every library.
_PROBE = """
import json, sys
from app.cli import main
main(["sample", "-o", sys.argv[1]])
import scipy.linalg  # scipy's own OpenBLAS, loaded after the limit was set
from app.runtime import blas_threads
print(json.dumps(blas_threads()))
"""


def test_the_test_session_runs_blas_single_threaded():
    import scipy.linalg  # noqa: F401
    threads = blas_threads()
    assert len(threads) >= 2 and set(threads.values()) == {1}, threads   # numpy's and scipy's


def test_the_command_line_limits_every_blas_library(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", _PROBE, str(tmp_path / "sample")], capture_output=True, text=True,
                         env=env, check=True, timeout=300).stdout
    threads = json.loads(out.strip().splitlines()[-1])
    assert len(threads) >= 2 and set(threads.values()) == {1}, threads
    assert any("numpy" in path for path in threads) and any("scipy" in path for path in threads)
