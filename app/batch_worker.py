"""Imported by the local cluster's fork server before it forks the batch's workers
(``model.fork_server.start_fork_server``, named by ``app.batch_preload.BATCH_PRELOAD`` as the job's ``preload``): what
a take's preview needs, loaded once for every worker instead of in each worker's first take. The VTK modules of
``widgets.snapshots.SurfaceSnapshots`` (VTK alone: not pyvista, whose import with the matplotlib it loads cost the
fork server ~0.7 s of CPU), with the render window backend the preview uses (EGL: ``prefer_egl``), Pillow's PNG
writer and the plugins it loads on its first save, the compiled solve kernel, and the libraries of the OpenGL driver
that will draw the previews (``load_gl_driver``); BLAS is limited to one thread here, for every worker. Not the graph
search of the preview's hidden back sides (``scipy.sparse.csgraph``, ~12 ms here): the job brings them found
(``model.batch.BatchJob.preview_view``). Nothing is rendered here: an OpenGL context must not be shared across a
fork.
"""
from __future__ import annotations

import ctypes.util
import os

from widgets.scene import use_offscreen_backend_if_headless

_WINDOW = "VTK_DEFAULT_OPENGL_WINDOW"
_EGL = "vtkEGLRenderWindow"
egl_over_display = False          # True: EGL chosen here although the workers have an X display (``leave_egl``)


def prefer_egl() -> bool:
    """Let the workers draw their previews through EGL, inside their own process, also where there is an X display
    (which ``render_png`` would otherwise use). Through the display every preview's OpenGL window and context are
    made, drawn and read back by round trips to the X server: CPU spent in another process (the server's, ~10-20 ms
    a preview under Xvfb) and waits on it, taken from the takes when the workers fill the cores; a batch's workers
    also have no business with the user's display (over ``ssh -X`` every preview would cross the network). Both
    draw the same pixels through Mesa (compared on ICT: identical). Kept when the user chose a window class
    (``VTK_DEFAULT_OPENGL_WINDOW``) or when there is no libEGL; without a display ``render_png`` uses EGL anyway.
    True when EGL was chosen over a display."""
    global egl_over_display
    has_display = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if not has_display or os.environ.get(_WINDOW) or ctypes.util.find_library("EGL") is None:
        return False
    os.environ[_WINDOW] = _EGL
    egl_over_display = True
    return True


def leave_egl() -> bool:
    """After a preview failed through EGL chosen by ``prefer_egl``: this worker's later previews use the display's
    own window again. True when that changed anything (the failed preview is then worth one more try)."""
    global egl_over_display
    if not egl_over_display:
        return False
    egl_over_display = False
    if os.environ.get(_WINDOW) == _EGL:
        del os.environ[_WINDOW]
    return True


def load_gl_driver() -> list[str]:
    """Load (``dlopen``) the libraries of the OpenGL driver a worker's preview window will use, without making a
    display or a context: EGL (glvnd's libEGL), Mesa's EGL and its software rasteriser (``swrast_dri.so``, which
    brings LLVM, ~110 MB). A worker forked from here then finds them loaded and relocated when it makes its window
    (~15 ms of its start on the 2-core development machine, before its first take). Where a library is not found
    nothing is loaded for it (another driver, or no EGL: the worker loads what it uses itself). Returns the paths
    loaded."""
    import ctypes
    loaded = []

    def load(path: str) -> bool:
        try:
            ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
        except OSError:
            return False
        loaded.append(path)
        return True

    if not load("libEGL.so.1") or not load("libEGL_mesa.so.0"):     # glvnd's and Mesa's sonames
        return loaded
    with open("/proc/self/maps") as maps:       # where Mesa is: its drivers are in dri/ beside it
        mesa = next((line.split()[-1] for line in maps if "libEGL_mesa" in line), None)
    dirs = [d for d in os.environ.get("LIBGL_DRIVERS_PATH", "").split(os.pathsep) if d]
    if mesa is not None:
        dirs.append(os.path.join(os.path.dirname(mesa), "dri"))
    for d in dirs:
        driver = os.path.join(d, "swrast_dri.so")
        if os.path.isfile(driver) and load(driver):
            break
    return loaded


prefer_egl()
use_offscreen_backend_if_headless()
if os.environ.get(_WINDOW) == _EGL:      # the previews draw through EGL (chosen over a display, or no display)
    load_gl_driver()

import PIL.Image  # noqa: E402
import PIL.PngImagePlugin  # noqa: E402,F401
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402,F401

import widgets.snapshots  # noqa: E402,F401
from solvers import take_kernel  # noqa: E402

take_kernel.kernel()

PIL.Image.preinit()    # the plugins Pillow loads on its first save (BMP, GIF, JPEG, PPM): ~10 ms of a first take

from model.batch import _limit_blas_once  # noqa: E402

_limit_blas_once()     # inherited by every worker (~15 ms of each one's start: threadpoolctl reads the libraries)


def warm_up() -> None:
    """What a worker's first take would otherwise do first, done while the worker waits for it: the preview's
    window with its shaders compiled (``app.cli_batch.warm_up_preview``, ~0.1 s; one BLAS thread was set when this
    module was imported). Never fails: a worker that cannot draw finds out in its first preview, as before."""
    try:
        from app.cli_batch import warm_up_preview
        warm_up_preview()
    except Exception:
        pass


def dask_setup(worker) -> None:
    """Dask's hook for a worker's preload modules (the local cluster's workers preload the job's ``preload``,
    ``model.batch.start_client``), run when the worker has started: ``warm_up`` goes to the worker's task thread
    (one thread: the takes queue behind it), so that the preview's OpenGL context is made on the thread that
    draws every preview, and runs there while the scheduler, the client and the job's scatter get ready (~0.2 s
    on the 2-core development machine)."""
    worker.executors["default"].submit(warm_up)
