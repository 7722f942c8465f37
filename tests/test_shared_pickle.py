"""The memory file a local batch's job reaches its driver and workers through (``model.shared_pickle``): the object
comes back equal, its arrays read in place from the file (not copied), private to the process that writes them, and
a handle a few bytes long opens it from another process."""
from __future__ import annotations

import os
import pickle
import subprocess
import sys

import numpy as np
import pytest

from model import shared_pickle
from model.rig import Rig


def _memfile(obj) -> int:
    fd = os.memfd_create("test-shared-pickle")
    with open(fd, "wb", closefd=False) as f:
        shared_pickle.dump(obj, f)
    return fd


def _rig() -> Rig:
    rng = np.random.default_rng(3)
    neutral = rng.normal(size=(40, 3))
    return Rig(neutral=neutral, face_counts=np.full(10, 3), face_indices=rng.integers(0, 40, 30),
               shape_names=["a", "b", "c"], deltas=rng.normal(size=(3, 40, 3)), name="tiny")


def test_an_object_comes_back_equal_with_every_kind_of_array():
    rig = _rig()
    obj = {"rig": rig, "fortran": np.asfortranarray(np.arange(12.0).reshape(3, 4)),
           "strided": np.arange(20, dtype=np.int32)[::3], "empty": np.zeros((0, 3)), "text": "ok", "n": 7}
    fd = _memfile(obj)
    try:
        got = shared_pickle.load(fd)
    finally:
        os.close(fd)
    np.testing.assert_array_equal(got["rig"].deltas, rig.deltas)
    np.testing.assert_array_equal(got["rig"].neutral, rig.neutral)
    assert got["rig"].shape_names == ["a", "b", "c"] and got["rig"].name == "tiny"
    assert got["fortran"].flags.f_contiguous and got["fortran"].tolist() == obj["fortran"].tolist()
    assert got["strided"].dtype == np.int32 and got["strided"].tolist() == list(range(0, 20, 3))
    assert got["empty"].shape == (0, 3) and (got["text"], got["n"]) == ("ok", 7)


def test_the_arrays_are_read_from_the_file_in_place_and_a_write_stays_private():
    deltas = np.arange(3 * 1000 * 3, dtype=np.float64).reshape(3, 1000, 3)
    fd = _memfile({"deltas": deltas})
    try:
        got = shared_pickle.load(fd)["deltas"]
        # where the array lies in the file: change those bytes through the file and the loaded array shows it
        raw = os.pread(fd, os.fstat(fd).st_size, 0)
        at = raw.find(deltas.tobytes())
        assert at > 0 and at % 64 == 0
        os.pwrite(fd, np.float64(-5.0).tobytes(), at + 8 * 17)
        assert got.ravel()[17] == -5.0            # a copy would still say 17.0
        # the array is writeable; a write changes this process's page only, not the file
        assert got.flags.writeable
        got[0, 0, 0] = 99.0
        again = shared_pickle.load(fd)["deltas"]
        assert again[0, 0, 0] == 0.0 and again.ravel()[17] == -5.0
    finally:
        os.close(fd)


def test_a_file_it_did_not_write_is_refused():
    for content in (b"", b"short", pickle.dumps({"a": 1}, protocol=5) * 3):
        fd = os.memfd_create("test-shared-pickle-bad")
        try:
            os.write(fd, content)
            with pytest.raises(ValueError, match="not a shared pickle"):
                shared_pickle.load(fd)
        finally:
            os.close(fd)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc descriptors: Linux")
def test_a_handle_is_a_few_bytes_and_opens_the_object_in_another_process():
    rig = _rig()
    fd = _memfile(rig)
    try:
        assert shared_pickle.reachable(fd)
        handle = pickle.dumps(shared_pickle.SharedObject(os.getpid(), fd), protocol=5)
        assert len(handle) < 200
        code = ("import pickle, sys\nrig = pickle.loads(sys.stdin.buffer.read())\n"
                "print(rig.name, float(rig.deltas.sum()), rig.deltas.flags.writeable)")
        out = subprocess.run([sys.executable, "-c", code], input=handle, capture_output=True, check=True,
                             cwd=os.path.dirname(os.path.dirname(__file__))).stdout.decode().split()
        assert out == ["tiny", repr(float(rig.deltas.sum())), "True"]
    finally:
        os.close(fd)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc descriptors: Linux")
def test_a_batch_job_opened_from_the_file_is_passed_on_as_its_handle():
    """Dask's broadcast scatters the job to one worker, which hands it to the next: that one must map the file too,
    not unpickle a copy of the rig."""
    from model.batch import BatchJob
    rig = _rig()
    job = BatchJob.prepare(rig, {"mode": "global", "residual": None, "calibration_frames": 0, "fixed_head": False})
    fd = _memfile(job)
    try:
        opened = pickle.loads(pickle.dumps(shared_pickle.SharedObject(os.getpid(), fd), protocol=5))
        assert isinstance(opened, BatchJob) and opened.signature == job.signature
        passed_on = pickle.dumps(opened, protocol=5)
        assert len(passed_on) < 200                   # the handle, not the rig
        again = pickle.loads(passed_on)
        np.testing.assert_array_equal(again.rig.deltas, rig.deltas)
        # the next worker's job reads the file: a change to the file's bytes shows in it (a copy would not)
        raw = os.pread(fd, os.fstat(fd).st_size, 0)
        at = raw.find(rig.deltas.tobytes())
        os.pwrite(fd, np.float64(123.0).tobytes(), at)
        assert again.rig.deltas.ravel()[0] == 123.0
        # and it poses the rig as the job it came from (its evaluator is built where it is used)
        w = np.array([0.3, 0.0, 0.7])
        np.testing.assert_allclose(opened.evaluator.pose(w), rig.neutral + np.tensordot(w, opened.rig.deltas, 1))
    finally:
        os.close(fd)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc descriptors: Linux")
def test_the_batch_command_keeps_only_the_shared_file_and_a_remote_cluster_gets_the_job_whole():
    """``share_job`` (the ``batch`` command on a local cluster): the job comes back mapped from a new in-memory file
    held by this process, passed on as its handle; ``portable_job`` (a scheduler's address: other machines) gives a
    job that pickles whole again, equal to the original."""
    from model.batch import BatchJob, portable_job, share_job
    rig = _rig()
    job = BatchJob.prepare(rig, {"mode": "global", "residual": None, "calibration_frames": 0, "fixed_head": False})
    shared = share_job(job)
    handle = shared_pickle.handle_of(shared)
    assert handle is not None and handle.pid == os.getpid()
    assert os.readlink(shared_pickle.descriptor_path(os.getpid(), handle.fd)).startswith("/memfd:")
    np.testing.assert_array_equal(shared.rig.deltas, rig.deltas)
    raw = os.pread(handle.fd, os.fstat(handle.fd).st_size, 0)
    os.pwrite(handle.fd, np.float64(-7.0).tobytes(), raw.find(rig.deltas.tobytes()))
    assert shared.rig.deltas.ravel()[0] == -7.0            # its arrays are the file's
    assert len(pickle.dumps(shared, protocol=5)) < 200
    whole = portable_job(shared)
    data = pickle.dumps(whole, protocol=5)
    assert len(data) > rig.deltas.nbytes
    back = pickle.loads(data)
    assert shared_pickle.handle_of(back) is None and back.signature == job.signature
    assert back.rig.deltas.ravel()[0] == -7.0 and np.array_equal(back.rig.neutral, rig.neutral)
    assert portable_job(job) is job                         # a job of this process's own arrays: as it is
    os.close(handle.fd)
