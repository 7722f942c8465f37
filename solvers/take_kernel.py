"""The compiled inner loop of a take solve (``solvers.take_solve.TakeSolver._pass``), loaded without numba; the
same extension module also holds the OBJ vertex-line reader (``solvers.decimal_kernel_jit``), the per-shape
deformation maps and the antagonist pairs' sums (``solvers.shape_kernels_jit``), which the readers, the
segmentation and the antagonist pairs use through ``built()``, and the batch previews' rasteriser
(``solvers.raster_kernel_jit``).

The kernel's source is ``solvers.take_kernel_jit`` (numba). Importing numba and initialising its compiler costs
about 0.5 s of CPU in every fresh process (the command line's ``solve``, the GUI's first take), more than the
whole solve of a 358-frame take; so the kernel is compiled ahead of time (numba.pycc) into a small extension
module, once per machine and per version of the source, and later processes load that (well under 1 ms).
Like the just-in-time kernels (``nogil=True``), the built functions release the GIL while they run (``_compile``),
so a loader's or a solver's thread leaves the GUI's event loop and other threads free, and the readers and the
segmentation can run them on several cores at once. The module is kept in ``solvers/__pycache__`` (or the user's
cache folder when that is not writable) under a
name that carries a hash of the source, numpy's version and the processor it is compiled for (its own
instruction set, as the just-in-time kernel uses), so an edited kernel, or another machine, gets a new build. When the
ahead-of-time build cannot run (no C compiler), the kernel runs through numba's just-in-time dispatcher
(``cache=True``); where numba is missing, ``available()`` is False and the solver keeps its Python loop.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
import sys
import sysconfig
import tempfile
import threading
from pathlib import Path

import numpy as np

_SOURCE = Path(__file__).with_name("take_kernel_jit.py")
_DECIMAL_SOURCE = Path(__file__).with_name("decimal_kernel_jit.py")
_SHAPES_SOURCE = Path(__file__).with_name("shape_kernels_jit.py")
_RASTER_SOURCE = Path(__file__).with_name("raster_kernel_jit.py")
_MODULE = "_take_kernel_aot"
# solve_pass's argument types, in take_kernel_jit.solve_pass's order (arrays C-contiguous: ``solve_pass`` below
# makes them so)
_SIGNATURE = ("i8(f8[:,:,::1], i8[::1], f8[::1], f8[:,::1], f8[::1], f8[:,::1], f8[:,::1], f8[:,::1], f8[:,:,::1], "
              "f8[:,:,::1], f8, f8[::1], i8[::1], f8, i8, f8, f8, f8, f8, i8, f8[:,::1], f8[:,:,::1], f8[:,::1], "
              "b1[::1], b1)")
_PARSE_SIGNATURE = "i8(u1[::1], f8[:,::1], i8[:,::1], i8[::1])"   # decimal_kernel_jit.parse_vertex_lines
_MAPS_SIGNATURE = "i8(i4[::1], i4[::1], f8[::1], f8[:,::1], f8[::1], f8[::1], i8, i8)"   # shape_kernels_jit.shape_maps
_MAPS4_SIGNATURE = "i8(i4[::1], i4[::1], f8[::1], f8[:,:,::1], f8[:,::1], f8[:,::1], i8, i8)"   # .shape_maps4
_PAIRS_SIGNATURE = "i8(f8[:,:,::1], f8[:,::1], b1[:,::1], f8[:,::1], f8[:,::1], f8[:,::1])"   # .antagonist_sums
_QP_SIGNATURE = "i8(f8[:,::1], f8[::1], f8[::1], f8, f8, f8, i8)"   # take_kernel_jit.box_qp_fresh
_NORMALS_SIGNATURE = "i8(f4[:,::1], i8[::1], i8[::1], i8[::1], f4[:,::1])"   # shape_kernels_jit.vertex_normals32
_RASTER_SIGNATURE = ("i8(f4[:,::1], f4[:,::1], i8[:,::1], u1[::1], f8[::1], f8[:,::1], f8[:,::1], u1[:,::1], "
                     "f8[:,::1], u1[:,:,::1])")                               # raster_kernel_jit.draw_mesh
# the built module's Python wrappers release the GIL around each call: part of the cache key, so that a build
# made without it is not loaded
_RELEASES_GIL = "release_gil"
_impl = None           # the loaded kernel: the extension module, or take_kernel_jit
_load_lock = threading.RLock()


def available() -> bool:
    """Whether the kernel can run here (numba installed, or its ahead-of-time build present)."""
    return _impl is not None or importlib.util.find_spec("numba") is not None or _built_path() is not None


def pass_masks(Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(masks (n, M) bool, mask_of (F,) int64): the distinct missing-marker masks of a take's frames and each
    frame's index into them; -1 for frames with fewer than 3 markers."""
    valid = np.isfinite(Y).all(axis=2)
    masks, inverse = np.unique(valid, axis=0, return_inverse=True)
    mask_of = inverse.ravel().astype(np.int64)
    mask_of[valid.sum(axis=1) < 3] = -1
    return masks, mask_of


