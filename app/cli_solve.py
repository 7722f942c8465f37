"""The ``solve`` command: a marker take onto a rig (Joshi §3–4, Ma §3.1, Fidaleo RBF residual), or a weight take
(Live Link Face CSV, weights CSV) on it.

Writes per-frame weights (CSV), optionally the dense head-stabilised result as a PC2 cache, a JSON report
(``model.take_workspace.solve_report``; README, "Solve report") and the rig animated by the weights as glTF,
through the same ``TakeWorkspace`` as the GUI's Mocap panel. A weight take needs no solve: its weights, mapped
onto the rig's shapes as the GUI plays them, are written as the same files.
"""
from __future__ import annotations

import sys

from app.cli_common import (about, add_rate_option, check_rate, check_rig_options, check_threshold, load_rig_arg,
                             print_warnings)


def add_parser(sub, rig_arg) -> None:
    sp = sub.add_parser("solve", help="solve a marker take (C3D/TRC/CSV) onto the rig, or write a weight take "
                                      "(Live Link Face or weights CSV) as the same outputs")
    rig_arg(sp)
    sp.add_argument("take", metavar="TAKE", help="marker take (.c3d, .trc, marker .csv) or weight take (Live Link "
                                                 "Face .csv, weights .csv as solve writes)")
    add_solve_options(sp)
    sp.add_argument("-o", "--output", required=True, help="weights CSV to write")
    sp.add_argument("--cache", help="PC2 point cache of the dense result to write")
    sp.add_argument("--report", help="JSON report to write")
    sp.add_argument("--gltf", metavar="OUT.glb", help="the rig animated by the weights, as .glb or .gltf (metres, "
                                                      "correctives as extra targets)")
    sp.set_defaults(func=cmd_solve, output_files=(("output", "-o"), ("cache", "--cache"), ("report", "--report"),
                                                  ("gltf", "--gltf")))


def add_solve_options(sp) -> None:
    """The options of a solve, one parser for ``solve``, ``batch`` (app.cli_batch) and the GUI's Batch Solve
    dialog: an option means the same thing everywhere (``solve_settings`` reads them)."""
    sp.add_argument("--map", help="marker map JSON (default: map markers automatically from the calibration frames)")
    sp.add_argument("--rig-units", choices=["cm", "mm", "m"], help="units of the rig (default: the rig's own)")
    # as model.take_workspace.SOLVE_DEFAULTS says (tests/test_cli_solve.py holds the two together)
    sp.add_argument("--global", dest="global_solve", action="store_true",
                    help="one weight vector for the whole face (the default; --threshold or --level solve per region)")
    sp.add_argument("--threshold", type=float, default=None,
                    help="segmentation quantile t for the regions of a per-region solve (default 0.5)")
    sp.add_argument("--level", type=int, default=None,
                    help="hierarchy level whose regions are solved, one weight vector each (default 2)")
    sp.add_argument("--residual", choices=["none", "joshi", "gaussian", "multiquadric"], default=None,
                    help="RBF residual kernel added to the blendshape fit (default: the best measured)")
    sp.add_argument("--calibration-frames", type=int, default=30,
                    help="neutral frames at the start of the take that settle scale and pose (default 30; at most the "
                         "take's frames); 0: no calibration, the markers are taken as the rig's own face in rig "
                         "space (head motion is still solved; --fixed-head stops that too)")
    sp.add_argument("--neutral-frames", default=None, metavar="A:B|auto",
                    help="the actor's neutral: frames A to B (inclusive), or 'auto' for the most neutral stretch "
                         "(default: the first --calibration-frames)")
    sp.add_argument("--stable", default=None, metavar="M1,M2,...|PATTERN",
                    help="markers the head motion is taken from (names or patterns such as 'root-*'; head-band "
                         "markers need not be in the map; default: all markers)")
    add_rate_option(sp)
    sp.add_argument("--fixed-head", action="store_true",
                    help="the markers are already head-stabilised in rig space: no calibration, no head motion "
                         "(always so for a one-frame take)")


def load_solve_rig(args):
    """The RIG argument's rig, in --rig-units when given. A project's edited antagonist pairs (Edit ▸ Antagonist
    Pairs…) are kept as ``args.antagonists`` for the solve (None: the rig's)."""
    from pathlib import Path
    args.antagonists = None
    if str(args.rig).lower().endswith(".bsproj") and Path(args.rig).is_file():
        from model.project import load_project
        check_rig_options(args)
        project = load_project(args.rig)
        rig, args.antagonists = project.rig, project.antagonists
    else:
        rig = load_rig_arg(args)
    if args.rig_units:
        rig.units = args.rig_units
    return rig


def check_solve_options(args) -> None:
    """The solve options that need no rig or take, checked before either is read: --threshold in [0, 1], a
    --calibration-frames count of 0 or more, not 0 with --neutral-frames (``check_calibration_settings``), and no
    per-region option (--threshold, --level) with --global (it solved globally, the option unused)."""
    from model.errors import RigInputError
    from model.take_workspace import check_calibration_settings
    regional = [o for o, v in (("--threshold", args.threshold), ("--level", args.level)) if v is not None]
    if args.global_solve and regional:
        raise RigInputError(f"--global: solves one weight vector for the whole face, and {' and '.join(regional)} "
                            f"choose{'s' if len(regional) == 1 else ''} the regions of a per-region solve; give one or "
                            "the other.")
    check_threshold(args)
    check_rate(args)
    check_calibration_settings(solve_options(args))


