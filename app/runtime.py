"""Process-wide runtime settings for the app, the command line and the tests."""
from __future__ import annotations

import os

# Environment variables the BLAS libraries read once, when they are loaded (OpenBLAS, MKL, BLIS).
_BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def limit_blas_threads(n: int = 1) -> None:
    """Run BLAS with ``n`` threads (single-threaded by default), in every BLAS library of the process.

    Our products are small (a pose is one 57×64k matrix-vector product; solves are K≤60 systems):
    threads cost more in hand-offs than they save, and on a busy 2-core machine a threaded gemv
    goes from ~0.5 ms to ~12 ms (measured on ICT FaceKit).

    numpy and scipy each bring their own OpenBLAS, loaded when the package is first imported, and
    threadpoolctl can only change libraries that are already loaded. So: numpy is imported here and
    limited at run time, and the environment variables are set for the libraries loaded later (scipy's
    reads OPENBLAS_NUM_THREADS when ``scipy.linalg`` or ``scipy.sparse.linalg`` is first imported).
    ``blas_threads()`` tells what every loaded library runs with.
    """
    for name in _BLAS_THREAD_VARIABLES:
        os.environ[name] = str(int(n))
    import numpy  # noqa: F401  (loads numpy's BLAS, so that the limit below reaches it)
    from threadpoolctl import threadpool_limits
    threadpool_limits(int(n), user_api="blas")


def blas_threads() -> dict[str, int]:
    """{library file: threads} for every BLAS library loaded in this process (threadpoolctl)."""
    from threadpoolctl import threadpool_info
    return {info["filepath"]: int(info["num_threads"]) for info in threadpool_info() if info["user_api"] == "blas"}


def quiet_numeric_warnings() -> None:
    """Hide numpy's RuntimeWarnings (a mean of an empty slice where a marker is never seen, ...) from a user of the
    command line and the window, in this process and in the processes it starts (``PYTHONWARNINGS``: a batch's
    workers): they print a source line meant for developers, while what matters reaches the user as a sentence (a
    warning, a refusal, a report's field)."""
    import warnings
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    given = os.environ.get("PYTHONWARNINGS", "")
    if "ignore::RuntimeWarning" not in given:
        os.environ["PYTHONWARNINGS"] = ",".join(filter(None, (given, "ignore::RuntimeWarning")))
