"""The last module the local cluster's fork server imports (``model.fork_server.start_fork_server``): once everything
a worker needs is imported there, ``gc.freeze()`` moves those objects (~220,000 of them: Dask, numpy, scipy, VTK,
pyvista, matplotlib through pyvista, the solver) out of the cyclic garbage collector's reach in every worker forked
afterwards.

Without it a worker's full collection walks all of them: 85 ms in one process, 130-180 ms inside a worker during a
batch, once or twice a run per worker, with the GIL held, so the worker's take and its event loop (heartbeats, the
next task) stand still meanwhile; with two workers on two cores that is time taken from the takes. Those objects live
as long as the worker anyway; only the objects a worker makes itself (its Dask state, the job, the takes) are
collected as before. The frozen objects' pages are also shared with the fork server longer (a collection no longer
writes to them).
"""
from __future__ import annotations

import gc
import signal

from distributed.versions import get_versions

from model.batch_env import restore_yaml

restore_yaml()     # the fork server's imports are done: PyYAML's own parser for anything read later

# Dask's scheduler, each worker and the client describe their installation when they meet (the worker as it
# registers, the scheduler for each worker and client that registers): the packages' versions, read from their
# metadata on the disk, and the processor's name, for which Python runs ``uname -p`` in a subprocess (a fork of a
# process that has VTK and LLVM mapped). Both are cached once read (``functools.cache``, ``cached_property``): read
# here, once, every process forked from here finds them, ~8 ms each on the way to its first take.
get_versions()

gc.freeze()

# Ctrl-C in the terminal reaches every process of the command's process group: the workers and the scheduler forked
# from here would each print a KeyboardInterrupt traceback while the command closes the cluster anyway. A signal mask
# is inherited by a fork, so SIGINT stays blocked in all of them (the command, which closes them, is not forked
# from here and still gets it).
signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
