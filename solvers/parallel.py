"""Work split over the machine's cores with threads, for work that runs outside the GIL: the compiled kernels
(``solvers.take_kernel``: the built module and the just-in-time one both release the GIL while they run), file
reads and most of numpy's array operations. The results are the same as the work done one piece after another.

The threads are started once a process and kept (``_pool``): starting a pool's threads for each call cost 0.3-0.6 ms
on the 2-core test machine, more while the other core was busy, and a segmentation of ICT FaceKit makes five such
calls.
"""
from __future__ import annotations

import os
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor, wait
from itertools import islice
from typing import Callable, Iterable, Iterator, TypeVar

T = TypeVar("T")
R = TypeVar("R")


def cores() -> int:
    """How many threads work here may use: the cores this process may run on, capped by ``OMP_NUM_THREADS``
    when it is set (a Dask worker's nanny sets it to its one core's share, so a worker never starts more)."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    limit = os.environ.get("OMP_NUM_THREADS", "")
    if limit.isdigit() and int(limit) > 0:
        n = min(n, int(limit))
    return max(1, n)


_POOLS: dict[int, ThreadPoolExecutor] = {}    # threads -> the pool of that many, made on first use
_POOLS_LOCK = threading.Lock()
_IN_POOL = threading.local()                  # ``inside`` is True on a pool's own threads


def _pool(threads: int) -> ThreadPoolExecutor:
    """The process's pool of ``threads`` threads, started on first use and kept (a forked child makes its own: the
    parent's threads do not exist there, see ``_forget_pools``)."""
    with _POOLS_LOCK:
        pool = _POOLS.get(threads)
        if pool is None:
            pool = _POOLS[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="parallel",
                                                        initializer=setattr, initargs=(_IN_POOL, "inside", True))
        return pool


def _forget_pools() -> None:
    """In a forked child: the parent's pools have no threads here (their lock may even be held), so start afresh."""
    global _POOLS_LOCK
    _POOLS.clear()
    _POOLS_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)


def ordered_map(fn: Callable[[T], R], items: Iterable[T], threads: int | None = None,
                ahead: int | None = None) -> Iterator[R]:
    """``fn`` of each item, yielded in the items' order, computed on up to ``threads`` threads (default
    ``cores()``) at most ``ahead`` items (default twice the threads) ahead of the one yielded, which bounds the
    memory of results not yet taken; one thread runs them here, one after another. The first exception in the
    items' order is raised where its result would have been, and the items not yet started are cancelled, as a
    loop would have stopped there; so are they when the caller stops taking results (the generator closed). Items
    still running then are waited for: when this returns or raises, no ``fn`` of its items runs any more.

    The threads are the process's pool of that many (``_pool``), shared by the calls of every thread; called from
    one of the pool's own threads (work nested in work), the items run there, one after another, so a pool never
    waits on itself."""
    threads = max(1, threads or cores())
    if threads == 1 or getattr(_IN_POOL, "inside", False):
        for item in items:
            yield fn(item)
        return
    items = iter(items)
    pool = _pool(threads)
    pending: deque = deque()
    try:
        for item in islice(items, max(1, ahead or 2 * threads)):
            pending.append(pool.submit(fn, item))
        while pending:
            result = pending.popleft().result()
            for item in islice(items, 1):
                pending.append(pool.submit(fn, item))
            yield result
    finally:
        running = [future for future in pending if not future.cancel()]
        wait(running)


def for_spans(fn: Callable[[int, int], object], n: int, threads: int | None = None) -> None:
    """``fn(a, b)`` for ``threads`` (default ``cores()``) equal spans ``a..b`` of ``range(n)``, one a thread, for
    work each span writes into its own part of shared arrays; returns when every span is done (the first
    exception raised here, as ``ordered_map`` raises it)."""
    parts = max(1, threads or cores())
    cuts = [n * i // parts for i in range(parts + 1)]
    for _ in ordered_map(lambda span: fn(*span), zip(cuts[:-1], cuts[1:]), threads=parts):
        pass


class Background:
    """``fn()`` started now on a thread of its own, for work that mostly runs outside the GIL (a k-d tree's build,
    a compiled kernel) to overlap work on this thread; ``result()`` waits for it and returns its value or raises
    its exception, every time it is asked. With one core (``cores()``) nothing starts early: the first ``result()``
    runs ``fn`` itself."""

    def __init__(self, fn: Callable[[], R]) -> None:
        self._fn, self._value, self._error, self._ran = fn, None, None, False
        self._thread = threading.Thread(target=self._run, name="background", daemon=True) if cores() > 1 else None
        if self._thread is not None:
            self._thread.start()

    def _run(self) -> None:
        try:
            self._value = self._fn()
        except BaseException as exc:   # raised again by result(), in its caller
            self._error = exc
        self._ran = True

    def result(self):
        if self._thread is not None:
            self._thread.join()
        elif not self._ran:
            self._run()
        if self._error is not None:
            raise self._error
        return self._value