def solve_options(args) -> dict:
    """The solve settings of ``model.take_workspace`` from the solve options, before a per-region solve's level
    (``solve_settings`` adds it with the segmentation)."""
    from model.take_workspace import SOLVE_DEFAULTS

    regional = not args.global_solve and SOLVE_DEFAULTS["regional"]
    if args.threshold is not None or args.level is not None:
        regional = not args.global_solve
    return {"mode": "region" if regional else "global", "residual": args.residual,
            "calibration_frames": args.calibration_frames, "fixed_head": args.fixed_head,
            "neutral_frames": args.neutral_frames, "stable": args.stable, "rate": getattr(args, "rate", None)}


def solve_settings(args, rig) -> tuple[dict, object]:
    """(solve settings of ``model.take_workspace``, segmentation or None) from the solve options; a per-region
    solve segments ``rig`` here, once for every take solved with these settings."""
    from model.take_workspace import SOLVE_DEFAULTS

    settings = solve_options(args)
    if getattr(args, "antagonists", None) is not None:      # a project's edited pairs (``load_solve_rig``)
        settings["antagonists"] = args.antagonists
    regional = settings["mode"] == "region"
    segmentation = None
    if regional:
        from model.errors import RigInputError
        from model.segmentation import SegmentationSettings, segment_rig
        t = args.threshold if args.threshold is not None else SOLVE_DEFAULTS["threshold"]
        with about(args.rig):         # a threshold that leaves no region of the rig: name the rig
            segmentation = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas,
                                       SegmentationSettings(t=t))
        n = len(segmentation.levels)
        if args.level is not None and not 0 <= args.level < n:
            raise RigInputError(f"{args.rig}: --level {args.level} does not exist: the rig's segmentation at "
                                f"threshold {t:g} has levels 0 to {n - 1}.")
        settings["level"] = args.level if args.level is not None else min(SOLVE_DEFAULTS["level"], n - 1)
    return settings, segmentation


def announce_solver_build() -> None:
    """Say on stderr that the take solver is compiled first, when it is (the first solve after installing):
    otherwise the command would sit silent for up to half a minute."""
    from solvers import take_kernel
    if not take_kernel.ready():
        print(take_kernel.BUILD_MESSAGE, file=sys.stderr, flush=True)


def cmd_solve(args) -> int:
    from model.marker_map import load_marker_map
    from model.take_exports import check_solve_output_space, export_solve_outputs
    from model.take_workspace import TakeWorkspace

    check_solve_options(args)
    rig = load_solve_rig(args)
    ws = TakeWorkspace(rig)
    if not ws.prepare_solve(args.take, load_marker_map(args.map) if args.map else None, solve_options(args),
                            check_outputs=lambda w: check_solve_output_space(w, args.cache, args.gltf)):
        return write_weight_take(ws, args)
    settings, segmentation = solve_settings(args, rig)
    announce_solver_build()
    sol = ws.solve(settings, segmentation=segmentation)
    report = export_solve_outputs(ws, args.output, args.cache, args.report, args.gltf)
    print_warnings(report["warnings"])            # the take reader's (a file cut short), also in the report
    for lab in report["markers_left_out"]:
        print(f"warning: marker {lab} left out ({report['markers_left_out_why'][lab]})", file=sys.stderr)
    with_c = f" with {len(report['correctives'])} corrective(s)" if report["correctives"] else ""
    print(f"solved {sol.n_frames} frames{with_c} in {sol.solve_seconds:.2f} s ({sol.frames_per_second:.0f} fps); "
          f"marker RMSE {report['marker_rmse']:.4g} {rig.units}; motion explained "
          f"{report['motion_explained'] if report['motion_explained'] is not None else float('nan'):.3f}; "
          f"neutral frames {_neutral_text(report)}; wrote {args.output}"
          + _written(args))
    return 0


def _neutral_text(report: dict) -> str:
    if report["neutral_frames"] is not None:
        return str(report["neutral_frames"])
    return "none (fixed head)" if report["head"] == "fixed" else "none (no calibration)"


def _written(args) -> str:
    return "".join(f", {p}" for p in (args.cache, args.report, args.gltf) if p)


def write_weight_take(ws, args) -> int:
    """``solve`` on a weight take: its weights on the rig's shapes, written as a solve's outputs."""
    from model.take_exports import export_solve_outputs
    take = ws.take
    if args.map:
        print(f"warning: {args.take} holds weights, not markers: --map is not used", file=sys.stderr)
    report = export_solve_outputs(ws, args.output, args.cache, args.report, args.gltf)
    print_warnings(take.warnings)
    if take.unmapped:
        print(f"warning: {len(take.unmapped)} column(s) drive no shape of the rig: {', '.join(take.unmapped)}",
              file=sys.stderr)
    print(f"weight take: {take.n_frames} frames at {take.rate:g} fps driving {len(report['shapes_driven'])} of "
          f"{ws.rig.n_shapes} shapes; wrote {args.output}" + _written(args))
    return 0
