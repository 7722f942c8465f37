"""The ``batch`` command: every take of a capture day solved onto the rig with the same options as ``solve``, on a
Dask cluster (a local one by default, or ``--scheduler ADDRESS``); ``model.batch`` does the work.

Per take ``OUTDIR/<take>/`` holds ``weights.csv``, ``report.json``, ``preview.png`` (the most expressive frame),
``cache.pc2`` with ``--cache``, and ``done.json`` (written last: the take is complete). ``OUTDIR/batch.json`` and
``batch.csv`` summarise the run. Complete takes are skipped unless ``--force``. Exit 2 when a take failed (each
failure is one sentence on stderr and in the summary); the other takes are solved regardless.
"""
from __future__ import annotations

import sys

from app.batch_preload import BATCH_PRELOAD
from app.cli_solve import add_solve_options, announce_solver_build, load_solve_rig, solve_settings
from model.errors import RigInputError


def add_parser(sub, rig_arg) -> None:
    sp = sub.add_parser("batch", help="solve many takes with the same options as solve, on a Dask cluster")
    rig_arg(sp)
    sp.add_argument("takes", nargs="+", metavar="TAKES", help="take files (.c3d, .trc, .csv), folders of takes or "
                                                              "glob patterns ('day1/**/*.c3d')")
    add_solve_options(sp)
    sp.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                    help="folder: OUTDIR/<take>/ per take, OUTDIR/batch.json and batch.csv")
    sp.add_argument("--cache", action="store_true", help="also write each take's dense result as cache.pc2 (large)")
    where = sp.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="worker processes of the local cluster (default: the cores)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="a running Dask scheduler (tcp://host:8786) whose workers see the same paths")
    sp.add_argument("--force", action="store_true", help="solve again the takes whose outputs are complete")
    sp.set_defaults(func=cmd_batch)


_snapshots = None      # this process's widgets.snapshots.SurfaceSnapshots: a worker draws every take's preview with it


def preview_png(points, face_counts, face_indices, *, focus=None, view=None) -> bytes:
    """A take's preview as a PNG file's bytes: ``widgets.scene.render_png``'s picture from the front, drawn by one
    off-screen plotter kept in this process for every preview of the same surface (``SurfaceSnapshots``: ~0.06 s a
    preview on ICT instead of ~0.18 with a new plotter each time), PNG compression level 1 (a 480x360 preview
    encodes in 10 ms instead of 41 and weighs ~150 KB instead of ~125). On a local cluster's worker that chose EGL
    over an X display (``app.batch_worker.prefer_egl``), a preview that fails through EGL is drawn again through the
    display's window, which that worker keeps using. ``view``: the faces' hidden back sides and display normals
    found beforehand (``model.rig_prep.DefaultView``: a batch's job carries them), instead of on the first preview
    (~0.03 s on ICT)."""
    from model.batch import PREVIEW_SIZE
    from widgets.snapshots import SurfaceSnapshots

    def draw(keep: bool) -> bytes:
        global _snapshots
        if _snapshots is not None and not (keep and _snapshots.size == PREVIEW_SIZE and _snapshots.camera == "front"):
            _snapshots.close()
            _snapshots = None
        if _snapshots is not None and not _snapshots.matches(face_counts, face_indices, PREVIEW_SIZE, "front"):
            _snapshots.set_faces(face_counts, face_indices, view)   # another rig, or ``warm_up_preview``'s stand-in
        if _snapshots is None:
            _snapshots = SurfaceSnapshots(face_counts, face_indices, size=PREVIEW_SIZE, camera="front", view=view)
        return _snapshots.png(points, focus=focus, compress_level=1)

    try:
        return draw(keep=True)
    except Exception:
        worker = sys.modules.get("app.batch_worker")     # loaded by the local cluster's fork server only
        if worker is None or not worker.leave_egl():
            raise
        return draw(keep=False)     # the plotter made through EGL goes; the new one draws through the display


def warm_up_preview() -> None:
    """Make this process's preview window and compile its shaders by drawing a stand-in (an open square, so that
    both the culled front faces and the backs' actor are drawn, as on a face rig) at the preview's size: a batch
    worker does it while it waits for its first take (``app.batch_worker.dask_setup``), which then draws its
    preview into the same window (``SurfaceSnapshots.set_faces``) in ~0.02 s instead of ~0.14 s: llvmpipe
    compiles the shaders of a new OpenGL context in its first render. A stand-in that cannot be drawn leaves
    nothing behind: the first preview then tries as before."""
    global _snapshots
    import numpy as np

    from model.batch import PREVIEW_SIZE
    from model.rig_prep import view_of
    from widgets.snapshots import SurfaceSnapshots
    if _snapshots is not None:
        return
    square = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]], dtype=np.float32)
    counts, indices = np.array([3, 3]), np.array([0, 1, 2, 0, 2, 3])
    # a flat open square hides neither back side; said here, not searched for: that search's first call imports
    # scipy.sparse.csgraph (~45 ms, a third of a worker's warm-up), which the takes never need (the job's view)
    view = view_of(counts, indices, len(square), np.zeros(len(counts), dtype=bool))
    snapshots = SurfaceSnapshots(counts, indices, size=PREVIEW_SIZE, camera="front", view=view)
    try:
        snapshots.image(square)
    except Exception:
        snapshots.close()
        raise
    _snapshots = snapshots


