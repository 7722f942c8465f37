"""A pyvista plotter living in a native child window of the Qt GUI: VTK renders straight into it.

Why not pyvistaqt's ``QtInteractor``: that one is a ``QOpenGLWidget``, and one ``QOpenGLWidget`` switches its
whole top-level window to OpenGL composition. Under software OpenGL (Xvfb + llvmpipe, this project's test
machine) every repaint of ANY widget in the main window -- a frame counter, a plot cursor, a slider -- then
costs ~25 ms on a 1400x1000 window (measured with py-spy: ``QPlatformBackingStore::rhiFlush``), on top of the
VTK render. With a native child window the rest of the GUI stays plain raster (~1 ms a repaint) and a VTK
render is one render + one swap: mocap playback went from ~5 to 30+ frames/s.

The class is pyvistaqt's recipe (Qt interactor widget + ``BasePlotter``) on VTK's own
``QVTKRenderWindowInteractor`` with its default ``QWidget`` base (``WA_PaintOnScreen``, a native window id
handed to a platform ``vtkRenderWindow``). It keeps the interface the widgets use: ``plotter.interactor`` is the
Qt widget, ``render()``, ``close()``, ``screenshot()``, subplots and linked views come from ``BasePlotter``.
"""
from __future__ import annotations

import contextlib
from typing import Callable

import vtkmodules.qt

vtkmodules.qt.QVTKRWIBase = "QWidget"  # read when the module below is first imported
from vtkmodules.qt.QVTKRenderWindowInteractor import QVTKRenderWindowInteractor  # noqa: E402

from pyvista.plotting import BasePlotter  # noqa: E402
from vtkmodules.vtkCommonCore import vtkTimeStamp  # noqa: E402
from pyvista.plotting.render_window_interactor import RenderWindowInteractor  # noqa: E402


_clock = vtkTimeStamp()


def vtk_clock() -> int:
    """VTK's modification clock, advanced by one: every ``Modified()`` of every VTK object in the process (a point,
    an actor, a camera, a window's size) advances the one counter this reads, so two readings one apart mean that
    nothing in VTK changed between them but the first reading itself."""
    _clock.Modified()
    return _clock.GetMTime()


@contextlib.contextmanager
def _no_base_plotter_init():
    """PySide continues the cooperative ``__init__`` chain past QWidget into BasePlotter with no arguments;
    suppress that call while the Qt part is built (BasePlotter is initialised explicitly afterwards)."""
    init = BasePlotter.__init__
    BasePlotter.__init__ = lambda *args, **kwargs: None
    try:
        yield
    finally:
        BasePlotter.__init__ = init


