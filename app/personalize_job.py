"""Personalisation in a child process, so that the window can cancel it (the solver has no cancel of its own; a
process can be stopped, a thread cannot) and never waits for it when it closes.

Qt-free: the child imports only this module and the model. ``start(template, state, request)`` spawns the process
and returns a ``PersonalizeJob``; the child runs ``app.personalize_controller.personalize_project`` (which writes the
project atomically, so a cancelled job leaves the previous file, or none) and sends back ``("stage", phrase)`` for
each stage it reaches (the actor's neutral, shape k/K of the solve, ...: ``stage`` after ``poll``), then one
message: ``("done", (path, summary, rows))`` or ``("failed", message)``.
"""
from __future__ import annotations

import multiprocessing as mp
import threading
import traceback


def _run(conn, template, state: dict, request: dict) -> None:
    from model.errors import RigInputError

    def progress(stage: str) -> None:
        try:
            conn.send(("stage", stage))
        except OSError:       # the window stopped listening (it cancels the job next)
            pass
    try:
        from model.actor_project import personalize_project
        result = personalize_project(template, state, request, progress=progress)
    except RigInputError as exc:
        conn.send(("failed", str(exc)))
    except MemoryError:
        conn.send(("failed", "Personalising ran out of memory."))
    except Exception as exc:       # reported to the user as one sentence; the traceback goes to stderr
        traceback.print_exc()
        conn.send(("failed", f"{type(exc).__name__}: {exc}"))
    else:
        conn.send(("done", (str(result[0]), result[1], result[2])))
    finally:
        conn.close()


class PersonalizeJob:
    """One personalisation running in a child process: ``poll()`` its result, ``cancel()`` it."""

    def __init__(self, template, state: dict, request: dict) -> None:
        ctx = mp.get_context("spawn")   # a fresh interpreter: nothing of the GUI (threads, Qt, OpenGL) is copied
        self._conn, child = ctx.Pipe(duplex=False)
        self.process = ctx.Process(target=_run, args=(child, template, state, request), daemon=True,
                                   name="blendshape-studio personalize")
        self.result: tuple | None = None
        self.stage = ""                 # the last stage the child reported
        self._start_error: OSError | None = None
        # Started on a thread of its own: ``start`` pickles the rig (tens of MB on ICT FaceKit) into a pipe the new
        # interpreter reads only once it is up, which held the window 0.3-0.45 s when the job was started from it
        self._starter = threading.Thread(target=self._start, args=(child,), daemon=True,
                                         name="blendshape-studio personalize start")
        self._starter.start()

    def _start(self, child) -> None:
        try:
            self.process.start()
        except OSError as exc:
            self._start_error = exc
        finally:
            child.close()

    def poll(self) -> tuple | None:
        """("done", result) or ("failed", message) once the child has finished, else None."""
        if self.result is not None:
            return self.result
        if self._starter.is_alive():
            return None
        if self._start_error is not None:
            exc = self._start_error
            self.result = ("failed", f"The personalisation could not start ({exc.strerror or exc}).")
            self._conn.close()
            return self.result
        try:
            self._read()
        except (EOFError, OSError):
            self.result = ("failed", f"The personalisation stopped unexpectedly (exit code {self.process.exitcode}).")
        if self.result is None and not self.process.is_alive():
            try:
                self._read()
            except (EOFError, OSError):
                pass
            if self.result is None:
                self.result = ("failed", f"The personalisation stopped unexpectedly (exit code "
                                         f"{self.process.exitcode}).")
        if self.result is not None:
            self.process.join(5)
        return self.result

    def _read(self) -> None:
        """The child's messages waiting in the pipe: its stages (the last kept as ``stage``), then its result."""
        while self.result is None and self._conn.poll():
            message = self._conn.recv()
            if message[0] == "stage":
                self.stage = str(message[1])
            else:
                self.result = message

    @property
    def running(self) -> bool:
        return self.result is None and (self._starter.is_alive() or self.process.is_alive())

    def cancel(self) -> None:
        """Stop the child now (nothing is written: the project is saved atomically at the very end)."""
        self._starter.join()            # a child being started is stopped once it is
        if self._start_error is None:
            if self.process.is_alive():
                self.process.terminate()
            self.process.join(10)
            if self.process.is_alive():
                self.process.kill()
                self.process.join(5)
        self._conn.close()
        if self.result is None:
            self.result = ("cancelled", None)