def prepare_job(rig, args):
    """The ``model.batch.BatchJob`` of the solve options in ``args`` for ``rig`` (the command and the GUI)."""
    from model.batch import BatchJob, preview_focus
    from model.marker_map import load_marker_map
    settings, segmentation = solve_settings(args, rig)
    marker_map = load_marker_map(args.map) if args.map else None
    return BatchJob.prepare(rig, settings, segmentation=segmentation, marker_map=marker_map,
                            cache=bool(getattr(args, "cache", False)), preview=preview_png,
                            focus=preview_focus(rig), preload=BATCH_PRELOAD)


def _clock(seconds: float | None) -> str:
    if seconds is None:
        return "--:--"
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def progress_text(p) -> str:
    """'5/12 takes, 840 frames/s, ETA 0:42' of a ``model.batch.BatchProgress`` (the terminal and the GUI)."""
    return f"{p.done}/{p.total} takes, {p.frames_per_second:.0f} frames/s, ETA {_clock(p.eta)}"


class ProgressPrinter:
    """Takes done, frames/s and ETA: one redrawn line with a bar on a terminal, a plain line per take otherwise."""

    def __init__(self, stream=None, width: int = 28) -> None:
        self.stream = stream or sys.stdout
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.width = width
        self._shown_dashboard = False

    def __call__(self, p) -> None:
        out = self.stream
        if p.dashboard and not self._shown_dashboard:
            print(f"dashboard: {p.dashboard}", file=out, flush=True)
            self._shown_dashboard = True
        status = progress_text(p)
        if self.tty:
            filled = int(self.width * p.done / max(p.total, 1))
            out.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {status}\033[K")
            if p.done >= p.total:
                out.write("\n")
            out.flush()
        elif p.row is not None:
            r = p.row
            if r["status"] != "solved":
                what = r["error"]
            elif r["marker_rmse"] is None:
                what = f"{r['frames']} frames, a weight take played on the rig"
            else:
                what = f"{r['frames']} frames, marker RMSE {r['marker_rmse']:.4g}"
            print(f"[{p.done}/{p.total}] {r['take']}: {r['status']} ({what}); {status}", file=out, flush=True)


def cmd_batch(args) -> int:
    from model.batch import (counts_text, find_takes, run_batch, share_job, start_fork_server, status_counts,
                             take_names)

    if args.workers is not None and args.workers < 1:
        raise RigInputError(f"--workers: {args.workers} workers is fewer than one.")
    takes = find_takes(args.takes, exclude=args.output)
    if not args.scheduler:
        start_fork_server(BATCH_PRELOAD)   # running already when the command came through app.launch (a no-op then)
    rig = load_solve_rig(args)
    job = prepare_job(rig, args)
    if not args.scheduler:      # the local workers map the job's file: this process keeps no copy of its own beside it
        job = share_job(job)
    del rig
    names = take_names(takes)
    print(f"{len(takes)} take(s) onto {job.rig.name} into {args.output}", flush=True)
    if not args.scheduler:
        announce_solver_build()      # the local workers' fork server compiles it before the first take
    rows = run_batch(job, takes, args.output, names=names, force=args.force, workers=args.workers,
                     scheduler=args.scheduler, progress=ProgressPrinter())
    print(f"{counts_text(rows)}; wrote {args.output}/batch.json and batch.csv")
    if status_counts(rows)["failed"]:
        for r in rows:
            if r["status"] == "failed":
                print(f"error: {r['error']}", file=sys.stderr)
        return 2
    return 0
