"""A disk that fails part-way through a write -- full (ENOSPC), over quota (EDQUOT), a file too large for it (EFBIG),
an input/output error (EIO) -- is one sentence naming the output and the problem: on the command line exit code 2
and no crash log (it was exit 1, "failed unexpectedly" and a crash log), in the window an error dialog; nothing is
left half-written (no temporary, no journal, the old file as it was), and the window keeps the open project, its
undo history and its autosave.

The disk is simulated by the file objects of this application's temporaries (``model.atomic.write_temporary``):
their writes stop with the error once ``room`` bytes are written, the part that fits written first, as a full disk
does. (The same commands on a real 1 MB tmpfs said the same sentences: see the commit that added this file.)"""
from __future__ import annotations

import builtins
import errno
import os
import re

import numpy as np
import pytest

from model.atomic import TEMP_MARK
from tests.rig_files import write_rig_folder

FULL = (r"the disk is full \([\d.]+ (?:bytes|KB|MB|GB|TB) free\); nothing was written; free some space or write to "
        r"another disk\.")
SENTENCES = {
    errno.ENOSPC: FULL,
    errno.EDQUOT: r"your disk quota is used up; nothing was written; free some of your space or write to another "
                  r"disk\.",
    errno.EFBIG: r"the file is larger than its disk \(or your limits\) allow one file to be; nothing was written; "
                 r"write to another disk\.",
    errno.EIO: r"the disk reported an input/output error; nothing was written; check the disk or write to another\.",
}


class _FailingFile:
    """A file whose writes stop with OSError(``code``) once ``room`` bytes are written (what fits is written)."""

    def __init__(self, f, room: int, code: int) -> None:
        self.f, self.room, self.code = f, room, code

    def write(self, data) -> int:
        view = data if isinstance(data, str) else memoryview(data).cast("B")     # text or bytes
        if len(view) > self.room:
            self.f.write(view[:self.room])
            self.room = 0
            raise OSError(self.code, os.strerror(self.code))
        self.room -= len(view)
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.f.close()


@pytest.fixture
def failing_disk(monkeypatch):
    """``fail(code=ENOSPC, room=64, only=None)``: from now on this application's temporaries (of the targets whose
    name contains ``only``) are written to a disk that fails with ``code`` after ``room`` bytes: those opened by
    their descriptor (``os.fdopen``) and by their name (``open``: the picture VTK's screenshot saves)."""
    def fail(code: int = errno.ENOSPC, room: int = 64, only: str | None = None) -> None:
        real_fdopen, real_open = os.fdopen, builtins.open

        def failing(f, name: str, mode: str):
            name = os.path.basename(name)
            if "w" in mode and TEMP_MARK in name and (only is None or only in name):
                return _FailingFile(f, room, code)
            return f

        def fdopen(fd, mode="r", *args, **kwargs):
            return failing(real_fdopen(fd, mode, *args, **kwargs), os.readlink(f"/proc/self/fd/{fd}"), mode)

        def open_(file, mode="r", *args, **kwargs):
            f = real_open(file, mode, *args, **kwargs)
            return failing(f, os.fspath(file), mode) if isinstance(file, (str, os.PathLike)) else f
        monkeypatch.setattr(os, "fdopen", fdopen)
        monkeypatch.setattr(builtins, "open", open_)
    return fail


def _listing(folder) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else b"<folder>"
            for p in sorted(folder.rglob("*"))}


def _crash_logs() -> set[str]:
    from app.crash import crash_dir
    return set(os.listdir(crash_dir())) if crash_dir().is_dir() else set()


@pytest.mark.parametrize("code", sorted(SENTENCES))
def test_a_disk_failing_part_way_is_one_sentence_naming_the_file_and_the_old_file_stays(tmp_path, failing_disk,
                                                                                       code):
    from model.atomic import atomic_write
    from model.errors import RigInputError
    out = tmp_path / "weights.csv"
    out.write_bytes(b"old\n")
    before = _listing(tmp_path)
    failing_disk(code, room=100)
    with pytest.raises(RigInputError) as caught:
        atomic_write(out, b"x" * 10_000)
    assert isinstance(caught.value, OSError) and caught.value.errno == code
    assert re.fullmatch(re.escape(f"{out}: ") + SENTENCES[code], str(caught.value)), str(caught.value)
    assert _listing(tmp_path) == before     # no temporary left, the old file as it was


