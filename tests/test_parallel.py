"""solvers.parallel: work on several threads gives what the loop gives, in order, errors and all."""
from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from solvers.parallel import cores, for_spans, ordered_map


def test_results_come_in_the_items_order_whatever_order_they_finish_in():
    def slow_first(i):
        time.sleep(0.02 if i == 0 else 0.0)     # the first item finishes last
        return i * i
    assert list(ordered_map(slow_first, range(12), threads=3)) == [i * i for i in range(12)]


def test_the_first_error_in_order_is_raised_where_its_result_was_and_later_items_are_not_started():
    started: list[int] = []
    lock = threading.Lock()

    def work(i):
        with lock:
            started.append(i)
        if i in (3, 5):
            time.sleep(0.01 if i == 3 else 0.0)   # item 5 fails first in time, item 3 first in order
            raise ValueError(f"item {i}")
        return i
    got = []
    with pytest.raises(ValueError, match="item 3"):
        for r in ordered_map(work, range(100), threads=2, ahead=4):
            got.append(r)
    assert got == [0, 1, 2]
    assert max(started) < 10, f"items up to {max(started)} were started after the error"


def test_no_more_than_ahead_items_are_computed_past_the_one_taken():
    computed: list[int] = []

    def work(i):
        computed.append(i)
        return i
    gen = ordered_map(work, range(50), threads=2, ahead=3)
    assert next(gen) == 0
    time.sleep(0.05)
    assert len(computed) <= 4            # item 0 and at most 3 ahead of it
    gen.close()                          # the caller stops: nothing more is started
    n = len(computed)
    time.sleep(0.05)
    assert len(computed) == n <= 4


def test_one_thread_runs_the_items_here_in_order():
    here = threading.get_ident()
    assert list(ordered_map(lambda i: (i, threading.get_ident() == here), range(3), threads=1)) == \
        [(0, True), (1, True), (2, True)]


def test_cores_follows_omp_num_threads(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert cores() == 1
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert cores() >= 1


def test_background_work_runs_beside_this_thread_and_hands_back_its_value_or_its_error(monkeypatch):
    from solvers.parallel import Background
    here = threading.get_ident()
    ran_on: list[int] = []

    def work():
        ran_on.append(threading.get_ident())
        return 42
    assert Background(work).result() == 42
    assert ran_on[-1] != here or cores() == 1

    def fails():
        raise ValueError("the work's own error")
    job = Background(fails)
    with pytest.raises(ValueError, match="the work's own error"):
        job.result()
    monkeypatch.setenv("OMP_NUM_THREADS", "1")       # one core: nothing starts early, result() runs it here
    job = Background(work)
    n = len(ran_on)
    assert job.result() == 42 and ran_on[-1] == here
    assert job.result() == 42 and len(ran_on) == n + 1   # asked again: the value, not a second run


@pytest.mark.parametrize("n,threads", [(10, 3), (2, 3), (0, 2), (7, 1)])
def test_spans_cover_every_index_once_in_order_and_an_error_comes_back(n, threads):
    seen: list[tuple[int, int]] = []
    lock = threading.Lock()

    def work(a: int, b: int) -> None:
        with lock:
            seen.append((a, b))
    for_spans(work, n, threads)
    seen.sort()
    assert len(seen) == threads and seen[0][0] == 0 and seen[-1][1] == n
    assert all(b0 == a1 for (_, b0), (a1, _) in zip(seen, seen[1:]))            # no gap, no overlap
    assert max(b - a for a, b in seen) - min(b - a for a, b in seen) <= 1       # equal shares

    def fail(a: int, b: int) -> None:
        if a <= n // 2 < b or (n == 0):
            raise ValueError("span")
    with pytest.raises(ValueError, match="span"):
        for_spans(fail, n, threads)


def test_the_threads_are_started_once_and_kept_for_every_call():
    def thread(_):
        time.sleep(0.005)       # both threads take items
        return threading.current_thread()
    first = set(ordered_map(thread, range(8), threads=2))
    second = set(ordered_map(thread, range(8), threads=2))
    assert len(first) == 2 and second == first      # the same two Thread objects, not two new ones a call


def test_a_caller_that_stops_taking_results_returns_after_the_running_items_end():
    ended: list[int] = []

    def work(i):
        if i == 1:
            time.sleep(0.1)
            ended.append(i)
        return i
    gen = ordered_map(work, range(10), threads=2, ahead=2)
    assert next(gen) == 0        # item 1 is running on the other thread now
    gen.close()
    assert ended == [1], "ordered_map returned while one of its items still ran"


def test_work_nested_in_work_runs_on_the_pools_thread_and_never_waits_on_the_pool():
    def outer(i):
        here = threading.current_thread()
        inner = list(ordered_map(lambda j: (j, threading.current_thread() is here), range(4), threads=2))
        assert inner == [(j, True) for j in range(4)]
        return i
    done: list[list[int]] = []
    worker = threading.Thread(target=lambda: done.append(list(ordered_map(outer, range(6), threads=2))), daemon=True)
    worker.start()
    worker.join(10)
    assert done == [list(range(6))], "nested work waited on its own pool"


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork here")
def test_a_forked_child_starts_threads_of_its_own():
    assert list(ordered_map(lambda i: i, range(4), threads=2)) == [0, 1, 2, 3]   # the parent's pool exists
    pid = os.fork()
    if pid == 0:                                  # the child: the parent's threads are not here
        try:
            ok = list(ordered_map(lambda i: i * i, range(6), threads=2)) == [0, 1, 4, 9, 16, 25]
        finally:
            os._exit(0 if ok else 1)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            assert os.waitstatus_to_exitcode(status) == 0
            return
        time.sleep(0.01)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    pytest.fail("a forked child's ordered_map waited on the parent's threads")
