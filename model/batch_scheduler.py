"""A local cluster's Dask scheduler in a process of its own, forked from the batch's fork server.

Why: the scheduler is up in a few milliseconds when it is forked from a process that has imported Dask
(``model.fork_server``), where the ``batch`` command would otherwise import it, and start it, on its own core after
it has loaded the rig. Used by ``model.batch.start_client`` where the fork server runs; elsewhere (no fork server)
the scheduler runs in the command's process as Dask's ``LocalCluster`` runs it.

Its dashboard is built when it is first opened (``serve_dashboard_on_demand``): Dask's dashboard imports bokeh
(~0.6 s of CPU on the 2-core development machine), which the fork server imported before any worker could be
forked from it; a batch on 2 workers waited that long for its first take (issue 21). The link is the same, and the
page answers once built.

``ForkedScheduler`` is a ``distributed.deploy.spec.ProcessInterface`` (Dask's interface for a cluster's scheduler or
worker started some other way: ``SSHCluster`` uses it), so ``distributed.SpecCluster`` starts, watches and closes it
as its own. The scheduler process never outlives the command: it closes when the command's end of its pipe closes,
however the command ended (and ends ``CLOSE_GRACE`` seconds later if its close has not), and leaves Ctrl-C to the
command.
"""
from __future__ import annotations

import asyncio
import logging
import os

from distributed.deploy.spec import ProcessInterface

from .fork_server import name_process


PROCESS_NAME = "dask-scheduler"     # the scheduler process's name in ``ps``/``top`` (Linux), beside the workers'
CLOSE_GRACE = 5.0                   # seconds the scheduler process has to close once the command has gone


def _serve(conn, options: dict, config: dict, log_level: int) -> None:
    """The scheduler process: a Dask ``Scheduler`` with ``options``, under ``config`` (the command's Dask
    configuration); sends its (address, None) on ``conn`` once it listens, or (None, error text), then runs until
    it is told to close or ``conn``'s other end closes (the command ended)."""
    import signal

    import dask
    from distributed import Scheduler
    from distributed.utils import silence_logging_cmgr
    signal.signal(signal.SIGINT, signal.SIG_IGN)        # Ctrl-C is the command's: it closes the cluster
    name_process(PROCESS_NAME)
    dask.config.update(dask.config.config, config, priority="new")

    import importlib.util
    on_demand = bool(options.get("dashboard")) and importlib.util.find_spec("bokeh") is not None
    if on_demand:            # its HTTP server still listens on the dashboard's address: only the pages wait
        options = {**options, "dashboard": False}

    async def main() -> None:
        loop = asyncio.get_running_loop()
        try:
            scheduler = await Scheduler(**options)
        except Exception as exc:                        # e.g. the dashboard's port is taken and cannot move
            conn.send((None, f"{type(exc).__name__}: {exc}"))
            return
        if on_demand:
            serve_dashboard_on_demand(scheduler, options.get("http_prefix") or "/")
        conn.send((scheduler.address, None))
        closing = []

        def command_gone() -> None:                     # EOF on the pipe: the command has ended
            loop.remove_reader(conn.fileno())
            closing.append(asyncio.ensure_future(scheduler.close()))
            # nobody is left to wait for a graceful close: should it hang (once, after a driver was killed in the
            # middle of a gather, it outlived the 30 s a test gives it), the process ends anyway
            loop.call_later(CLOSE_GRACE, os._exit, 0)

        loop.add_reader(conn.fileno(), command_gone)
        await scheduler.finished()

    with silence_logging_cmgr(level=log_level), silence_logging_cmgr(level=log_level, root="bokeh"):
        asyncio.run(main())


def serve_dashboard_on_demand(scheduler, prefix: str = "/") -> None:
    """Build ``scheduler``'s Dask dashboard on the first request for a page its HTTP server does not otherwise
    serve, then send the browser to the same address again, which the dashboard now answers (Dask's
    ``distributed.dashboard.scheduler.connect``, as ``Scheduler(dashboard=True)`` calls it at its start). The
    scheduler's own routes (health, metrics, the JSON API) answer from the start. ``scheduler`` was made with
    ``dashboard=False`` and a dashboard address, so that its HTTP server listens there."""
    from tornado import web

    server = scheduler.http_application

    class BuildDashboard(web.RequestHandler):
        def get(self, *_) -> None:
            if on_demand in server.applications:     # the first request: build it (two requests may both land here)
                server.applications.remove(on_demand)
                import distributed.dashboard.scheduler
                distributed.dashboard.scheduler.connect(server, scheduler.http_server, scheduler, prefix=prefix)
            self.redirect(self.request.uri)

        head = get

    on_demand = web.Application([(r".*", BuildDashboard)])
    server.add_application(on_demand)      # asked after the scheduler's own routes, as the dashboard would be


class ForkedScheduler(ProcessInterface):
    """``SpecCluster``'s scheduler, run in a process forked from this process's fork server (``_serve``).
    ``options``: ``distributed.Scheduler``'s keyword arguments (plain values: they are pickled to the process);
    ``log_level``: the level below which its log lines are dropped, as ``LocalCluster(silence_logs=...)``."""

    def __init__(self, log_level: int = logging.ERROR, **options) -> None:
        self.options, self.log_level = options, log_level
        self.process = self._conn = None
        super().__init__()

    async def start(self) -> None:
        import multiprocessing

        import dask
        from dask.utils import parse_timedelta
        ctx = multiprocessing.get_context("forkserver")
        ours, theirs = ctx.Pipe(duplex=True)
        self.process = ctx.Process(target=_serve, args=(theirs, self.options, dask.config.config, self.log_level),
                                   name="dask-scheduler", daemon=True)
        self.process.start()
        theirs.close()
        self._conn = ours
        loop = asyncio.get_running_loop()
        timeout = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), default="s")
        try:
            if await loop.run_in_executor(None, ours.poll, timeout):
                address, error = ours.recv()
            else:
                address, error = None, f"it did not answer within {timeout:g} s"
        except EOFError:
            address, error = None, f"the process ended (exit code {self.process.exitcode})"
        if address is None:
            await self.close()
            host = self.options.get("host")
            raise RuntimeError(f"The local cluster's scheduler did not start{f' on {host}' if host else ''}: {error}.")
        self.address = address
        await super().start()

    async def close(self) -> None:
        """After ``SpecCluster`` has told the scheduler to close: wait for its process to end (5 s), else end it."""
        if self.process is not None:
            loop = asyncio.get_running_loop()
            await loop.run_in_executor(None, self.process.join, 5.0)
            if self.process.exitcode is None:
                self.process.terminate()
                await loop.run_in_executor(None, self.process.join, 5.0)
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        await super().close()
