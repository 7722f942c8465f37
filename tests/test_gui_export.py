"""File ▸ Export Rig from the window: the pose shown and the keyed animation leave as a glTF that reads back
with the same shapes, default weights and frames (issue 16), written in the background."""
from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from model.gltf import load_gltf
from tests.gui_helpers import make_window

pytestmark = pytest.mark.gui


def _gltf_json(path):
    raw = path.read_bytes()
    n = struct.unpack_from("<I", raw, 12)[0]
    return json.loads(raw[20:20 + n])


def test_export_the_pose_and_the_keyframes_as_glb(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    doc = w.document
    i = doc.rig.shape_index("jawOpen")
    weights = doc.weights
    weights[i] = 0.7
    w.set_pose(weights, "jaw")
    w.keyframes.set_key(0.0)
    weights[i] = 0.2
    w.set_pose(weights, "jaw")
    w.keyframes.set_key(1.0)
    names = list(w.exports.animations())
    assert len(names) == 1 and names[0].startswith("Keyframes (2 keys")
    out = tmp_path / "face.glb"
    with qtbot.waitSignal(w.exports.exported, timeout=60000):
        w.exports.export_to(out, names[0])
    rig = load_gltf(out)
    assert rig.shape_names == doc.rig.shape_names
    np.testing.assert_allclose(rig.deltas, doc.rig.deltas * 0.01, atol=1e-6)     # cm -> m
    g = _gltf_json(out)
    assert g["meshes"][0]["weights"][i] == pytest.approx(0.2)                    # the pose shown
    [anim] = g["animations"]
    times = g["accessors"][anim["samplers"][0]["input"]]
    assert times["count"] == int(w.keyframes.fps) + 1 and times["max"][0] == pytest.approx(1.0)


def test_a_failed_export_is_one_sentence_and_keeps_the_window(qtbot, tmp_path):
    w = make_window(qtbot, tmp_path)
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with qtbot.waitSignal(w.exports.failed, timeout=60000) as sig:
        w.exports.export_to(blocker / "face.glb")                   # a folder that is a file
    assert "\n" not in sig.args[0]
    assert w.document.project is not None


def test_an_export_its_disk_has_no_room_for_is_refused_in_a_dialog(qtbot, tmp_path, monkeypatch):
    """File ▸ Export Rig wrote a glTF or USD file without a look at the disk (the `export` command refused it): now
    the same check (``model.export.check_export_space``) refuses it in one sentence before anything is written."""
    import shutil
    from collections import namedtuple
    from model.export import export_size
    w = make_window(qtbot, tmp_path)
    usage = namedtuple("Usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**9, 10**9 - 1000, 1000))
    for name in ("face.usdc", "face.glb"):
        out = tmp_path / name
        with qtbot.waitSignal(w.exports.failed, timeout=60000) as sig:
            w.exports.export_to(out)
        least = export_size(w.document.rig, out, units=None)
        assert least > 1000 and sig.args[0].startswith(f"{out}: needs at least ") and "1 KB free" in sig.args[0]
        assert "\n" not in sig.args[0] and not out.exists()
    monkeypatch.undo()
    with qtbot.waitSignal(w.exports.exported, timeout=60000):
        w.exports.export_to(tmp_path / "face.usdc")
    assert (tmp_path / "face.usdc").stat().st_size >= export_size(w.document.rig, tmp_path / "face.usdc")


def test_no_export_of_the_window_writes_over_the_files_it_has_open(qtbot, tmp_path, monkeypatch):
    """The command line refuses an output that is one of its inputs (the rig, a .gltf's buffers and images, ...); the
    window's exports checked only Export Pose's OBJ against the rig's OBJ folder: Export Rig wrote over the open
    .gltf or its buffer, Export Image over its texture, Export Keyed Animation over the open project, the Mocap
    panel's weights over the take it plays. Each is refused now in one sentence (the same rule,
    ``model.beside_inputs``), nothing written; a file elsewhere is written as before."""
    from PySide6 import QtCore, QtWidgets
    from tests.gui_helpers import open_and_wait
    from tests.test_cli_outputs import _gltf_with_files_beside
    rig = _gltf_with_files_beside(tmp_path / "rig")
    buffer, texture = rig.parent / "Morph Stress.bin", rig.parent / "tiny grid.png"
    w = make_window(qtbot, tmp_path, sample=False)
    open_and_wait(qtbot, w, rig)
    project = tmp_path / "stress.bsproj"
    assert w.save_to(project)
    take = tmp_path / "take.csv"          # a weights CSV on the rig's shapes, played by the Mocap panel
    take.write_text(f"frame,time,{w.document.rig.shape_names[0]}\n0,0,0\n1,0.033333,0.5\n2,0.066667,1\n")
    assert w.mocap.load_take(take)

    def files() -> dict:
        return {p: p.read_bytes() for p in (rig, buffer, texture, project, take)}
    before = files()
    for path, sentence in ((rig, f"{rig}: is the rig itself, which the window has open; choose another file."),
                           (buffer, f"{buffer}: is the buffer file 'Morph%20Stress.bin' that the rig ({rig}) reads; "
                                    "choose another file."),
                           (project, f"{project}: is the project itself, which the window has open; choose another "
                                     "file.")):
        with qtbot.waitSignal(w.exports.failed, timeout=10000) as sig:
            w.exports.export_to(path)
        assert sig.args == [sentence] and w.last_error == sentence
    assert not w.save_image(texture, (32, 32))
    assert w.last_error == (f"{texture}: is the image file 'tiny%20grid.png' that the rig ({rig}) reads; choose "
                            "another file.")
    w.export_pose_to(rig)
    assert w.last_error.startswith(f"{rig}: is the rig itself")
    # through the window's own dialogs: the keyed animation as PC2 over the project, the take's weights over the take
    weights = w.document.weights
    w.keyframes.set_key(0.0)
    weights[0] = 1.0
    w.set_pose(weights, "raise")
    w.keyframes.set_key(1.0)
    answer = {"path": project}
    monkeypatch.setattr(QtWidgets.QFileDialog, "getSaveFileName",
                        staticmethod(lambda *a, **k: (str(answer["path"]), "")))
    w.keyframes.export_pc2_dialog()
    assert w.last_error == f"{project}: is the project itself, which the window has open; choose another file."
    answer["path"] = take
    w.last_error = None
    qtbot.mouseClick(w.mocap.panel.export_weights_button, QtCore.Qt.LeftButton)
    assert w.last_error == f"{take}: is the take itself, which the window has open; choose another file."
    assert w.mocap.panel.status_label.text() == w.last_error
    w.jobs.wait()
    assert files() == before
    answer["path"] = tmp_path / "weights.csv"                    # elsewhere: written
    qtbot.mouseClick(w.mocap.panel.export_weights_button, QtCore.Qt.LeftButton)
    assert (tmp_path / "weights.csv").is_file()
    with qtbot.waitSignal(w.exports.exported, timeout=60000):
        w.exports.export_to(tmp_path / "out.gltf")
    assert (tmp_path / "out.gltf").is_file() and files() == before


def test_export_rig_copies_no_array_on_the_gui_thread_and_exports_the_rig_as_it_was(qtbot, tmp_path, ict_dir):
    """File ▸ Export Rig takes the rig as it is (``Rig.snapshot``: its arrays shared, never changed in place by an
    edit) instead of a deep copy on the GUI thread (11 s of a frozen window at 422k vertices, 228 shapes), and an
    edit made while the export runs does not leak into the file."""
    import tracemalloc

    from app.commands import SetShapeDeltaCommand
    from tests.gui_helpers import open_and_wait
    w = make_window(qtbot, tmp_path)
    open_and_wait(qtbot, w, ict_dir)
    doc = w.document
    jobs = []
    real_submit = w.exports.runner.submit
    w.exports.runner.submit = lambda job, done, failed: jobs.append((job, done, failed))
    out = tmp_path / "ict.glb"
    tracemalloc.start()
    try:
        w.exports.export_to(out)
        allocated = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(jobs) == 1 and allocated < 0.1 * doc.rig.deltas.nbytes, allocated   # a deep copy: > 1x
    k = doc.rig.shape_index("jawOpen")
    before = doc.rig.deltas[k].copy()
    doc.undo_stack.push(SetShapeDeltaCommand(doc, "jawOpen", before * 2.0, "Double jawOpen"))  # while it waits
    assert np.abs(doc.rig.deltas[k] - 2.0 * before).max() == 0
    with qtbot.waitSignal(w.exports.exported, timeout=60000):
        real_submit(*jobs[0])
    exported = load_gltf(out)
    np.testing.assert_allclose(exported.deltas[exported.shape_index("jawOpen")], before * 0.01, atol=1e-6)   # m


def test_the_windows_obj_exports_refuse_a_material_library_over_the_rigs_own(qtbot, tmp_path):
    """Export Pose as OBJ and Export Rig as OBJ also write the OBJ's material library beside it; one that would land
    over the rig's own materials is refused in a dialog, as the command line refuses it, and nothing is written."""
    from tests.gui_helpers import open_and_wait
    from tests.test_cli_outputs import _rig_with_materials_and_a_linked_shape
    rig = _rig_with_materials_and_a_linked_shape(tmp_path)
    w = make_window(qtbot, tmp_path, sample=False)
    open_and_wait(qtbot, w, rig)
    before = {p: (p.read_bytes(), p.is_symlink()) for p in tmp_path.rglob("*") if p.is_file() and "settings" not in
              p.parts}
    sentence = (f"{rig / 'face.mtl'} (the material library written with {rig / 'face.obj'}): is in {rig}, the folder "
                "the rig is read from, and would overwrite a file it reads; choose a file elsewhere.")
    w.export_pose_to(rig / "face.obj")
    assert w.last_error == sentence
    w.last_error = None
    with qtbot.waitSignal(w.exports.failed, timeout=10000) as sig:
        w.exports.export_to(rig / "face.obj")
    assert sig.args == [sentence] and w.last_error == sentence
    w.jobs.wait()
    assert {p: (p.read_bytes(), p.is_symlink()) for p in tmp_path.rglob("*") if p.is_file() and "settings" not in
            p.parts} == before
