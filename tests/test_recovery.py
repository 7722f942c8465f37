"""Autosave files and locks (model.recovery), without the GUI: what the main window relies on."""
from __future__ import annotations

import json
import socket
import subprocess
import sys

import numpy as np
import pytest

from model.project import Project, save_project
from model.recovery import (describe_owner, find_recoveries, load_recovery, lock_owner, lock_path, recovery_path,
                            recovery_snapshot, release_lock, remove_recovery, take_lock, write_recovery)


@pytest.fixture(autouse=True)
def private_data_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))


def test_autosave_beside_a_project_restores_the_edits(tmp_path, sample_rig):
    path = tmp_path / "face.bsproj"
    project = Project(rig=sample_rig.copy())
    save_project(project, path)
    project.weights[3] = 0.7                                   # an unsaved edit
    written = write_recovery(project, path)
    assert written == tmp_path / ".face.bsproj.recovery"
    [rec] = find_recoveries(path)
    assert rec.project_path == str(path) and "face.bsproj, autosaved" in rec.describe()
    restored = load_recovery(rec)
    assert restored.weights[3] == 0.7 and "recovery" not in restored.sections
    assert np.array_equal(restored.rig.deltas, sample_rig.deltas)
    remove_recovery(path)
    assert find_recoveries(path) == []


def test_the_autosave_snapshot_shares_the_rigs_arrays_and_keeps_the_state_it_was_taken_in(tmp_path, sample_rig):
    """The autosave writes a snapshot off the GUI thread while editing goes on: the rig's large arrays are shared (a
    studio rig's deltas are not copied on the GUI thread), everything else is copied, and the edits made after it (which
    replace the rig's arrays, as the undo commands do, and change the pose and sections in place) do not reach it."""
    project = Project(rig=sample_rig.copy(), sections={"markers": {"markers": [{"name": "M00", "vertex": 3}]}})
    before = project.rig.deltas.copy()
    snap = recovery_snapshot(project)
    assert snap.rig.deltas is project.rig.deltas and snap.rig.neutral is project.rig.neutral
    assert snap.rig is not project.rig and snap.weights is not project.weights and snap.sections is not project.sections
    edited = project.rig.deltas.copy()                # an edit, as SetShapeDeltaCommand makes it: a new array
    edited[0] += 1.0
    project.rig.deltas = edited
    project.rig.shape_names[0] = "renamed"
    project.weights[2] = 0.9
    project.sections["markers"]["markers"][0]["vertex"] = 7
    path = tmp_path / "face.bsproj"
    write_recovery(snap, path)
    restored = load_recovery(find_recoveries(path)[0])
    assert np.array_equal(restored.rig.deltas, before) and restored.rig.shape_names[0] == sample_rig.shape_names[0]
    assert restored.weights[2] == 0.0 and restored.sections["markers"]["markers"][0]["vertex"] == 3


def test_autosave_of_a_rig_never_saved_goes_to_the_data_folder(tmp_path, sample_rig):
    rig = sample_rig.copy()
    rig.source = str(tmp_path / "some_rig_folder")
    project = Project(rig=rig)
    project.weights[0] = 0.25
    written = write_recovery(project, None)
    assert written.parent == tmp_path / "data" / "blendshape-studio" / "recovery"
    assert written == recovery_path(None, rig.source)
    [rec] = find_recoveries()
    assert rec.project_path is None and load_recovery(rec).weights[0] == 0.25


def test_a_lock_held_by_a_live_process_is_reported_and_a_dead_ones_is_not(tmp_path):
    path = tmp_path / "face.bsproj"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock_path(path).write_text(json.dumps({"pid": other.pid, "host": socket.gethostname(), "since": "now"}))
        owner = lock_owner(path)
        assert owner["pid"] == other.pid
        assert "already open in another Blendshape Studio window" in describe_owner(owner, path)
        assert take_lock(path)["pid"] == other.pid          # warned, and this window takes the lock
    finally:
        other.kill()
        other.wait()
    assert lock_owner(path) is None                          # our own lock is no warning
    lock_path(path).write_text(json.dumps({"pid": other.pid, "host": socket.gethostname(), "since": "then"}))
    assert lock_owner(path) is None                          # the owner died: a stale lock
    take_lock(path)
    release_lock(path)
    assert not lock_path(path).exists()


def test_damaged_recovery_files_and_a_fifo_lock_neither_crash_nor_block_a_start(tmp_path):
    import os
    import threading
    import zipfile
    path = tmp_path / "face.bsproj"
    with zipfile.ZipFile(recovery_path(path), "w") as z:        # a manifest nested deeper than Python follows
        z.writestr("manifest.json", "[" * 100_000 + "]" * 100_000)
    assert find_recoveries(path) == []
    os.mkfifo(lock_path(path))
    result = {}
    t = threading.Thread(target=lambda: result.setdefault("owner", lock_owner(path)), daemon=True)
    t.start()
    t.join(10)
    assert not t.is_alive() and result["owner"] is None
