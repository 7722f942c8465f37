"""Imported by the local cluster's fork server before it forks the batch's workers (``model.batch.start_fork_server``,
named by ``app.cli_batch.PRELOAD`` as the job's ``preload``): what a take's preview needs, loaded once for every
worker instead of in each worker's first take. VTK and pyvista, with the render window backend the preview uses
(EGL without a display: ``widgets.scene.use_offscreen_backend_if_headless``, as ``render_png`` sets it), the VTK
modules pyvista loads with its first plotter, the graph search of the preview's hidden faces
(``solvers.mesh.hidden_back_faces``), and the compiled solve kernel. Nothing is rendered here: an OpenGL context
must not be shared across a fork.

``ALLOW_PLOTTING``: pyvista's first plotter in a process otherwise checks whether the system can plot at all (it
runs ``xset`` or opens an OpenGL window to ask, ~0.07 s in every worker's first take) only to warn; the previews
render off screen, and one that cannot be drawn costs its take the picture only (``model.batch.solve_take_file``).
"""
from __future__ import annotations

import os

from widgets.scene import use_offscreen_backend_if_headless

use_offscreen_backend_if_headless()
os.environ.setdefault("ALLOW_PLOTTING", "true")

import pyvista  # noqa: E402,F401  (its plotting layer and VTK's OpenGL rendering below load with the first plotter)
import pyvista.plotting  # noqa: E402,F401
import scipy.sparse.csgraph  # noqa: E402,F401
import vtkmodules.vtkInteractionWidgets  # noqa: E402,F401
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402,F401
import vtkmodules.vtkViewsContext2D  # noqa: E402,F401

from solvers import take_kernel  # noqa: E402

take_kernel.kernel()
