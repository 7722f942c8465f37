"""Imports scipy's array-API layer without the numpy submodules it would drag in, once per process, when imported:
by the ``blendshape-studio`` command before anything else (``app.launch``) and by the local cluster's fork server
(``model.fork_server.WORKER_MODULES``).

Every scipy subpackage imports ``scipy._lib._array_api``, which imports its vendored ``array_api_compat.numpy``:
a copy of numpy's namespace made by ``from numpy import *`` and a ``hasattr`` on every name ``dir(numpy)`` lists.
Both name numpy's lazily loaded submodules, so that copy imports ``numpy.f2py`` (and the character-set detection
it uses), ``numpy.testing``, ``numpy.ma``, ``numpy.polynomial``, ``numpy.random``, ``numpy.ctypeslib`` and the
rest: 115 modules, 0.05-0.09 s of a fresh process's start (measured: ``scipy.sparse``, ``ndimage``, ``spatial``
and ``linalg`` in 0.39 s against 0.44 s, medians of 8 alternated runs), none of which the application uses.

While that one import runs, numpy's ``__all__`` and ``__dir__`` leave out the submodules not loaded yet; they are
restored at once, and the submodules stay importable as ever (``np.random`` or ``import numpy.testing`` loads
them on first use). The copy then lacks those names only, which scipy's code reaches through numpy itself, not
through the copy (its array-API namespace is what the array API standard defines: ``linalg`` and ``fft``, which
the copy imports itself, are kept)."""
from __future__ import annotations

import sys


def import_scipy_array_api() -> None:
    """Import ``scipy._lib._array_api`` with numpy's not-yet-loaded submodules hidden (a no-op once imported)."""
    if "scipy._lib._array_api" in sys.modules:
        return
    import numpy
    names = numpy.__all__
    listing = vars(numpy).get("__dir__")      # numpy's own module __dir__ (lists the unloaded submodules)
    unloaded = {n for n in names if n not in vars(numpy)} - {"typing", "fft"}   # the copy imports those two
    numpy.__all__ = [n for n in names if n not in unloaded]
    if listing is not None:
        numpy.__dir__ = lambda: [n for n in listing() if n not in unloaded]
    try:
        import scipy._lib._array_api  # noqa: F401
    except ImportError:              # a scipy without that module: nothing to spare
        pass
    finally:
        numpy.__all__ = names
        if listing is not None:
            numpy.__dir__ = listing


import_scipy_array_api()
