"""Imported by the local cluster's fork server before it forks the batch's workers (``model.batch.start_client``,
named by ``app.cli_batch.prepare_job`` as the job's ``preload``): what a take's preview needs, loaded once for
every worker instead of in each worker's first take. VTK and pyvista, with the render window backend the preview
uses (EGL without a display: ``widgets.scene.use_offscreen_backend_if_headless``, as ``render_png`` sets it), and
the compiled solve kernel. Nothing is rendered here: an OpenGL context must not be shared across a fork.
"""
from __future__ import annotations

from widgets.scene import use_offscreen_backend_if_headless

use_offscreen_backend_if_headless()

import pyvista  # noqa: E402,F401  (its plotting layer and VTK's OpenGL rendering below load with the first plotter)
import pyvista.plotting  # noqa: E402,F401
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402,F401

from solvers import take_kernel  # noqa: E402

take_kernel.kernel()