def solve_pass(Y, order, w, R, t, rest, Dm, At, Hs, Bts, mu, tols, mask_of, lam_t, iterations, rw, rw0, lo, hi,
               max_iter, W, Rs, ts, solved, first_solved_before) -> int:
    """``take_kernel_jit.solve_pass`` (its docstring tells the arguments) in the compiled kernel. w, R, t, W, Rs,
    ts and solved are written in place, so they must be C-contiguous float64 (bool for ``solved``)."""
    for a in (w, R, t, W, Rs, ts, solved):
        if not a.flags.c_contiguous:
            raise ValueError("solve_pass writes its state and outputs in place: pass C-contiguous arrays")
    c = np.ascontiguousarray
    return int(kernel().solve_pass(
        c(Y, np.float64), c(order, np.int64), w, R, t, c(rest, np.float64), c(Dm, np.float64), c(At, np.float64),
        c(Hs, np.float64), c(Bts, np.float64), float(mu), c(tols, np.float64), c(mask_of, np.int64),
        float(lam_t), int(iterations), float(rw), float(rw0), float(lo), float(hi), int(max_iter), W, Rs, ts,
        solved, bool(first_solved_before)))


def box_qp_fresh(H, g, w, lo, hi, tol, max_iter=200) -> int:
    """``take_kernel_jit.box_qp_fresh`` in the compiled kernel: the box QP ½wᵀHw − gᵀw over lo ≤ w ≤ hi of a
    one-off H from ``w`` (C-contiguous float64, changed in place to the minimiser); returns the iterations."""
    if not (w.flags.c_contiguous and w.dtype == np.float64):
        raise ValueError("box_qp_fresh writes the weights in place: pass a C-contiguous float64 array")
    c = np.ascontiguousarray
    return int(kernel().box_qp_fresh(c(H, np.float64), c(g, np.float64), w, float(lo), float(hi), float(tol),
                                     int(max_iter)))


def usable_now() -> bool:
    """Whether the compiled kernel can run without being compiled first: loaded, or built for this machine (the
    callers with a Python loop of their own use it only then: ``solvers.weight_solve``)."""
    return _impl is not None or (available() and ready())


def ready() -> bool:
    """Whether ``kernel()`` returns at once: the kernel is loaded, or built for this machine, or numba is missing
    (the Python loop then). False: the first solve compiles it first (``BUILD_MESSAGE``)."""
    return _impl is not None or importlib.util.find_spec("numba") is None or _built_path() is not None


# the ahead-of-time build: 5-25 s measured (15-25 s CPU the first time, less with numba's caches warm)
BUILD_MESSAGE = "Compiling the take solver for this processor (once per installation, up to half a minute)\u2026"


