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


def _rewrite(path, out, member, change):
    """Copy a project with one member's bytes passed through ``change(bytes)``."""
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for n in src.namelist():
            b = src.read(n)
            dst.writestr(n, change(b) if n == member else b)
    return out


def _npy(a) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _rewrite_array(path, out, key, edit):
    """Copy a project with the array ``key`` replaced by ``edit(array)``."""
    return _rewrite(path, out, f"{key}.npy", lambda b: _npy(edit(np.load(io.BytesIO(b)))))


def _rewrite_manifest(path, out, edit):
    return _rewrite(path, out, "manifest.json", lambda b: json.dumps(edit(json.loads(b))).encode())


def _refused(path, *words):
    with pytest.raises(RigInputError) as err:
        load_project(path)
    msg = str(err.value)
    assert msg.startswith(str(path)) and "\n" not in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


def test_negative_face_count_with_the_same_total_is_refused(project_file, tmp_path):
    def edit(a):
        a = a.astype(np.int32)
        a[0] += 5
        a[1] -= 5          # the total still matches the indices: only the sign gives it away
        return a
    _refused(_rewrite_array(project_file, tmp_path / "neg.bsproj", "rig/face_counts", edit), "corners")


def test_int64_indices_beyond_int32_are_not_wrapped(project_file, tmp_path):
    def edit(a):
        a = a.astype(np.int64)
        a[0] = 2**32       # would wrap to 0, a valid vertex, if cast silently
        return a
    _refused(_rewrite_array(project_file, tmp_path / "wrap.bsproj", "rig/face_indices", edit), "2³¹")


def test_a_declared_shape_of_10_to_the_12_is_refused_before_allocating(project_file, tmp_path):
    def change(b):
        header = np.lib.format.header_data_from_array_1_0(np.zeros((1, 3)))
        header["shape"] = (10**12, 3)
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, header)
        return buf.getvalue() + b[-4096:]
    out = _rewrite(project_file, tmp_path / "huge.bsproj", "rig/deltas.npy", change)
    _refused(out, "declares 3000000000000 values")


def test_a_member_that_inflates_beyond_its_header_is_refused(project_file, tmp_path):
    # 64 MiB of zeros that deflate to almost nothing
    out = _rewrite(project_file, tmp_path / "bomb.bsproj", "rig/neutral.npy", lambda b: b + bytes(64 << 20))
    assert out.stat().st_size < 2 << 20
    _refused(out, "rig/neutral", "damaged")


@pytest.mark.parametrize("weights", [[np.nan], [1e308]])
def test_nan_or_absurd_pose_weights_are_refused(project_file, tmp_path, weights):
    def edit(a):
        a[: len(weights)] = weights
        return a
    _refused(_rewrite_array(project_file, tmp_path / "w.bsproj", "pose/weights", edit))


@pytest.mark.parametrize("preset_weight", [None, "1", [1], 1e308, True])
def test_preset_weights_of_the_wrong_type_or_size_are_refused(project_file, tmp_path, preset_weight):
    def edit(m):
        m["rig"]["presets"] = {"happy": {m["rig"]["shape_names"][0]: preset_weight}}
        return m
    _refused(_rewrite_manifest(project_file, tmp_path / "p.bsproj", edit), "happy")


def test_a_manifest_nested_100000_deep_is_one_sentence(project_file, tmp_path):
    out = _rewrite(project_file, tmp_path / "deep.bsproj", "manifest.json", lambda b: b"[" * 100_000 + b"]" * 100_000)
    _refused(out, "nested too deeply")


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


def test_a_gltf_cut_inside_a_string_says_where_in_plain_words(tmp_path):
    """The audit's truncated third-party glTF (SimpleMorph.gltf cut at 500 bytes): the sentence read "Unterminated
    string starting at at line 8" (Python's message ends in "at", and the line was added after it)."""
    from tests.conftest import DATA, require_data
    cut = tmp_path / "cut.gltf"
    cut.write_bytes(require_data(DATA / "thirdparty" / "gltf" / "SimpleMorph.gltf").read_bytes()[:500])
    proc = run_cli("info", cut, check=False)
    sentence = f"{cut}: is not valid JSON (Unterminated string starting at line 8)."
    assert proc.returncode == 2 and proc.stderr == f"error: {sentence}\n", proc.stderr
