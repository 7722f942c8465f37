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


@pytest.fixture
def numpy_asks_for_huge_pages():
    before = toggle(True)
    yield
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


def test_a_large_load_asks_for_ordinary_pages_and_an_ict_sized_one_keeps_huge_pages(
        tmp_path, ict_dir, ict_rig, monkeypatch, numpy_asks_for_huge_pages):
    from model import project, readers
    from model.project import Project, load_project, save_project
    save_project(Project(rig=ict_rig.copy()), tmp_path / "ict.bsproj")
    # ICT's deltas (36.5 MB: a mapping of their own) are under LARGE: numpy's request stands
    assert ict_rig.deltas.nbytes < project.LARGE
    assert huge_pages_asked(load_project(tmp_path / "ict.bsproj").rig.deltas)
    assert huge_pages_asked(readers.load_rig(ict_dir).deltas)
    # the same files as a studio-scale rig would be read: ordinary pages
    monkeypatch.setattr(project, "LARGE", 16 << 20)
    monkeypatch.setattr(readers, "LARGE", 16 << 20)
    big = load_project(tmp_path / "ict.bsproj").rig
    assert not huge_pages_asked(big.deltas)
    np.testing.assert_array_equal(big.deltas, ict_rig.deltas)
    assert not huge_pages_asked(readers.load_rig(ict_dir).deltas)
    assert toggle(True) is True            # and numpy asks again afterwards


def test_the_windows_preparation_of_a_large_rig_asks_for_ordinary_pages(
        ict_rig, monkeypatch, numpy_asks_for_huge_pages):
    from model import rig_prep
    seen = []
    evaluator = rig_prep.PoseEvaluator

    def spy(rig, *args, **kwargs):             # numpy's setting while the display evaluator copies the deltas
        seen.append(toggle(False))
        toggle(seen[-1])
        return evaluator(rig, *args, **kwargs)
    monkeypatch.setattr(rig_prep, "PoseEvaluator", spy)
    rig_prep.prepare_rig(ict_rig)                       # ICT: numpy's own setting
    monkeypatch.setattr(rig_prep, "LARGE", 16 << 20)
    prep = rig_prep.prepare_rig(ict_rig)                # as a studio rig: ordinary pages
    assert seen == [True, False]
    assert toggle(True) is True
    np.testing.assert_array_equal(prep.evaluator.evaluate(np.full(ict_rig.n_shapes, 0.3)),
                                  evaluator(ict_rig).evaluate(np.full(ict_rig.n_shapes, 0.3)))