def start_background_build():
    """Build the kernel in a separate process (a ``subprocess.Popen``, or None when ``ready()``), so that the
    first solve does not wait for it: the GUI starts this when it opens. A solve that starts meanwhile waits for
    that build instead of starting its own (``_build``'s lock)."""
    if ready():
        return None
    import subprocess
    return subprocess.Popen([sys.executable, "-c", "from solvers import take_kernel; take_kernel.kernel()"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            cwd=str(_SOURCE.parent.parent), start_new_session=True)


def built():
    """The ahead-of-time module when it is built for this machine (its ``solve_pass``, ``parse_vertex_lines``,
    ``shape_maps`` and ``antagonist_sums``), else None: never builds it, never imports numba (a reader's fast
    path; a loader thread may call this while a solve thread calls ``kernel()``: one lock)."""
    global _impl
    with _load_lock:
        if _impl is None or not hasattr(_impl, "parse_vertex_lines"):
            module = _load_built()
            if module is None:
                return None
            _impl = module
        return _impl


def kernel():
    """The module whose ``solve_pass`` runs the sweep: the ahead-of-time build (built here on first use), else
    the just-in-time one."""
    global _impl
    with _load_lock:
        if _impl is None:
            _impl = _load_built()
        if _impl is not None:
            return _impl
    module = _build() or _jit()      # not under the lock: a build takes up to half a minute (``_build_lock``)
    with _load_lock:
        if _impl is None or not hasattr(_impl, "parse_vertex_lines"):
            _impl = module
        return _impl


def __getattr__(name):
    """The jit module's other functions (``box_qp`` ...), for tests that call them one by one."""
    if name.startswith("_"):
        raise AttributeError(name)
    return getattr(_jit(), name)


# --- the ahead-of-time build ---------------------------------------------------------------------------------
def _cpu() -> str:
    """This machine's processor (its model and instruction set flags): the build is compiled for it."""
    try:
        with open("/proc/cpuinfo") as f:
            return "".join(line for line in f.read().split("\n\n")[0].splitlines(True)
                           if line.startswith(("model name", "flags", "Features", "CPU part")))
    except OSError:
        import platform
        return platform.machine() + platform.processor()


@functools.lru_cache(maxsize=1)
def _key() -> str:
    h = hashlib.sha256(_SOURCE.read_bytes() + _DECIMAL_SOURCE.read_bytes() + _SHAPES_SOURCE.read_bytes()
                       + _RASTER_SOURCE.read_bytes())
    for part in (_SIGNATURE, _PARSE_SIGNATURE, _MAPS_SIGNATURE, _MAPS4_SIGNATURE, _PAIRS_SIGNATURE, _QP_SIGNATURE,
                 _NORMALS_SIGNATURE, _RASTER_SIGNATURE,
                 np.__version__, _cpu(), _RELEASES_GIL):
        h.update(part.encode())
    return h.hexdigest()[:16]


def _cache_dirs() -> list[Path]:
    home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "blendshape-studio"
    return [_SOURCE.parent / "__pycache__", home]


def _file_name() -> str:
    return f"{_MODULE}_{_key()}{sysconfig.get_config_var('EXT_SUFFIX') or '.so'}"


def _built_path() -> Path | None:
    name = _file_name()
    for folder in _cache_dirs():
        if (folder / name).is_file():
            return folder / name
    return None


def _import(path: Path):
    spec = importlib.util.spec_from_file_location(_MODULE, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _load_built():
    path = _built_path()
    if path is None:
        return None
    try:
        return _import(path)
    except (ImportError, OSError):
        return None      # a damaged or foreign build: rebuilt below


def _build():
    """Compile the kernel ahead of time into the first writable cache folder (about 20 s, once); None when it
    cannot be built here."""
    if importlib.util.find_spec("numba") is None:
        return None
    name = _file_name()
    for folder in _cache_dirs():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with _build_lock(folder):
                if (folder / name).is_file():       # built by another process while this one waited
                    return _import(folder / name)
                _compile(folder, name)
            for old in folder.glob(f"{_MODULE}_*"):       # builds of earlier sources or another processor
                if old.name != name:
                    try:
                        old.unlink()
                    except OSError:
                        pass
            return _import(folder / name)
        except Exception:        # no compiler, a read-only folder, ...: the next folder, then the jit kernel
            continue
    return None


class _build_lock:
    """An exclusive lock on ``folder``'s build (``flock`` on a lock file): a process that needs the kernel while
    another builds it (the GUI's background build, a batch's workers) waits for that build instead of doing the
    same 20 s of work beside it. A no-op where ``fcntl`` is missing."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / f".{_MODULE}.lock"
        self.file = None

    def __enter__(self):
        try:
            import fcntl
        except ImportError:
            return self
        self.file = open(self.path, "a")
        fcntl.flock(self.file, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc) -> None:
        if self.file is not None:
            self.file.close()       # releases the lock


def _compile(folder: Path, name: str) -> None:
    """The numba.pycc build of the kernel into ``folder / name``, moved into place atomically."""
    import warnings
    with tempfile.TemporaryDirectory(dir=folder, prefix=".take-kernel-build-") as tmp:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # numba.pycc's pending deprecation
            from numba.pycc import CC
            from . import decimal_kernel_jit, raster_kernel_jit, shape_kernels_jit, take_kernel_jit
            import llvmlite.binding as llvm
            cc = CC(_MODULE)
            cc.target_cpu = llvm.get_host_cpu_name()   # this processor's instructions (AVX2, FMA ...): the
            cc.output_dir = tmp                        # cache key carries the processor (_cpu)
            cc.output_file = name
            cc.verbose = False
            cc.export("solve_pass", _SIGNATURE)(take_kernel_jit.solve_pass.py_func)
            cc.export("parse_vertex_lines", _PARSE_SIGNATURE)(decimal_kernel_jit.parse_vertex_lines.py_func)
            cc.export("shape_maps", _MAPS_SIGNATURE)(shape_kernels_jit.shape_maps.py_func)
            cc.export("shape_maps4", _MAPS4_SIGNATURE)(shape_kernels_jit.shape_maps4.py_func)
            cc.export("antagonist_sums", _PAIRS_SIGNATURE)(shape_kernels_jit.antagonist_sums.py_func)
            cc.export("box_qp_fresh", _QP_SIGNATURE)(take_kernel_jit.box_qp_fresh.py_func)
            cc.export("vertex_normals32", _NORMALS_SIGNATURE)(shape_kernels_jit.vertex_normals32.py_func)
            cc.export("draw_mesh", _RASTER_SIGNATURE)(raster_kernel_jit.draw_mesh.py_func)
            with _wrappers_release_gil():
                cc.compile()
        os.replace(Path(tmp) / name, folder / name)   # atomic: a concurrent build wins or loses whole


class _wrappers_release_gil:
    """While open, numba.pycc compiles its exported functions' Python wrappers with the GIL released around the
    call, as ``njit(nogil=True)`` does for the just-in-time ones: pycc has no option for it, but it builds each
    function with ``numba.core.compiler.Flags()`` and the wrapper follows their ``release_gil``. The functions take
    arrays and numbers only and touch no Python object, so they may run without it."""

    def __enter__(self):
        from numba.pycc import compiler

        class ReleasingFlags(compiler.Flags):
            def __init__(self, *args, **kwargs):
                super().__init__(*args, **kwargs)
                self.release_gil = True
        self._module, self._flags = compiler, compiler.Flags
        compiler.Flags = ReleasingFlags
        return self

    def __exit__(self, *exc) -> None:
        self._module.Flags = self._flags


def _jit():
    from . import take_kernel_jit
    return take_kernel_jit if take_kernel_jit.available() else None
