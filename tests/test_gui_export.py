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
