"""Imported by the local cluster's fork server before it forks the batch's workers
(``model.fork_server.start_fork_server``, named by ``app.batch_preload.BATCH_PRELOAD`` as the job's ``preload``): what
a take's preview needs besides the solve, loaded once for every worker instead of in each worker's first take: the
compiled kernel (the take solver's, which also draws the previews: ``solvers.raster``), the preview's modules, and
Pillow's PNG writer with the plugins it loads on its first save; BLAS is limited to one thread here, for every worker.

No OpenGL and no VTK: a preview is drawn on the CPU (``app.cli_batch.preview_image``), so a worker needs no display,
no EGL and no context of its own, and has nothing to ready before its first take.
"""
from __future__ import annotations

import PIL.Image
import PIL.PngImagePlugin  # noqa: F401

import solvers.raster  # noqa: F401
import widgets.scene  # noqa: F401
from solvers import take_kernel

take_kernel.kernel()   # built here if it is not yet (the workers then wait for no build of their own)

PIL.Image.preinit()    # the plugins Pillow loads on its first save (BMP, GIF, JPEG, PPM): ~10 ms of a first take

from model.batch import _limit_blas_once  # noqa: E402

_limit_blas_once()     # inherited by every worker (~15 ms of each one's start: threadpoolctl reads the libraries)
