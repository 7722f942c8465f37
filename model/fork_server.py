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
