"""A local cluster's batch run from a process forked from the fork server (the "driver"), so that the process that
asked for it (the ``batch`` command, the GUI) never imports Dask.

Why: the local cluster is driven by a Dask client and its nannies, which need ``distributed`` imported; in the
``batch`` command that import alone took ~0.3-0.4 s of its one core before the cluster could start (issue 21: on 2
workers that was a tenth of a 24-take run, and the run's speed-up on 2 cores against 1 stays below 1.7x with it).
The fork server (``model.fork_server``) imported it long before, on the other core, while the command loaded the rig;
a process forked from it starts in a few milliseconds with Dask ready.

How (``solve_in_driver``, called by ``model.batch.run_batch``):
- the driver is started with the 'forkserver' method; it adopts that fork server (``adopt_fork_server``), so the
  scheduler and the workers it starts are forked from it too, and starts the cluster at once
  (``model.batch.solve_on_cluster``, the same code as in-process);
- meanwhile this process writes the job (rig, settings, marker map; ~40 MB for ICT) into an anonymous in-memory
  file (``memfd``) with pickle protocol 5 (numpy arrays written straight from their memory) and hands the driver the
  file's descriptor over their socket pair; the driver reads it on a thread while its cluster starts. Sent through
  the pipe itself, the job took ~0.18 s; this way ~0.05 s, and behind the cluster's start;
- the driver sends each take's ``BatchProgress`` and at the end the ``ClusterOutcome``; this process relays the
  progress, and says 'cancelled' (the caller's ``cancel()``) or 'interrupted' (Ctrl-C here: the driver, like the
  fork server's other children, never sees SIGINT) to the driver, which stops as the in-process run does;
- the summary is written here, by ``run_batch``, as for an in-process run. If the driver ends without its outcome
  (killed), the takes it had not reported are found complete on disk or failed as 'stopped unexpectedly'; the
  scheduler and the workers end with it (their pipes to it close).

Only for a local cluster on a fork server whose children can adopt it (Linux, Python 3.8-3.13: ``available``);
elsewhere, and for a scheduler's address, ``run_batch`` runs the cluster in-process.
"""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from typing import Callable

PROCESS_NAME = "dask-batch"         # the driver's name in ``ps``/``top`` (Linux), beside the scheduler and workers
JOB_FILE = "blendshape-studio-batch-job"     # the job's in-memory file, as /proc/<pid>/fd shows it
_POLL = 0.1                          # seconds between looks at the caller's ``cancel()`` while the driver works


@dataclass
class ClusterOutcome:
    """What the cluster did with a run's pending takes (``solve_on_cluster``): their rows by index in the run's takes
    (a take the run stopped before is missing), the frames solved, the seconds from the submits to the last result,
    the dashboard's link, and why it stopped early: None, 'cancelled' or 'interrupted' (Ctrl-C)."""

    rows: dict = field(default_factory=dict)
    frames: int = 0
    seconds: float = 0.0
    dashboard: str | None = None
    stopped: str | None = None


def available(preload: tuple = ()) -> bool:
    """Whether a local cluster can be run from a driver: a fork server runs (started here with ``preload`` if not
    yet) and its children can adopt it, and anonymous in-memory files exist (Linux)."""
    from .fork_server import can_adopt_fork_server, start_fork_server
    return hasattr(os, "memfd_create") and can_adopt_fork_server() and start_fork_server(preload)


