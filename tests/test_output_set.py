"""Several outputs written as one set survive kill -9 at any moment: after the next start every file is
from the same generation, and no temporary file remains (issue 17)."""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from model.output_set import finish_interrupted_sets, write_set

WRITER = r"""
import sys, itertools
from model.output_set import write_set
folder = sys.argv[1]
names = ["weights.csv", "cache.pc2", "report.json"]
for gen in itertools.count(int(sys.argv[2])):
    tag = f"generation {gen}\n".encode()
    write_set({f"{folder}/{n}": (lambda f, t=tag, k=k: f.write(t + bytes(300_000 * (k + 1))))
               for k, n in enumerate(names)})
    print(gen, flush=True)
"""


def _generations(folder: Path) -> set[str]:
    return {(folder / n).read_bytes().split(b"\n", 1)[0].decode() for n in ("weights.csv", "cache.pc2", "report.json")}


def _kill_runs(tmp_path: Path, runs: int, seed: int) -> None:
    rng = random.Random(seed)
    folder = tmp_path / "out"
    folder.mkdir()
    write_set({folder / n: (lambda f: f.write(b"generation 0\n")) for n in ("weights.csv", "cache.pc2", "report.json")})
    repo = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(repo))
    for run in range(runs):
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(folder), str(run * 1000 + 1)], env=env,
                                stdout=subprocess.PIPE)
        proc.stdout.readline()                                  # it is writing sets now
        time.sleep(rng.uniform(0, 0.05))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
        finish_interrupted_sets(folder)                         # what the next start does
        assert len(_generations(folder)) == 1, f"run {run}: mixed set {_generations(folder)}"
        left = sorted(p.name for p in folder.iterdir() if p.name.startswith("."))
        assert left == [], f"run {run}: left behind {left}"


def test_sets_survive_kill_minus_9(tmp_path):
    _kill_runs(tmp_path, 12, seed=1)


@pytest.mark.fuzz
def test_sets_survive_100_kills(tmp_path):
    _kill_runs(tmp_path, 100, seed=2)


def test_a_writer_that_fails_leaves_the_old_set(tmp_path):
    write_set({tmp_path / "a": lambda f: f.write(b"old"), tmp_path / "b": lambda f: f.write(b"old")})

    def broken(f):
        raise OSError("disk full")
    with pytest.raises(OSError):
        write_set({tmp_path / "a": lambda f: f.write(b"new"), tmp_path / "b": broken})
    assert (tmp_path / "a").read_bytes() == (tmp_path / "b").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]


def test_a_set_with_a_folder_where_a_file_goes_is_refused_before_any_file_is_written(tmp_path):
    """A target that is an existing folder (or a path through a file) is one sentence naming it, raised before
    anything is written: the set stays the old one whole and no temporary or journal is left (before, the other
    files were replaced, then the move onto the folder failed with IsADirectoryError, leaving both)."""
    from model.atomic import atomic_write
    from model.errors import RigInputError
    names = ("w.csv", "c.pc2")
    write_set({tmp_path / n: lambda f: f.write(b"old") for n in names})
    (tmp_path / "report").mkdir()
    for bad, words in ((tmp_path / "report", f"{tmp_path / 'report'}: is a folder, not a file."),
                       (tmp_path / "w.csv" / "r.json", f"{tmp_path / 'w.csv'} is a file, not a folder.")):
        with pytest.raises(RigInputError) as refused:
            write_set({tmp_path / "w.csv": lambda f: f.write(b"new"), tmp_path / "c.pc2": lambda f: f.write(b"new"),
                       bad: lambda f: f.write(b"new")})
        assert str(refused.value).endswith(words), str(refused.value)
        assert [(tmp_path / n).read_bytes() for n in names] == [b"old", b"old"]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["c.pc2", "report", "w.csv"]
    with pytest.raises(RigInputError, match="is a folder, not a file"):
        atomic_write(tmp_path / "report", b"new")
    assert list((tmp_path / "report").iterdir()) == [] and len(list(tmp_path.iterdir())) == 3


def test_files_get_the_users_umask(tmp_path):
    old = os.umask(0o002)
    try:
        write_set({tmp_path / "shared.csv": lambda f: f.write(b"x")})
    finally:
        os.umask(old)
    assert (tmp_path / "shared.csv").stat().st_mode & 0o777 == 0o664
