"""Outputs the command line cannot write -- a folder where a file goes, a file where a folder goes, a pipe, a path
through a file, one file named for two outputs -- are refused before any work, in one sentence naming the path,
with exit code 2: nothing the user had is replaced and no temporary or journal is left behind."""
from __future__ import annotations

import os
import sys

import pytest

from tests.cli_runner import run_cli
from tests.rig_files import write_rig_folder


def _refused(proc, sentence: str) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr == f"error: {sentence}\n", proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""


def _listing(folder) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_solve_refuses_a_report_that_is_a_folder_and_keeps_the_old_outputs(ict_dir, take_dir, tmp_path):
    """The audit's case: `--report DIR` beside existing outputs. Before, the take was solved, w.csv and c.pc2 were
    replaced, then the move onto DIR failed (exit 1, a crash log) and a temporary and a journal were left."""
    d = tmp_path / "d"
    (d / "rdir").mkdir(parents=True)
    (d / "w.csv").write_text("old weights\n")
    (d / "c.pc2").write_bytes(b"old cache")
    before = _listing(d)
    common = ["solve", ict_dir, take_dir / "take.c3d", "--map", take_dir / "marker_map.json", "--global"]
    proc = run_cli(*common, "-o", d / "w.csv", "--cache", d / "c.pc2", "--report", d / "rdir", check=False)
    _refused(proc, f"{d / 'rdir'}: is a folder, not a file.")
    assert (d / "w.csv").read_text() == "old weights\n" and (d / "c.pc2").read_bytes() == b"old cache"
    assert _listing(d) == before
    # one file named for two outputs: before, the report silently took the weights' place
    proc = run_cli(*common, "-o", d / "w.csv", "--report", d / "w.csv", check=False)
    _refused(proc, f"{d / 'w.csv'}: is given for both -o and --report; each output needs its own file.")
    assert (d / "w.csv").read_text() == "old weights\n" and _listing(d) == before


@pytest.mark.parametrize("command, target", [
    (["render", "{rig}", "-o", "{out}"], "folder"),
    (["export", "{rig}", "-o", "{out}"], "folder"),
    (["segment", "{rig}", "-o", "{out}"], "folder"),
    (["corrective", "{rig}", "--drivers", "raise,push", "--target", "{rig}/raise.obj", "-o", "{out}"], "folder"),
    (["personalize", "{rig}", "--scans", "{rig}/raise.obj", "-o", "{tmp}/actor.bsproj", "--report", "{out}"],
     "folder"),
    (["export", "{rig}", "-o", "{out}/posed.obj"], "file above"),
    (["render", "{rig}", "-o", "{out}"], "pipe"),
    (["sample", "-o", "{out}"], "file"),
    (["batch", "{rig}", "{tmp}/take.trc", "-o", "{out}"], "file"),
])
def test_every_command_refuses_an_output_it_cannot_write(tmp_path, command, target):
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    out = tmp_path / "out"
    if target == "folder":
        out.mkdir()
        (out / "keep.txt").write_text("mine")
        sentence = f"{out}: is a folder, not a file."
    elif target == "pipe":
        if not hasattr(os, "mkfifo"):
            pytest.skip("no named pipes here")
        os.mkfifo(out)
        sentence = f"{out}: is not a regular file (a device, pipe or socket); nothing was written."
    else:
        out.write_text("mine")
        sentence = f"{out}/posed.obj: {out} is a file, not a folder." if target == "file above" else \
            f"{out}: is a file, not a folder."
    before = _listing(tmp_path)
    proc = run_cli(*[a.format(rig=rig, out=out, tmp=tmp_path) for a in command], check=False)
    _refused(proc, sentence)
    assert _listing(tmp_path) == before
    if target != "pipe":
        assert (out / "keep.txt" if out.is_dir() else out).read_text() == "mine"


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX paths")
def test_an_output_in_a_folder_named_by_its_trailing_slash_is_refused(tmp_path):
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    proc = run_cli("segment", rig, "-o", f"{tmp_path}/regions/", check=False)
    _refused(proc, f"{tmp_path}/regions/: is a folder, not a file.")
    assert not (tmp_path / "regions").exists()