class NativePlotter(QVTKRenderWindowInteractor, BasePlotter):
    """A Qt widget that is also a pyvista plotter (``shape``/``border`` as for ``pyvista.Plotter``)."""

    def __init__(self, parent=None, *, multi_samples: int = 0, **kwargs) -> None:
        with _no_base_plotter_init():
            QVTKRenderWindowInteractor.__init__(self, parent)
        self._closed = True   # until BasePlotter is initialised (it sets False); close() sets it again
        # VTK's clock when the window last showed a whole render (None: its picture is not known to be current)
        self._shown_at: int | None = None
        self._shown_size: tuple | None = None    # the window's size at its last whole render
        # whether its owner will render it on the event loop's next turn (a coalesced redraw): set by the owner
        self.render_pending: Callable[[], bool] = lambda: False
        # called by resizeEvent once the render window has its new size, before the paint the resize brings: the owner
        # lays out there what depends on the size (a legend, a framing), and that one paint draws it
        self.resized: Callable[[], None] = lambda: None
        BasePlotter.__init__(self, **kwargs)
        self.interactor = self
        self.ren_win = self.GetRenderWindow()
        self.ren_win.SetMultiSamples(multi_samples)
        # Show a frame by blitting its colour alone into the window (VTK's default, BlitToHardware, also copies
        # its depth buffer there, through a shader: a full-window pass on software OpenGL, ~2.5 ms CPU a frame
        # under Xvfb). Nothing reads the window's depth: VTK reads depth, pixels and screenshots from its own
        # frame buffers. The picture on screen is the same, bit for bit.
        self.ren_win.SetFrameBlitModeToBlitToCurrent()
        for renderer in self.renderers:
            renderer.view_isometric()
            self.ren_win.AddRenderer(renderer)
        self._off_screen = False
        self.iren = RenderWindowInteractor(self, interactor=self.ren_win.GetInteractor())
        self.iren.interactor.RemoveObservers("MouseMoveEvent")
        self.iren.initialize()
        self.enable_trackball_style()
        self._observers = {}
        self.iren.add_observer("KeyPressEvent", self.key_press_event)
        self.reset_key_events()
        self._first_time = False  # lets BasePlotter render without show()
        self.ren_win.AddObserver("EndEvent", self._rendered_now)

    def _rendered_now(self, *_args) -> None:
        self._shown_at = vtk_clock()
        self._shown_size = tuple(self.ren_win.GetSize())

    def _unchanged(self) -> bool:
        """Whether nothing in VTK has changed since this window last showed a whole render (``vtk_clock``): no
        point, colour, camera, window size, and no other window's render. Anything did: False until the next
        render. Reading the clock moves it, so the mark moves with it."""
        now = vtk_clock()
        if self._shown_at is None or now != self._shown_at + 1:
            return False
        self._shown_at = now
        return True

    def _setEventInformation(self, *args, **kwargs) -> None:  # QVTKRenderWindowInteractor's, for every Qt event
        """Hand the pointer's position and keys to VTK's interactor, which that modifies: not a change of the
        picture (the pointer entering the viewport as a dialog closes over it, then the expose)."""
        current = self._unchanged()
        super()._setEventInformation(*args, **kwargs)
        if current:
            self._shown_at = vtk_clock()

    def render(self) -> None:
        """Render now into the window (no-op once closed or before the widget has a size), unless nothing has
        changed since its last render, which it shows: when an expose rendered a change first (a dialog closing
        over the viewport while its redraw was pending), the redraw does not draw the same picture again (0.07 s
        at 422k vertices)."""
        if self._closed:
            return
        self._rendered = True
        if not self._unchanged():
            BasePlotter.render(self)

    def paintEvent(self, event) -> None:  # Qt override: expose / resize
        """Show the last render again when nothing has changed since (``_unchanged``): a menu, tooltip or dialog
        closing over the viewport on an X server without a compositor exposes it, and the picture VTK keeps in its
        own frame buffer is blitted back (``Frame``: ~2 ms at any rig size) instead of rendered again (13-18 ms on
        ICT, 0.07-0.16 s at 422k vertices under llvmpipe). Anything changed -- a point, a colour, the camera, the
        window's size (``resizeEvent``) -- or another window rendered meanwhile: a whole render, unless the owner
        renders on the event loop's next turn anyway (``render_pending``) and the window's size is the same: the last
        picture is shown until then. A new rig is taken in by one turn and rendered by the next (0.1 s each at 422k
        vertices); the progress dialog closing over the viewport between them made both one freeze of the window."""
        if self._closed:
            return
        if self._unchanged():
            self.ren_win.Frame()
            # Frame itself touches one object (its frame buffers' state); anything more: render next time
            marked, now = self._shown_at, vtk_clock()
            self._shown_at = now if now == marked + 2 else None
        elif self._shown_size == tuple(self.ren_win.GetSize()) and self.render_pending():
            self.ren_win.Frame()
        else:
            self.ren_win.Render()

    def resizeEvent(self, event) -> None:  # Qt override
        if not self._closed:
            super().resizeEvent(event)
            self.resized()

    def close(self) -> None:  # both BasePlotter.close and QWidget.close; returns None like pyvistaqt's
        """Release the render window now, X display connection included: left to the garbage collector it
        may be destroyed after the X server is gone (the end of a test run), and Xlib then exits the process."""
        if self._closed:
            return
        BasePlotter.close(self)
        QVTKRenderWindowInteractor.close(self)
        self._Iren.SetRenderWindow(None)
        self._Iren = _ClosedInteractor()
        self._RenderWindow = None


class _ClosedInteractor:
    """Stands in for the VTK interactor after close: late Qt events (leave, focus) reach it and do nothing."""

    def __getattr__(self, name):
        return lambda *args, **kwargs: None
