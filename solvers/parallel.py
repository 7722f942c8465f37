"""Work split over the machine's cores with threads, for work that runs outside the GIL: the compiled kernels
(``solvers.take_kernel``: the built module and the just-in-time one both release the GIL while they run), file
reads and most of numpy's array operations. The results are the same as the work done one piece after another.
"""
from __future__ import annotations

import os
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
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


def ordered_map(fn: Callable[[T], R], items: Iterable[T], threads: int | None = None,
                ahead: int | None = None) -> Iterator[R]:
    """``fn`` of each item, yielded in the items' order, computed on up to ``threads`` threads (default
    ``cores()``) at most ``ahead`` items (default twice the threads) ahead of the one yielded, which bounds the
    memory of results not yet taken; one thread runs them here, one after another. The first exception in the
    items' order is raised where its result would have been, and the items not yet started are cancelled, as a
    loop would have stopped there; so are they when the caller stops taking results (the generator closed)."""
    threads = max(1, threads or cores())
    if threads == 1:
        for item in items:
            yield fn(item)
        return
    items = iter(items)
    pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="parallel")
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
        for future in pending:
            future.cancel()
        pool.shutdown(wait=True)


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
