"""Every reader against mutated real files (issue 17): each input is refused in one sentence or loads a
valid model; never a traceback, garbage, a hang, a memory blow-up or a native crash.

The normal run gives each reader a few hundred inputs; ``pytest -m fuzz tests/fuzz`` gives each 1,200
(over 10,000 in all). Inputs are seeded: a failure names the file kept for reproducing it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import DATA, require_data

REPO = Path(__file__).resolve().parents[2]
READERS = ["obj-folder", "gltf", "bsproj", "c3d", "trc", "marker-csv", "livelink", "weights-csv", "marker-map",
           "rig-any"]
NORMAL = int(os.environ.get("BLENDSHAPE_STUDIO_FUZZ_INPUTS", "200"))
LONG = 1200


def _fuzz(reader: str, n: int, seed: int, tmp_path: Path) -> dict:
    require_data(DATA / "mocap" / "ict_livelink_take")
    proc = subprocess.run([sys.executable, "-m", "tests.fuzz.run", "--readers", reader, "--per-reader", str(n),
                           "--seed", str(seed), "--out", str(tmp_path / "failures")],
                          cwd=REPO, capture_output=True, text=True, timeout=3600)
    assert proc.stdout.strip(), proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])["readers"][reader]


def _report(result: dict) -> str:
    lines = [f"{f['status']}: {f['input']}\n    {f['detail'].strip().splitlines()[-1] if f['detail'].strip() else ''}"
             for f in result["failures"][:15]]
    return f"{result['counts']}\n" + "\n".join(lines)


@pytest.mark.parametrize("reader", READERS)
def test_reader_survives_mutated_files(reader, tmp_path):
    result = _fuzz(reader, NORMAL, seed=1, tmp_path=tmp_path)
    assert sum(result["counts"].values()) == NORMAL
    assert result["failures"] == [], _report(result)


@pytest.mark.fuzz
@pytest.mark.parametrize("reader", READERS)
def test_reader_survives_the_long_run(reader, tmp_path):
    result = _fuzz(reader, LONG, seed=2, tmp_path=tmp_path)
    assert result["failures"] == [], _report(result)


def test_the_harness_tells_each_failure_apart(tmp_path):
    """The classification a passing run relies on: a clean refusal, a valid load, and each kind of failure."""
    from model.errors import RigInputError
    from tests.fuzz.isolate import run_isolated

    def refuse(p):
        raise RigInputError(f"{p}: is not a rig.")

    def hang(p):
        while True:
            pass

    def blow_up(p):
        return bytearray(8 << 30)

    def crash(p):
        import ctypes
        ctypes.string_at(0)

    def ok(p):
        return 1

    def bad(x):
        assert x == 2, "garbage"

    assert run_isolated(refuse, bad, "x").status == "refused"
    assert run_isolated(ok, lambda x: None, "x").status == "loaded"
    assert run_isolated(ok, bad, "x").status == "garbage"
    assert run_isolated(lambda p: {}["k"], bad, "x").status == "traceback"
    assert run_isolated(hang, bad, "x", timeout=1).status == "hang"
    assert run_isolated(blow_up, bad, "x").status == "memory"
    assert run_isolated(crash, bad, "x").status == "crash"
