"""The first module the local cluster's fork server imports (``model.fork_server.start_fork_server``): the environment
a Dask nanny gives the worker it starts (``distributed.nanny.pre-spawn-environ``: one BLAS/OpenMP thread, glibc's
memory trimming) and ordinary memory pages for numpy (below), set in the fork server before anything there loads
numpy, so that every worker forked from it has it. A nanny sets it in its own process before it starts a worker,
which a forked worker never sees.

Read from Dask's configuration as ``distributed.config`` reads it (its defaults file under the user's settings)
without importing ``distributed``, whose import loads numpy: the process that starts the fork server (the
``batch`` command, before it loads the rig) then pays nothing for it. A variable already set is kept.

Also, for the fork server's imports only, YAML is read with libyaml (``fast_yaml``, until ``restore_yaml``).
"""
from __future__ import annotations

import importlib.util
import os

import yaml

_pure_safe_load = yaml.safe_load


def _libyaml_safe_load(stream):
    """``yaml.safe_load`` through libyaml's parser: the same values (the same constructor, ``SafeConstructor``)."""
    return yaml.load(stream, Loader=yaml.CSafeLoader)


def fast_yaml() -> bool:
    """Read YAML with libyaml (PyYAML's C extension) until ``restore_yaml``; False where PyYAML was built without it.

    Importing Dask and distributed parses their defaults (``dask.yaml``, and ``distributed.yaml`` twice in the fork
    server: ``pre_spawn_environ`` below, then ``distributed.config``) with ``yaml.safe_load``, PyYAML's parser in pure
    Python: ~30 ms of the fork server's ~0.7 s of imports, which is what a batch waits for (the command is ready before
    them). libyaml reads the same files into the same values in ~3 ms."""
    if getattr(yaml, "CSafeLoader", None) is None:
        return False
    yaml.safe_load = _libyaml_safe_load
    return True


def restore_yaml() -> None:
    """``yaml.safe_load`` as PyYAML has it, for whatever the workers read later (``model.batch_preloaded``, the fork
    server's last import, calls this)."""
    yaml.safe_load = _pure_safe_load


fast_yaml()

import dask  # noqa: E402  (dask itself does not import numpy; its configuration read with libyaml)


def pre_spawn_environ() -> dict[str, str]:
    """``distributed.nanny.pre-spawn-environ`` with Dask's defaults under the user's configuration."""
    try:
        env = dask.config.get("distributed.nanny.pre-spawn-environ")
    except KeyError:            # distributed not imported here: its defaults are not in the configuration yet
        spec = importlib.util.find_spec("distributed")
        with open(os.path.join(os.path.dirname(spec.origin), "distributed.yaml")) as f:
            dask.config.update_defaults(yaml.safe_load(f))
        env = dask.config.get("distributed.nanny.pre-spawn-environ")
    return {k: str(v) for k, v in env.items() if v is not None}


for _name, _value in pre_spawn_environ().items():
    os.environ.setdefault(_name, _value)

# Ordinary memory pages for numpy's arrays in the workers. numpy asks Linux for transparent huge pages (madvise) for
# every array of 4 MB or more; where the kernel compacts memory on first touch to find them (THP defrag 'madvise', a
# common default), two workers side by side spent twice the kernel time a take that one worker alone did (measured
# on the 2-core development machine, 16 takes of ICT: 0.39-0.44 s of system time a worker on 2 workers, 0.16-0.18 s
# without huge pages; 0.23-0.28 s on 1 worker either way). A take's large arrays are written once and dropped.
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
