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
the copy imports itself, are kept).

The scipy subpackages imported later in the process skip the parse of their functions' docstrings that scipy does
on import for its documentation (``_UnparsedDoc``)."""
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
        import scipy._lib._array_api as array_api
    except ImportError:              # a scipy without that module: nothing to spare
        return
    finally:
        numpy.__all__ = names
        if listing is not None:
            numpy.__dir__ = listing
    try:
        import scipy._lib._util as util      # every subpackage imports it too
    except ImportError:
        util = None
    for module in (array_api, util):
        if isinstance(getattr(module, "FunctionDoc", None), type):
            module.FunctionDoc = _UnparsedDoc


class _UnparsedDoc:
    """Stands in for numpydoc's ``FunctionDoc`` in ``scipy._lib._array_api`` and ``_util``, whose decorators
    (``xp_capabilities``, ``_apply_over_batch``) parse the docstring of every function they mark, when its
    subpackage is imported, to append a note to it (the array libraries it was tested with, the batching rule): ~300
    parses, ~0.1 s of a fresh process (``scipy.spatial``, ``ndimage``, ``sparse`` and ``linalg`` imported in
    0.21-0.31 s against 0.30-0.40 s). Appending to the notes or the extended summary parses nothing, and the
    docstring stays as written, without the note; the decorators' other work (the capabilities' registration) is
    unchanged. Anything else asked of it is answered by a real ``FunctionDoc``, parsed then, with what was appended."""

    _APPENDED = ("Notes", "Extended Summary")

    def __init__(self, func, *args, **kwargs) -> None:
        self._args = (func,) + args, kwargs
        self._doc = getattr(func, "__doc__", None) or ""
        self._pending: dict[str, list] = {}
        self._real = None

    def __getitem__(self, section: str):
        if self._real is None and section in self._APPENDED:
            return self._pending.setdefault(section, [])
        return self._parsed()[section]

    def __setitem__(self, section: str, value) -> None:
        self._parsed()[section] = value

    def __getattr__(self, name: str):
        return getattr(self._parsed(), name)

    def __str__(self) -> str:
        # the decorators drop the first line (the signature) of what this returns
        return "\n" + self._doc if self._real is None else str(self._real)

    def _parsed(self):
        if self._real is None:
            from scipy._lib._docscrape import FunctionDoc
            args, kwargs = self._args
            real = FunctionDoc(*args, **kwargs)
            for section, lines in self._pending.items():
                lines[:0] = real[section]
                real[section] = lines
            self._real = real
        return self._real


import_scipy_array_api()