def solve_in_driver(job, tasks: list, *, solve: Callable, progress: Callable | None = None,
                    cancel: Callable[[], bool] | None = None, **options) -> ClusterOutcome:
    """``solve(lambda: job, tasks, progress=..., stop=..., **options)`` (``model.batch.solve_on_cluster``, passed in:
    this module is below ``model.batch``) run by a driver process forked from the fork server;
    ``progress`` is called here for each of its reports, ``cancel()`` after each and every ``_POLL`` seconds. Returns
    the ``ClusterOutcome``; raises what the driver raised (e.g. the scheduler could not start), KeyboardInterrupt
    after the driver has stopped on a Ctrl-C that came before the cluster's start."""
    import multiprocessing
    from multiprocessing.reduction import send_handle

    from . import shared_pickle
    from .fork_server import fork_server_address
    ctx = multiprocessing.get_context("forkserver")
    ours, theirs = ctx.Pipe(duplex=True)        # a socket pair: it can carry a descriptor
    process = ctx.Process(target=_drive, args=(theirs, fork_server_address(), solve, tasks, options),
                          name=PROCESS_NAME, daemon=False)   # not daemonic: it starts the cluster's processes
    outcome, said = None, None

    def tell(what: str) -> None:
        nonlocal said
        if said is None:
            said = what
            try:
                ours.send(("stop", what))
            except OSError:
                pass

    try:
        process.start()
        theirs.close()
        handle = shared_pickle.handle_of(job)
        if handle is not None and handle.pid == os.getpid():    # mapped from this process's file already (share_job)
            send_handle(ours, handle.fd, process.pid)
        else:
            fd = shared_pickle.memory_file(job, JOB_FILE)
            try:
                send_handle(ours, fd, process.pid)
            finally:
                os.close(fd)
        error = None
        while outcome is None and error is None:
            try:
                try:
                    # asked after every report too: while takes end more often than every _POLL seconds, a wait
                    # for the next report never times out
                    if cancel is not None and said is None and cancel():
                        tell("cancelled")
                    if not ours.poll(_POLL):
                        continue
                    kind, value = ours.recv()
                except (EOFError, OSError):         # the driver is gone without its outcome (killed)
                    outcome = ClusterOutcome(stopped="stopped unexpectedly (the batch's driver process ended)")
                    break
                if kind == "progress":
                    if progress is not None:
                        progress(value)
                elif kind == "outcome":
                    outcome = value
                elif kind == "error":
                    error = value
            except KeyboardInterrupt:               # the driver stops in order and says what it did
                tell("interrupted")
        if error is not None:
            raise error
    except KeyboardInterrupt:                       # before the driver had the job: it cannot stop in order
        if process.pid is not None:
            process.kill()
        raise
    finally:
        ours.close()
        if process.pid is not None:
            process.join(10.0)
            if process.exitcode is None:
                process.kill()
                process.join()
    if outcome.stopped is None and said == "interrupted":
        outcome.stopped = "interrupted"            # the Ctrl-C came after the last take: still said
    return outcome


def _drive(conn, address: str, solve: Callable, tasks: list, options: dict) -> None:
    """The driver process: adopt the fork server at ``address``, start the cluster while the job arrives on
    ``conn``, solve ``tasks`` on it with ``solve`` and send the outcome (or the error that stopped it)."""
    import _thread

    from . import shared_pickle
    from .fork_server import adopt_fork_server, name_process
    name_process(PROCESS_NAME)
    adopt_fork_server(address)
    said: list[str] = []
    arrived: dict = {}
    ready, ending, ended = threading.Event(), threading.Lock(), []

    def listen() -> None:
        """The job first, then the caller's stop messages; a Ctrl-C (or the caller gone) interrupts the main thread
        as a Ctrl-C interrupts an in-process run, until the main thread has its outcome."""
        from multiprocessing.reduction import recv_handle
        try:
            fd = recv_handle(conn)
            if shared_pickle.reachable(fd):     # kept open while this process lives: the workers map it
                arrived["job"] = shared_pickle.SharedObject(os.getpid(), fd)
            else:
                try:
                    arrived["job"] = shared_pickle.load(fd)
                finally:
                    os.close(fd)
        except BaseException as exc:     # noqa: BLE001  (handed to the main thread, which raises it)
            arrived["error"] = exc
        finally:
            ready.set()
        while True:
            try:
                _, what = conn.recv()
            except (EOFError, OSError):
                what = "interrupted"
            said.append(what)
            if what == "interrupted":
                with ending:
                    if not ended:
                        _thread.interrupt_main()
                return

    def job():
        ready.wait()
        if "error" in arrived:
            raise arrived["error"]
        return arrived["job"]

    def progress(p) -> None:
        conn.send(("progress", p))

    threading.Thread(target=listen, name="batch-job", daemon=True).start()
    outcome = None
    try:
        try:
            outcome = solve(job, tasks, progress=progress, stop=lambda: said[0] if said else None, **options)
        except KeyboardInterrupt:       # before the takes were submitted, or while the cluster closed
            outcome = ClusterOutcome(stopped="interrupted")
        with ending:                    # no interruption after this
            ended.append(True)
    except KeyboardInterrupt:           # one that came between the two
        with ending:
            ended.append(True)
        outcome = outcome or ClusterOutcome(stopped="interrupted")
    except BaseException as exc:     # noqa: BLE001  (the caller raises it: one sentence where it is RigInputError)
        with ending:
            ended.append(True)
        try:
            conn.send(("error", exc))
        except Exception:            # not picklable: its text
            conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))
        return
    try:
        conn.send(("outcome", outcome))
    except OSError:
        pass
