"""The local cluster's fork server (``model.batch``): the process every local worker of a batch is forked from, which
imported what a take needs once. Only the standard library here, so that the ``batch`` command can start it first
thing (``app.launch``), before it imports numpy and the rest of the application itself: the fork server's ~2 s of
imports then run on the other core from the command's first ~10 ms, not from after its own ~0.3 s of imports.
"""
from __future__ import annotations

import os

# What a take needs on a worker, imported once by the local cluster's fork server (``start_fork_server``): first
# Dask's worker environment (before numpy loads), scipy's array-API layer without numpy's unused submodules
# (``model.scipy_import``), then Dask, the solve and its exports, and what a take imports on
# first use (the take readers, the weights CSV, the antagonist pairs, the temporal smoothing's scipy.ndimage,
# threadpoolctl), which would otherwise cost every worker's first take ~0.1 s; last the local cluster's scheduler
# (``model.batch_scheduler``, forked from here too; not its dashboard, which it builds when first opened: bokeh's
# ~0.6 s of imports here made every batch wait for them), and numpy.ma, which np.unique loads on its first call in a
# take (~20 ms).
WORKER_MODULES = ("model.batch_env", "model.scipy_import", "distributed", "model.batch", "model.take_workspace",
                  "model.take_exports", "solvers.take_kernel", "model.take_c3d", "model.livelink", "model.weights_csv",
                  "model.antagonists", "scipy.ndimage", "threadpoolctl", "model.batch_scheduler", "numpy.ma")
_FORK_SERVER_HASH_SEED = "6640"         # a nanny's choice when none is set, so that every worker hashes alike


def start_fork_server(preload: tuple = ()) -> bool:
    """Start this process's fork server, which the local cluster's workers are forked from, if it is not running:
    it imports ``WORKER_MODULES`` and ``preload`` in its own process while this one goes on (the ``batch`` command
    starts it before anything else, ``app.launch``; ``model.batch.start_client`` calls this too), then freezes what
    they made for the garbage collector (``model.batch_preloaded``). Costs this process a few milliseconds: it
    imports neither Dask nor numpy. The fork server gets the environment a nanny gives the worker it starts
    (``model.batch_env``) and a fixed hash seed, so that every worker hashes alike. False where there is no fork
    server (the workers are then spawned)."""
    import multiprocessing
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False
    import multiprocessing.forkserver
    modules = [*dict.fromkeys([*WORKER_MODULES, *preload]), "model.batch_preloaded"]   # its gc.freeze() last
    multiprocessing.get_context("forkserver").set_forkserver_preload(modules)
    if os.environ.get("PYTHONHASHSEED") in (None, "0"):
        os.environ["PYTHONHASHSEED"] = _FORK_SERVER_HASH_SEED
    multiprocessing.forkserver.ensure_running()
    return True


def fork_server_address() -> str | None:
    """The address of this process's fork server, None where it has none running (``start_fork_server``)."""
    import multiprocessing.forkserver
    return getattr(multiprocessing.forkserver._forkserver, "_forkserver_address", None)


def can_adopt_fork_server() -> bool:
    """Whether a process forked from the fork server can have its own children forked by it (``adopt_fork_server``):
    Python's fork server as 3.8-3.13 write it, where a child's request carries no key."""
    import multiprocessing.forkserver
    server = multiprocessing.forkserver._forkserver
    return (hasattr(server, "_forkserver_address") and hasattr(server, "_forkserver_alive_fd")
            and not hasattr(server, "_forkserver_authkey"))


def adopt_fork_server(address: str) -> None:
    """In a process forked from the fork server at ``address`` (``model.batch_driver``): let the processes it
    starts with the 'forkserver' method be forked by that server too, as its parent's are, instead of starting a
    fresh fork server here, which would import everything again (~2 s). Python gives such a process the server's
    liveness pipe and resource tracker (``multiprocessing.forkserver._serve_one``) but not its address, and its
    ``ensure_running`` only knows a server it started itself (it waits on the server's pid, which is not its
    child): the address is set here, and ``ensure_running`` only checks the resource tracker."""
    import multiprocessing.forkserver
    from multiprocessing import resource_tracker
    server = multiprocessing.forkserver._forkserver
    server._forkserver_address = address

    def ensure_running() -> None:
        resource_tracker.ensure_running()

    server.ensure_running = ensure_running              # what connect_to_new_process calls
    multiprocessing.forkserver.ensure_running = ensure_running   # the module's name for it (start_fork_server's)


def name_process(name: str) -> None:
    """Give this process ``name`` as the system shows it (Linux's ``prctl(PR_SET_NAME)``; elsewhere nothing): the
    batch's driver, the scheduler and the workers are all forked from the same fork server and would look alike."""
    import ctypes
    import sys
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(15, name.encode()[:15], 0, 0, 0)     # 15: PR_SET_NAME
        except (OSError, AttributeError):
            pass
