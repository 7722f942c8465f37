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
from app.crash import log_unexpected_rows
from app.cli_common import check_not_an_input, print_warnings
from app.cli_solve import add_solve_options, announce_solver_build, check_solve_options, load_solve_rig, solve_settings
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
    sp.set_defaults(func=cmd_batch, output_folders=(("output", "-o"),))


class PreviewMesh:
    """What a preview draws of a surface, found once for every take of a rig: its triangles (``fan_triangulate``,
    as VTK splits polygons), which of them may show their back (``hidden_back_faces``: from the job's view when
    it has them, ``model.rig_prep.DefaultView``, else searched on the first pose as ``render_png`` does) and its
    display normals."""

    def __init__(self, face_counts, face_indices, points, view=None) -> None:
        import numpy as np
        self.face_counts, self.face_indices = np.array(face_counts), np.array(face_indices)
        self.n_points = len(points)
        if view is not None and len(view.hidden_backs) == len(self.face_counts) \
                and view.normals.n_points == self.n_points:
            hidden, self.normals = view.hidden_backs, view.normals
        else:
            from solvers.mesh import hidden_back_faces
            from solvers.normals import VertexNormals
            hidden = hidden_back_faces(points, self.face_counts, self.face_indices)
            self.normals = VertexNormals(self.face_counts, self.face_indices, self.n_points)
        self.triangles = np.ascontiguousarray(self.normals.tris, dtype=np.int64)
        self.both_sides = (~np.repeat(np.asarray(hidden, dtype=bool), np.maximum(self.face_counts - 2, 0))
                           ).astype(np.uint8)

    def matches(self, face_counts, face_indices, n_points: int) -> bool:
        import numpy as np
        return (n_points == self.n_points and np.array_equal(face_counts, self.face_counts)
                and np.array_equal(face_indices, self.face_indices))


_preview_mesh: PreviewMesh | None = None     # the last preview's faces: a worker draws every take of a rig with it


def preview_image(points, face_counts, face_indices, *, focus=None, view=None, size=None):
    """``widgets.scene.render_png``'s picture from the front (the skin colour, the two lights, the gradient
    behind, no colour map), (h, w, 3) uint8, drawn on the CPU (``solvers.raster.draw``: no OpenGL, no VTK) at
    ``size`` (default ``model.batch.PREVIEW_SIZE``). ``view``: the faces' hidden back sides and display normals
    found beforehand (``model.rig_prep.DefaultView``: a batch's job carries them); the faces' triangles are kept
    for the next picture of the same faces."""
    import numpy as np

    from model.batch import PREVIEW_SIZE
    from solvers import raster
    from widgets import scene
    global _preview_mesh
    size = tuple(int(v) for v in (size or PREVIEW_SIZE))
    points = np.asarray(points, dtype=np.float32)
    if _preview_mesh is None or not _preview_mesh.matches(face_counts, face_indices, len(points)):
        _preview_mesh = PreviewMesh(face_counts, face_indices, points, view)
    mesh = _preview_mesh

    def rgb(color):            # as pyvista passes a colour to VTK: 8 bits a channel
        return np.array([round(255 * float(c)) / 255 for c in color])

    skin = rgb(scene.SKIN)
    key = -np.asarray(scene.KEY_LIGHT_POSITION, dtype=np.float64)    # a camera light towards the focal point
    return raster.draw(points, mesh.normals(points), mesh.triangles, mesh.both_sides, size=size,
                       camera=scene.camera_placement("front", points if focus is None else focus, size),
                       view_angle=30.0, lights=[(key, scene.KEY_LIGHT_INTENSITY),
                                                ((0.0, 0.0, -1.0), scene.FILL_LIGHT_INTENSITY)],   # the headlight
                       ambient=scene.AMBIENT * skin, diffuse=scene.DIFFUSE * skin,
                       specular=scene.SURFACE_SPECULAR * skin, specular_power=scene.SPECULAR_POWER,
                       background_bottom=rgb(scene.BACKGROUND_BOTTOM), background_top=rgb(scene.BACKGROUND_TOP))


def preview_png(points, face_counts, face_indices, *, focus=None, view=None) -> bytes:
    """A take's preview as a PNG file's bytes: ``preview_image`` at ``model.batch.PREVIEW_SIZE``, PNG compression
    level 1 (a 480x360 preview encodes in ~10 ms instead of ~41 and weighs ~150 KB instead of ~125)."""
    import io

    import numpy as np
    from PIL import Image
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(preview_image(points, face_counts, face_indices, focus=focus, view=view))
                    ).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


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
    from model.batch import (batch_files, counts_text, find_takes, run_batch, share_job, start_fork_server,
                             status_counts, take_names)

    if args.workers is not None and args.workers < 1:
        raise RigInputError(f"--workers: {args.workers} workers is fewer than one.")
    check_solve_options(args)
    notes: list[str] = []
    takes = find_takes(args.takes, exclude=args.output, notes=notes)
    names = take_names(takes)
    for path in batch_files(args.output, names, args.cache):   # none of them over the rig, a take given or the map
        check_not_an_input(args, path, "-o", "give -o another folder")
    print_warnings(notes)       # a batch's own output named as a take: left out, and said so
    if not args.scheduler:
        start_fork_server(BATCH_PRELOAD)   # running already when the command came through app.launch (a no-op then)
    rig = load_solve_rig(args)
    job = prepare_job(rig, args)
    if not args.scheduler:      # the local workers map the job's file: this process keeps no copy of its own beside it
        job = share_job(job)
    del rig
    print(f"{len(takes)} take(s) onto {job.rig.name} into {args.output}", flush=True)
    if not args.scheduler:
        announce_solver_build()      # the local workers' fork server compiles it before the first take
    rows = run_batch(job, takes, args.output, names=names, force=args.force, workers=args.workers,
                     scheduler=args.scheduler, progress=ProgressPrinter())
    log_unexpected_rows(rows, "solving the take")
    print(f"{counts_text(rows)}; wrote {args.output}/batch.json and batch.csv")
    for r in rows:                # what the readers decided for the takes solved now (also in batch.json, per take)
        if r["status"] == "solved":
            print_warnings(r.get("warnings"))
    if status_counts(rows)["failed"]:
        for r in rows:
            if r["status"] == "failed":
                print(f"error: {r['error']}", file=sys.stderr)
        return 2
    return 0