@pytest.mark.parametrize("command, output, only", [
    (["export", "{rig}", "-o", "{out}"], "posed.obj", None),
    (["export", "{rig}", "-o", "{out}"], "rig.glb", None),
    (["export", "{rig}", "-o", "{out}"], "rig.usda", None),
    (["segment", "{rig}", "--min-size", "4", "-o", "{out}"], "regions.json", None),
    (["render", "{rig}", "-o", "{out}", "--size", "64,64"], "front.png", None),
    (["personalize", "{rig}", "--scans", "{rig}/raise.obj", "-o", "{tmp}/actor.bsproj", "--report", "{out}"],
     "report.json", "report.json"),
    (["sample", "-o", "{out}"], "sample", "browDown_R"),
])
def test_a_command_on_a_full_disk_says_so_in_one_sentence_exit_2_without_a_crash_log(tmp_path, failing_disk,
                                                                                       capsys, command, output, only):
    """Each command's write on a disk that fills part-way: one sentence naming the output, exit 2, no crash log,
    every file as it was (a set such as personalize's project and report: neither; the sample: none of its files)."""
    from app import cli
    rig = tmp_path / "rig"
    write_rig_folder(rig)
    out = tmp_path / output
    before, logs = _listing(tmp_path), _crash_logs()
    failing_disk(errno.ENOSPC, room=64 if only != "browDown_R" else 2000, only=only)
    code = cli.main([a.format(rig=rig, out=out, tmp=tmp_path) for a in command])
    err = capsys.readouterr().err
    assert code == 2, err
    assert re.fullmatch(re.escape(f"error: {out}: ") + FULL + "\n", err), err
    assert _listing(tmp_path) == before
    assert _crash_logs() == logs


def test_a_set_whose_moves_stop_part_way_says_how_far_and_is_finished_later(tmp_path, monkeypatch):
    """After its journal is written a set is new (``model.output_set``): a disk error while its files are moved into
    place says which are new, and the rest are moved in the next time a set is written there. Their temporaries
    are kept meanwhile, even once their writer is gone and another file is written to the folder (they were
    removed as a dead writer's, leaving the set half old)."""
    from model import atomic, output_set
    from model.atomic import atomic_write
    from model.errors import RigInputError
    from model.output_set import finish_interrupted_sets, write_set
    names = ["weights.csv", "report.json", "cache.pc2"]
    for name in names:
        (tmp_path / name).write_text(f"old {name}")
    real, moved = os.replace, []

    def replace(src, dst):
        if os.path.basename(dst) not in names:    # the journal's own move
            return real(src, dst)
        if len(moved) == 1:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        moved.append(dst)
        return real(src, dst)
    monkeypatch.setattr(output_set.os, "replace", replace)
    with pytest.raises(RigInputError) as caught:
        write_set({tmp_path / name: (lambda f, n=name: f.write(f"new {n}".encode())) for name in names})
    assert str(caught.value) == (
        f"{tmp_path / 'report.json'}: the disk reported an input/output error while the 3 files written together "
        f"were moved into place (1 of them are new); the rest become new the next time a set is written to "
        f"{tmp_path}; check the disk or write to another.")
    monkeypatch.setattr(output_set.os, "replace", real)
    monkeypatch.setattr(atomic, "process_alive", lambda pid: False)     # the writer gone (a command that ended)
    atomic_write(tmp_path / "regions.json", b"{}")                         # another output into that folder
    finish_interrupted_sets(tmp_path)
    assert {name: (tmp_path / name).read_text() for name in names} == {name: f"new {name}" for name in names}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names + ["regions.json"])


