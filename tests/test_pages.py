"""Ordinary memory pages for studio-scale arrays written once (model.pages): a load of a rig whose arrays reach
``LARGE`` and the window's display evaluator of such a rig ask Linux for ordinary pages, an ICT-sized load keeps
numpy's request for huge pages, and numpy's setting comes back afterwards. Checked in the kernel's own record of
each mapping (``/proc/self/smaps``: ``hg`` among its VmFlags where huge pages were asked for with madvise)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux's transparent huge pages")

toggle = np._core.multiarray._set_madvise_hugepage


def huge_pages_asked(a: np.ndarray) -> bool:
    """Whether the mapping holding the middle of ``a`` was madvised for transparent huge pages (numpy advises from
    the first page boundary inside the array on, so the page of its first byte is a mapping of its own)."""
    address = a.__array_interface__["data"][0] + a.nbytes // 2
    inside = False
    for line in Path("/proc/self/smaps").read_text().splitlines():
        head = line.split(" ", 1)[0]
        if "-" in head and ":" not in head:
            start, end = (int(x, 16) for x in head.split("-"))
            inside = start <= address < end
        elif inside and line.startswith("VmFlags:"):
            return "hg" in line.split()[1:]
    raise AssertionError("the array's mapping is not in /proc/self/smaps")


def numpy_asks_for_huge_pages_now() -> bool:
    """Whether numpy madvises transparent huge pages for its large arrays in this process (its setting, unchanged)."""
    before = toggle(False)
    toggle(before)
    return bool(before)


def no_runs_in_flight(timeout: float = 120.0) -> None:
    """Wait for the ``small_pages`` blocks other threads run (a segmentation an earlier test's window started) to
    end: numpy's setting is theirs until then."""
    import time

    from model import pages
    deadline = time.monotonic() + timeout
    while pages.active() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not pages.active(), "a segmentation or load of an earlier test is still running"


@pytest.fixture
def numpy_asks_for_huge_pages():
    no_runs_in_flight()
    before = toggle(True)
    try:
        if not huge_pages_asked(np.ones(40 << 17)):     # 40 MB: a mapping of its own
            pytest.skip("numpy does not ask this kernel for transparent huge pages (none configured)")
        yield
    finally:
        assert toggle(before) is True, "numpy's setting was not given back"


def test_small_pages_nests_across_threads_and_gives_numpy_its_setting_back(numpy_asks_for_huge_pages):
    import threading

    from model.pages import small_pages
    inside = threading.Event()
    release = threading.Event()

    def other_run():
        with small_pages():
            inside.set()
            release.wait(10)

    t = threading.Thread(target=other_run)
    with small_pages():
        assert toggle(False) is False
        t.start()
        assert inside.wait(10)
    assert toggle(False) is False          # the other thread's run is not over: still off
    release.set()
    t.join()
    assert toggle(True) is True            # back on after the last one
    with small_pages(when=False):
        assert toggle(True) is True        # ``when`` False changes nothing


def test_a_large_project_is_read_into_ordinary_pages_and_a_smaller_one_keeps_huge_pages(
        tmp_path, ict_rig, monkeypatch, numpy_asks_for_huge_pages):
    """The project: ICT with its shapes four times over (146 MB of deltas). Arrays of that size always get a mapping
    of their own: glibc serves smaller ones (ICT's 37 MB) from its heap when it has room, whose pages keep the advice
    an earlier array there was given, so only a size like this shows what a load asks for."""
    from model import pages
    from model.project import Project, load_project, save_project
    from model.rig import Rig
    names = [f"{n}_{i}" for i in range(4) for n in ict_rig.shape_names]
    rig = Rig(neutral=ict_rig.neutral, face_counts=ict_rig.face_counts, face_indices=ict_rig.face_indices,
              shape_names=names, deltas=np.concatenate([ict_rig.deltas] * 4))
    save_project(Project(rig=rig), tmp_path / "four.bsproj")
    assert 64 << 20 < rig.deltas.nbytes < pages.LARGE
    assert huge_pages_asked(load_project(tmp_path / "four.bsproj").rig.deltas)     # under LARGE: numpy's request
    monkeypatch.setattr(pages, "LARGE", 64 << 20)                                # as a studio-scale rig is read
    big = load_project(tmp_path / "four.bsproj").rig
    assert not huge_pages_asked(big.deltas)
    np.testing.assert_array_equal(big.deltas, rig.deltas)
    assert toggle(True) is True            # and numpy asks again afterwards


def test_an_obj_folder_of_a_large_rig_gets_its_deltas_on_ordinary_pages(ict_dir, monkeypatch,
                                                                         numpy_asks_for_huge_pages):
    """The OBJ reader's deltas array is made with numpy asking for ordinary pages from ``LARGE`` on (numpy's setting
    at the moment the array is made; ICT's folder is too small for its own mapping, see above)."""
    from model import pages, readers
    seen = []

    class Numpy:                   # numpy as the reader sees it, noting numpy's setting when the deltas are made
        def __getattr__(self, name):
            return getattr(np, name)

        def empty(self, *args, **kwargs):
            seen.append(numpy_asks_for_huge_pages_now())
            return np.empty(*args, **kwargs)
    monkeypatch.setattr(readers, "np", Numpy())
    small = readers.load_rig(ict_dir)
    monkeypatch.setattr(pages, "LARGE", 16 << 20)
    big = readers.load_rig(ict_dir)
    assert seen == [True, False]
    np.testing.assert_array_equal(big.deltas, small.deltas)
    assert toggle(True) is True


def test_the_windows_preparation_of_a_large_rig_asks_for_ordinary_pages(
        ict_rig, monkeypatch, numpy_asks_for_huge_pages):
    from model import pages, rig_prep
    seen = []
    evaluator = rig_prep.PoseEvaluator

    def spy(rig, *args, **kwargs):             # numpy's setting while the display evaluator copies the deltas
        seen.append(numpy_asks_for_huge_pages_now())
        return evaluator(rig, *args, **kwargs)
    monkeypatch.setattr(rig_prep, "PoseEvaluator", spy)
    rig_prep.prepare_rig(ict_rig)                       # ICT: numpy's own setting
    monkeypatch.setattr(pages, "LARGE", 16 << 20)
    prep = rig_prep.prepare_rig(ict_rig)                # as a studio rig: ordinary pages
    assert seen == [True, False]
    assert toggle(True) is True
    np.testing.assert_array_equal(prep.evaluator.evaluate(np.full(ict_rig.n_shapes, 0.3)),
                                  evaluator(ict_rig).evaluate(np.full(ict_rig.n_shapes, 0.3)))
