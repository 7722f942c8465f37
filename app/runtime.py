"""Process-wide runtime settings for the app, the command line and the tests."""
from __future__ import annotations


def limit_blas_threads(n: int = 1) -> None:
    """Run BLAS single-threaded.

    Our products are small (a pose is one 57×64k matrix-vector product; solves are K≤60 systems):
    threads cost more in hand-offs than they save, and on a busy 2-core machine a threaded gemv
    goes from ~1 ms to ~20 ms (measured on ICT FaceKit). threadpoolctl changes it at run time,
    whatever numpy was built with.
    """
    from threadpoolctl import threadpool_limits
    threadpool_limits(n, user_api="blas")
