"""The failures a tester found with hostile files (issue 17), each now one clean sentence naming the file."""
from __future__ import annotations

import io
import json
import os
import threading
import zipfile

import numpy as np
import pytest

from model.errors import RigInputError
from model.project import Project, load_project, save_project
from tests.cli_runner import run_cli


@pytest.fixture()
def project_file(tmp_path, sample_rig):
    path = tmp_path / "sample.bsproj"
    save_project(Project(rig=sample_rig.copy()), path)
    return path


def _rewrite(path, out, change):
    """Copy a project, passing each member's bytes through ``change(name, bytes)``."""
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for n in src.namelist():
            dst.writestr(n, change(n, src.read(n)))
    return out


def _npy(a) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _refused(path, *words):
    with pytest.raises(RigInputError) as err:
        load_project(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and "\n" not in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


def test_negative_face_count_with_the_same_total_is_refused(project_file, tmp_path):
    def change(name, b):
        if name == "rig/face_counts.npy":
            a = np.load(io.BytesIO(b)).astype(np.int32)
            a[0] += 5
            a[1] -= 5          # the total still matches the indices: only the sign gives it away
            return _npy(a)
        return b
    _refused(_rewrite(project_file, tmp_path / "neg.bsproj", change), "corners")


def test_int64_indices_beyond_int32_are_not_wrapped(project_file, tmp_path):
    def change(name, b):
        if name == "rig/face_indices.npy":
            a = np.load(io.BytesIO(b)).astype(np.int64)
            a[0] = 2**32   # would wrap to 0, a valid vertex, if cast silently
            return _npy(a)
        return b
    _refused(_rewrite(project_file, tmp_path / "wrap.bsproj", change), "2³¹")


def test_a_declared_shape_of_10_to_the_12_is_refused_before_allocating(project_file, tmp_path):
    def change(name, b):
        if name == "rig/deltas.npy":
            header = np.lib.format.header_data_from_array_1_0(np.zeros((1, 3)))
            header["shape"] = (10**12, 3)
            buf = io.BytesIO()
            np.lib.format.write_array_header_1_0(buf, header)
            return buf.getvalue() + b[-4096:]
        return b
    _refused(_rewrite(project_file, tmp_path / "huge.bsproj", change), "declares 3000000000000 values")


def test_a_member_that_inflates_beyond_its_header_is_refused(project_file, tmp_path):
    def change(name, b):
        if name == "rig/neutral.npy":
            return b + bytes(64 << 20)   # 64 MiB of zeros that deflate to almost nothing
        return b
    out = _rewrite(project_file, tmp_path / "bomb.bsproj", change)
    assert out.stat().st_size < 2 << 20
    _refused(out, "rig/neutral", "damaged")


@pytest.mark.parametrize("weights", [[np.nan], [1e308]])
def test_nan_or_absurd_pose_weights_are_refused(project_file, tmp_path, weights):
    def change(name, b):
        if name == "pose/weights.npy":
            a = np.load(io.BytesIO(b))
            a[: len(weights)] = weights
            return _npy(a)
        return b
    _refused(_rewrite(project_file, tmp_path / "w.bsproj", change))


@pytest.mark.parametrize("preset_weight", [None, "1", [1], 1e308, True])
def test_preset_weights_of_the_wrong_type_or_size_are_refused(project_file, tmp_path, preset_weight):
    def change(name, b):
        if name == "manifest.json":
            m = json.loads(b)
            m["rig"]["presets"] = {"happy": {m["rig"]["shape_names"][0]: preset_weight}}
            return json.dumps(m).encode()
        return b
    _refused(_rewrite(project_file, tmp_path / "p.bsproj", change), "happy")


def test_a_manifest_nested_100000_deep_is_one_sentence(project_file, tmp_path):
    def change(name, b):
        return (b"[" * 100_000 + b"]" * 100_000) if name == "manifest.json" else b
    _refused(_rewrite(project_file, tmp_path / "deep.bsproj", change), "nested too deeply")


def test_a_fifo_named_bsproj_does_not_block(tmp_path):
    fifo = tmp_path / "x.bsproj"
    os.mkfifo(fifo)
    result = {}
    t = threading.Thread(target=lambda: result.setdefault("p", run_cli("info", fifo, check=False, timeout=60)))
    t.start()
    t.join(60)
    assert not t.is_alive()
    proc = result["p"]
    assert proc.returncode == 2 and "not a regular file" in proc.stderr and "Traceback" not in proc.stderr


def test_a_project_linked_to_dev_zero_is_refused_unread(tmp_path):
    link = tmp_path / "zero.bsproj"
    link.symlink_to("/dev/zero")
    proc = run_cli("info", link, check=False, timeout=60)
    assert proc.returncode == 2 and "not a regular file" in proc.stderr


def test_a_valid_project_still_opens(project_file, sample_rig):
    p = load_project(project_file)
    assert np.array_equal(p.rig.neutral, sample_rig.neutral) and p.rig.shape_names == sample_rig.shape_names