def test_a_batch_take_on_a_full_disk_fails_in_one_sentence_without_a_crash_log(tmp_path, ict_rig, llf_csv,
                                                                              failing_disk):
    """A take whose outputs do not fit: a failed row saying so (no traceback for a crash log: it was 'the solve
    stopped unexpectedly (OSError ...)' with one), nothing of its set left."""
    from model.batch import BatchJob, solve_and_report
    job = BatchJob.prepare(ict_rig, {"mode": "global", "residual": None, "calibration_frames": 30,
                                     "fixed_head": False})
    out = tmp_path / "out" / "llf"
    failing_disk(errno.ENOSPC, room=4096, only="weights.csv")
    row = solve_and_report(job, str(llf_csv), str(out), "llf")
    assert row["status"] == "failed" and "traceback" not in row, row
    assert re.fullmatch(re.escape(f"{out / 'weights.csv'}: ") + FULL, row["error"]), row["error"]
    assert not out.exists()      # nor the take's folder, made for the set


def test_a_crash_log_the_disk_has_no_room_for_is_not_left_half_written(tmp_path, monkeypatch):
    """A crash log written to a full disk: none is named (as before) and no part of one is left behind (the first
    bytes that fitted were left as a log cut short)."""
    from app.crash import write_crash_log
    monkeypatch.setenv("BLENDSHAPE_STUDIO_LOGS", str(tmp_path / "logs"))
    real = builtins.open

    def open_(file, mode="r", *args, **kwargs):
        f = real(file, mode, *args, **kwargs)
        return _FailingFile(f, 40, errno.ENOSPC) if os.path.basename(str(file)).startswith("crash-") else f
    monkeypatch.setattr(builtins, "open", open_)
    assert write_crash_log(ValueError("a bug"), "testing") is None
    assert list((tmp_path / "logs").iterdir()) == []


# --- the window -------------------------------------------------------------------------------------------------
@pytest.mark.gui
def test_the_window_on_a_full_disk_shows_the_sentence_and_loses_nothing(qtbot, tmp_path, failing_disk):
    """Save, Export Rig, Export Pose as OBJ and Export Image on a disk that fills part-way: an error dialog with the
    sentence; the project stays open with its edits unsaved and its undo history, its autosave as it was, nothing
    written."""
    from model.recovery import find_recoveries
    from tests.gui_helpers import make_window
    w = make_window(qtbot, tmp_path)
    w.apply_preset("surprised")
    w.shapes_panel.row("jawOpen").box.setValue(0.3)
    steps, weights = w.document.undo_stack.count(), w.document.weights.copy()
    w.autosave.autosave_now()
    qtbot.waitUntil(lambda: w.autosave.written > 0, timeout=20000)
    autosaves = {r.path: r.path.read_bytes() for r in find_recoveries()}
    assert autosaves
    out = tmp_path / "out"
    out.mkdir()
    failing_disk(errno.ENOSPC, room=4096)

    assert not w.save_to(out / "face.bsproj")
    assert re.fullmatch(re.escape(f"{out / 'face.bsproj'}: ") + FULL, w.last_error), w.last_error
    assert w.document.path is None and w.document.is_modified and w.isWindowModified()
    assert w.document.undo_stack.count() == steps and w.document.undo_stack.canUndo()
    np.testing.assert_array_equal(w.document.weights, weights)

    with qtbot.waitSignal(w.exports.failed, timeout=60000) as failed:
        w.exports.export_to(out / "face.glb")
    assert re.fullmatch(re.escape(f"{out / 'face.glb'}: ") + FULL, failed.args[0]), failed.args[0]
    assert w.last_error == failed.args[0]

    w.export_pose_to(out / "pose.obj")
    qtbot.waitUntil(lambda: "pose.obj" in w.last_error, timeout=60000)
    assert re.fullmatch(re.escape(f"{out / 'pose.obj'}: ") + FULL, w.last_error), w.last_error

    assert w.save_image(out / "face.png", (64, 64))      # Export Image: the picture is written in the background
    qtbot.waitUntil(lambda: "face.png" in w.last_error, timeout=60000)
    assert re.fullmatch(re.escape(f"{out / 'face.png'}: ") + FULL, w.last_error), w.last_error

    assert list(out.iterdir()) == []
    assert {r.path: r.path.read_bytes() for r in find_recoveries()} == autosaves
    w.document.undo_stack.undo()            # the history still works
    assert w.document.undo_stack.count() == steps and w.document.undo_stack.index() == steps - 1
