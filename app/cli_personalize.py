"""The ``personalize`` command: the actor's own rig from a template rig and scans or a marker take
(Ma et al. 2016 §3; ALGORITHMS.md §9; ``model.personalize``).

Writes a new project with the personalised rig (same shape names, correctives and presets) and prints the
solve's size and time and the shapes that changed most (RMS and largest change of their displacements).
"""
from __future__ import annotations

import json

from app.cli_common import load_rig_arg, print_warnings


def add_parser(sub, rig_arg) -> None:
    sp = sub.add_parser("personalize", help="build an actor's own rig from scans or a marker take (Ma et al. 2016)")
    rig_arg(sp)
    sp.add_argument("--neutral-scan", metavar="SCAN.obj",
                    help="the actor's neutral scan in the rig's topology (default: warped to the take, or "
                         "re-estimated from the pose scans)")
    sp.add_argument("--scans", nargs="+", metavar="FILE_OR_DIR", default=[],
                    help="pose scans of the actor (OBJ files in the rig's topology, or folders of them)")
    sp.add_argument("--take", metavar="TAKE", help="a marker take of the actor (.c3d, .trc, .csv) for an actor without scans")
    sp.add_argument("--map", metavar="MAP.json", help="marker map of the take (default: mapped automatically)")
    sp.add_argument("--calibration-frames", type=int, default=30,
                    help="neutral frames at the start of the take (default 30; 1 to the take's frames)")
    sp.add_argument("--neutral-frames", default=None, metavar="A:B",
                    help="the actor's neutral: frames A to B of the take (inclusive, counted from 0), as solve's "
                         "--neutral-frames (default: the first --calibration-frames)")
    sp.add_argument("--iterations", type=int, default=None, help="weight/delta alternations (default 3)")
    sp.add_argument("--top", type=int, default=10, help="changed shapes to list (default 10)")
    sp.add_argument("--report", help="JSON report to write (the summary and every shape's change)")
    sp.add_argument("-o", "--output", required=True, help=".bsproj project to write")
    sp.set_defaults(func=cmd_personalize, output_files=(("output", "-o"), ("report", "--report")))


def cmd_personalize(args) -> int:
    from model.errors import RigInputError
    from model.output_set import write_set
    from model.personalize import personalize_rig_detailed, scan_paths, shape_change_report
    from model.project import Project, project_writer

    if args.map and not args.take:
        raise RigInputError("--map: a marker map needs --take.")
    if args.neutral_frames is not None:
        from model.take_workspace import parse_neutral_frames
        if not args.take:
            raise RigInputError("--neutral-frames: the actor's neutral frames are a marker take's; give --take too.")
        if parse_neutral_frames(args.neutral_frames) == "auto":
            raise RigInputError("--neutral-frames: personalize takes the actor's neutral as a frame range A:B, not "
                                "'auto'.")
    if args.iterations is not None and args.iterations < 1:
        raise RigInputError(f"--iterations: {args.iterations} is fewer than one.")
    rig = load_rig_arg(args)
    scans = scan_paths(args.scans)
    take = marker_map = None
    if args.take:
        from model.takes import MarkerTake, load_take
        take = load_take(args.take)
        if not isinstance(take, MarkerTake):
            raise RigInputError(f"{args.take}: is a weight take ({take.file_format}), not marker trajectories.")
        if args.neutral_frames is not None:
            from model.personalize import neutral_frames_of
            neutral_frames_of(take, args.calibration_frames, args.neutral_frames)   # inside the take, before any work
        elif not 1 <= args.calibration_frames <= take.n_frames:   # the actor's neutral: 0 or too many read no neutral
            raise RigInputError(f"{args.take}: has {take.n_frames} frames; --calibration-frames "
                                f"{args.calibration_frames} must be 1 to {take.n_frames} (the actor's neutral "
                                "frames at its start).")
        if args.map:
            from model.marker_map import load_marker_map
            marker_map = load_marker_map(args.map)
        print_warnings(take.warnings)    # what its reader decided (a file cut short, gaps at the origin)
    options = {} if args.iterations is None else {"iterations": args.iterations}
    actor, _, summary = personalize_rig_detailed(rig, args.neutral_scan, scans, take, marker_map,
                                                 calibration_frames=args.calibration_frames,
                                                 neutral_frames=args.neutral_frames, **options)
    _, rows = shape_change_report(rig, actor)
    writers = {args.output: project_writer(Project(rig=actor))}
    if args.report:
        report = json.dumps({**summary, "rig": str(args.rig), "output": str(args.output), "shapes": rows},
                            indent=1).encode("utf-8")
        writers[args.report] = lambda f: f.write(report)
    write_set(writers)    # the project and its report as one set: both new, or neither (as solve's outputs)
    fit = summary["fit_rms"]
    fit_text = f"; scan fit RMS {fit[0]:.4g} -> {fit[-1]:.4g} {rig.units}" if fit else ""
    print(f"wrote {args.output}: {actor.n_shapes} shapes personalised ({summary['unknowns']:,} unknowns, "
          f"{summary['seconds']:.1f} s; neutral: {summary['neutral']}{_frames_text(summary)}){fit_text}")
    for r in rows[: max(args.top, 0)]:
        print(f"  {r['shape']:<20} change RMS {r['rms']:.4g}  max {r['max']:.4g} {rig.units}  "
              f"({100 * r['relative']:.0f}% of the shape)")
    return 0


def _frames_text(summary: dict) -> str:
    frames = summary.get("neutral_frames")
    return f" of frames {frames[0]}:{frames[1]}" if frames else ""
