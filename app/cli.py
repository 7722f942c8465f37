"""The ``blendshape-studio`` command line (DESIGN.md, Command line). Stable: scripts and tests rely on it.

Every error in the input is one sentence on stderr naming the file and the problem, and a non-zero exit.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from app import cli_batch, cli_pairs, cli_personalize, cli_solve
from app.command_line import opens_window
from app.cli_common import (EXIT_INPUT, EXIT_UNEXPECTED, ArgumentParser, about, add_rate_option, check_not_an_input,
                             check_outputs, check_rate, check_rig_options, check_shape_names, check_threshold,
                             join_dash_values, load_rig_arg, parse_size, pose_weights, print_warnings)
from model.errors import RigInputError

def cmd_info(args) -> int:
    rig = load_rig_arg(args)
    moving = int((np.abs(rig.deltas).max(axis=(0, 2)) > 0).sum()) if rig.n_shapes else 0
    info = {
        "path": str(args.rig),
        "name": rig.name,
        "vertices": rig.n_vertices,
        "faces": rig.n_faces,
        "triangles": int(np.maximum(rig.face_counts - 2, 0).sum()),
        "units": rig.units,
        "shapes": rig.shape_names,
        "moving_vertices": moving,
        "correctives": [{"name": c.name, "drivers": list(c.drivers), "rule": c.rule, "muted": c.muted}
                        for c in rig.correctives],
        "presets": sorted(rig.presets),
        "bounds": {"min": rig.neutral.min(axis=0).round(6).tolist(),   # DESIGN.md's contract, as ``take-info``'s
                   "max": rig.neutral.max(axis=0).round(6).tolist()},
    }
    if Path(args.rig).suffix.lower() in (".gltf", ".glb"):  # which mesh was read, and the others (--mesh NAME)
        from model.gltf import gltf_meshes
        info["meshes"] = gltf_meshes(args.rig)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        print(f"{info['name']}: {info['vertices']} vertices, {info['faces']} faces, "
              f"{len(info['shapes'])} shapes, units {info['units']}")
        print(f"  shapes: {', '.join(info['shapes'])}")
        if info["correctives"]:
            names = [c["name"] + (" (muted)" if c["muted"] else "") for c in info["correctives"]]
            print(f"  correctives: {', '.join(names)}")
        if info["presets"]:
            print(f"  presets: {', '.join(info['presets'])}")
        if len(info.get("meshes", [])) > 1:
            print("  meshes (--mesh NAME): " + ", ".join(f"{m['name']} ({m['targets']} targets, {m['vertices']} vertices)"
                                                      for m in info["meshes"]))
    return 0


def cmd_render(args) -> int:
    from widgets.scene import use_offscreen_backend_if_headless
    use_offscreen_backend_if_headless()
    from app.views import build_view
    check_threshold(args)
    size = parse_size(args.size)
    rig = load_rig_arg(args)
    weights = pose_weights(rig, args)
    from model.segmentation import SegmentationSettings
    settings = SegmentationSettings(min_region_size=args.min_size)
    if args.threshold is not None:
        settings.t = args.threshold
    with about(args.rig):       # a --level the segmentation lacks, a threshold that leaves no region: name the rig
        settings.validate()
        view = build_view(rig, weights, args.view, settings=settings, level=args.level)
    from model.parts import checked_hidden, drawn_faces, rig_parts, vertex_colors
    from widgets.scene import SKIN, render_png
    parts = rig_parts(rig)
    hidden = None if args.hide is None else \
        checked_hidden(parts, [n.strip() for n in args.hide.split(",") if n.strip() and n.strip() != "none"])
    faces, counts, indices = drawn_faces(rig, hidden, parts)
    colors = vertex_colors(parts, rig.face_counts, rig.face_indices, rig.n_vertices, SKIN) \
        if args.material_colors else None
    texture = None
    if args.texture != "none":
        from app.texture_controller import render_texture
        from widgets.texture_view import textured_surface
        split, image8 = render_texture(rig, weights, args.rig, args.texture, args.texture_detail, args.view)
        texture = textured_surface(split.of_faces(rig.face_counts, faces), image8, counts)
    render_png(view.points, counts, indices, args.output, focus=view.focus,
               colormap=view.colormap, camera=args.camera, size=size, wireframe=args.wireframe,
               title=view.title if args.label else "", texture=texture, base_colors=colors)
    print(f"wrote {args.output}")
    return 0


def cmd_export(args) -> int:
    from model.export import check_export_space, check_files_beside, export_rig, load_animation
    check_rate(args)
    if args.rate is not None and not args.animation:
        raise RigInputError("--rate: gives the frame rate of --animation's weights CSV; no --animation was given.")
    rig = load_rig_arg(args)
    check_files_beside(rig, args.output, lambda p: check_not_an_input(args, p, "-o"))   # an OBJ's .mtl
    weights = pose_weights(rig, args)
    animation = load_animation(args.animation, rig, args.rate) if args.animation else None
    check_export_space(rig, args.output, animation.n_frames if animation else 0, units=args.out_units, up=args.up)
    export_rig(rig, args.output, weights, animation, units=args.out_units, up=args.up)
    print_warnings(animation.warnings if animation is not None else ())
    frames = f", {animation.n_frames} frames" if animation is not None else ""
    print(f"wrote {args.output} ({rig.n_vertices} vertices, {rig.n_faces} faces, {rig.n_shapes} shapes, "
          f"{len(rig.correctives)} correctives{frames})")
    return 0


def cmd_segment(args) -> int:
    from model.atomic import atomic_write
    from model.segmentation import SegmentationSettings, segment_rig, segmentation_to_json
    from model.wording import duration
    check_threshold(args)
    rig = load_rig_arg(args)
    chosen = {"t": args.threshold, "map_kind": args.map, "smoothing": args.smoothing,
              "separate_meshes": args.separate_meshes,
              "normalise": None if args.normalise is None else args.normalise == "per-shape",
              "split_by_shapes": None if args.split is None else args.split == "shapes"}
    with about(args.rig):      # settings out of range, a threshold that leaves no region: name the rig
        settings = SegmentationSettings(levels=args.levels, min_region_size=args.min_size, overlap_rings=args.overlap,
                                        method=args.method, **{k: v for k, v in chosen.items() if v is not None})
        seg = segment_rig(rig.neutral, rig.face_counts, rig.face_indices, rig.deltas, settings)
    atomic_write(args.output, json.dumps(segmentation_to_json(seg)).encode("utf-8"))
    counts = ", ".join(str(lvl.n_regions) for lvl in seg.levels)
    print(f"wrote {args.output}: {len(seg.levels)} levels with {counts} regions "
          f"({duration(seg.seconds.get('total', 0.0))})")
    return 0


def cmd_corrective(args) -> int:
    """Smith §4.5 from a scan: e = (x_scan − x_cur) / a(w) at full drivers (or fit weights first with --fit)."""
    from model.corrective_authoring import corrective_from_scan
    from model.correctives import add_corrective, mirrored_corrective
    from model.obj_io import read_obj
    from model.project import Project, load_project, save_project
    path = Path(args.rig)
    check_rig_options(args)
    project = load_project(path) if path.suffix.lower() == ".bsproj" else Project(rig=load_rig_arg(args))
    rig = project.rig
    drivers = [d.strip() for d in args.drivers.split(",") if d.strip()]
    if len(drivers) < 2:
        raise RigInputError(f"--drivers: a corrective needs two or more driver shapes, got {len(drivers)}.")
    if len(set(drivers)) < len(drivers):
        raise RigInputError(f"--drivers: {', '.join(sorted({d for d in drivers if drivers.count(d) > 1}))} is "
                            "listed more than once.")
    check_shape_names(rig, drivers, "--drivers", args.rig)
    corrective, _ = corrective_from_scan(rig, drivers, read_obj(args.target).vertices, args.rule, fit=args.fit,
                                         name=args.name or "", source=str(args.target))
    made = [corrective]
    if args.mirror:
        made.append(mirrored_corrective(corrective, rig.shape_names, rig.neutral, units=rig.units))
    for c in made:
        add_corrective(rig, c)
    save_project(project, args.output)
    print(f"wrote {args.output} with corrective {' and '.join(c.name for c in made)} ({args.rule}); "
          f"largest correction {np.linalg.norm(corrective.delta, axis=1).max():.4g} {rig.units}")
    return 0


def cmd_take_info(args) -> int:
    from model.takes import load_take, take_summary
    check_rate(args)
    info = take_summary(load_take(args.take, rate=args.rate))
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    gaps = sum(info["missing"].values())
    outputs = info.get("model_outputs_left_out")
    kind = f"weights take ({info['format']})" if info["kind"] == "weights" else f"{info['kind']} take"
    print(f"{Path(args.take).name}: {kind}, {info['frames']} frames at {info['rate']:g} fps, "
          f"{len(info['labels'])} {'markers' if info['kind'] == 'markers' else 'weight columns'}"
          + (f" ({info['units']}), {gaps} missing samples" if info["kind"] == "markers" else "")
          + (f"; {outputs} model outputs left out" if outputs else ""))
    if info["bounds"]:
        print(f"  bounds: {info['bounds']['min']} .. {info['bounds']['max']}")
    print(f"  labels: {', '.join(info['labels'])}")
    print_warnings(info["warnings"])
    return 0


def cmd_sample(args) -> int:
    from model.atomic import disk_error
    from model.readers import PRESETS_FILE
    from resources.sample_rig import write_sample
    from resources.sample_textures import write_sample_textures
    folder = Path(args.output)
    taken = sorted(p.name for p in folder.iterdir() if p.suffix.lower() == ".obj" or p.name == PRESETS_FILE) \
        if folder.is_dir() else []
    if taken:      # the sample's files would overwrite that rig's, or be read with them as one rig
        more = f" and {len(taken) - 1} more" if len(taken) > 1 else ""
        raise RigInputError(f"{folder}: already holds {taken[0]}{more}; write the sample rig into a new or empty "
                            "folder.")
    before = set(folder.iterdir()) if folder.is_dir() else None
    try:
        out = write_sample(folder)
        write_sample_textures(out)
    except OSError as exc:     # a full disk part-way: the files written so far go too, not half a rig left
        for p in set(folder.iterdir()) - (before or set()) if folder.is_dir() else ():
            p.unlink(missing_ok=True)
        if before is None and folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
        from model.atomic import write_error
        raise (disk_error(folder, exc, rename=True) or write_error(folder, exc)) from exc
    print(f"wrote the sample rig to {out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="blendshape-studio",
                       description="Blendshape Studio: edit, segment, solve and render blendshape face rigs.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    def rig_arg(sp):
        sp.add_argument("rig", metavar="RIG", help="an OBJ folder, a .gltf/.glb file or a .bsproj project")
        sp.add_argument("--neutral", help="file name of the neutral OBJ in a folder (default: the one named *neutral*)")
        sp.add_argument("--units", choices=["cm", "mm", "m"], help="units of the rig files (default: cm for OBJ)")
        sp.add_argument("--mesh", help="glTF: the mesh to read (default: the most morph targets, then vertices)")

    def pose_args(sp):
        sp.add_argument("--weights", help="NAME=V,... shape weights of the pose (default: neutral)")
        sp.add_argument("--preset", help="start from a named preset of the rig (e.g. happy)")

    sp = sub.add_parser("info", help="print what a rig holds")
    rig_arg(sp)
    sp.add_argument("--json", action="store_true", help="machine-readable output")
    sp.set_defaults(func=cmd_info)

    sp = sub.add_parser("take-info", help="print what a take (C3D, TRC, marker CSV, Live Link Face CSV) holds")
    sp.add_argument("take", metavar="TAKE", help="a .c3d, .trc or .csv take")
    add_rate_option(sp)
    sp.add_argument("--json", action="store_true", help="machine-readable output")
    sp.set_defaults(func=cmd_take_info)

    sp = sub.add_parser("render", help="render a pose or a map to a PNG, off screen")
    rig_arg(sp)
    pose_args(sp)
    sp.add_argument("-o", "--output", required=True, help="PNG file to write")
    sp.set_defaults(output_files=(("output", "-o"),))
    sp.add_argument("--view", default="shaded", choices=["shaded", "deformation", "deformation-rgb", "segmentation"])
    sp.add_argument("--threshold", type=float, default=None,
                    help="segmentation quantile t in [0, 1] of the moving skin (default 0.5)")
    sp.add_argument("--level", type=int, default=0, help="hierarchy level to show (0 = finest)")
    sp.add_argument("--min-size", type=int, default=30, help="segmentation: smallest region in vertices (default 30)")
    sp.add_argument("--size", default="1024,768", help="W,H in pixels (default 1024,768)")
    sp.add_argument("--camera", default="front", choices=["front", "left", "right", "three-quarter"])
    sp.add_argument("--wireframe", action="store_true", help="draw polygon edges")
    sp.add_argument("--label", action="store_true", help="write the view's name in the corner")
    sp.add_argument("--texture", default="none", choices=["band-pass", "linear", "none"],
                    help="draw the rig's textures blended by the pose (shaded view; textures found beside the rig)")
    sp.add_argument("--texture-detail", default="regional", choices=["regional", "dominant", "neutral"],
                    help="band-pass: whose detail band shows (default: per region, the strongest shape there)")
    sp.add_argument("--hide", default=None, metavar="PART,...",
                    help="parts (the materials the faces name) not to draw; 'none' draws every part (default: the "
                         "helper shells over the eyes, e.g. ICT's M_EyeOcclusion, M_EyeBlend, M_LacrimalFluid)")
    sp.add_argument("--material-colors", action="store_true",
                    help="draw each part in its material's colour (MTL Kd, glTF base colour) instead of one skin colour")
    sp.set_defaults(func=cmd_render)

    sp = sub.add_parser("export", help="write the rig for other tools: glTF/USD blend shapes and animation, or a posed OBJ")
    rig_arg(sp)
    pose_args(sp)
    sp.add_argument("-o", "--output", required=True, help=".glb, .gltf, .usd, .usda, .usdc or .obj file to write")
    sp.set_defaults(output_files=(("output", "-o"),))
    sp.add_argument("--animation", help="weights CSV (as solve writes) or Live Link Face CSV to animate (glTF, USD)")
    add_rate_option(sp, "frames a second of an --animation weights CSV without a time column (default 30, with a "
                        "warning); a file's own times are kept")
    sp.add_argument("--out-units", choices=["m", "cm", "mm"],
                    help="units of the file written (default: m for glTF and USD, the rig's for OBJ)")
    sp.add_argument("--up", choices=["y", "z"], default="y", help="up axis of the file written (default y)")
    sp.set_defaults(func=cmd_export)

    sp = sub.add_parser("segment", help="segment the face into regions and a hierarchy (JSON)")
    rig_arg(sp)
    sp.add_argument("--threshold", type=float, default=None,
                    help="quantile t in [0, 1] of the map over the skin that moves (default 0.5)")
    sp.add_argument("--levels", type=int, default=None, help="hierarchy levels (default: until one region)")
    sp.add_argument("--map", default=None, choices=["laplacian", "displacement", "laplacian+displacement"],
                    help="where the skin bends (Joshi), moves (Acosta), or either (default laplacian+displacement)")
    sp.add_argument("--normalise", default=None, choices=["per-shape", "none"],
                    help="per-shape: each shape's map over its own 99%% quantile before the maximum (default); "
                         "none: the raw maximum (Joshi)")
    sp.add_argument("--smoothing", type=int, default=None, help="rounds of 1-ring smoothing of the map (default 1)")
    sp.add_argument("--split", default=None, choices=["shapes", "none"],
                    help="shapes: cut regions where the group of shapes moving the skin changes (default)")
    sp.add_argument("--separate-meshes", default=None, choices=["follow", "background"],
                    help="separate meshes (eyeballs, teeth): follow the region that moves them (default) or stay "
                         "in the background")
    sp.add_argument("--method", default="threshold", choices=["threshold", "region-growing"])
    sp.add_argument("--min-size", type=int, default=30, help="smallest region in vertices (default 30)")
    sp.add_argument("--overlap", type=int, default=1, help="overlap rings between regions (default 1)")
    sp.add_argument("-o", "--output", required=True, help="JSON file to write")
    sp.set_defaults(func=cmd_segment, output_files=(("output", "-o"),))

    sp = sub.add_parser("corrective", help="add a corrective shape for a driver combination from a scan (Smith)")
    rig_arg(sp)
    sp.add_argument("--drivers", required=True, help="A,B[,C...] driver shapes (two or more)")
    sp.add_argument("--target", required=True, help="OBJ of the desired surface with the drivers at 1 (rig vertex order)")
    sp.add_argument("--rule", default="product", help="activation: product, hierarchical, min or smooth-min")
    sp.add_argument("--name", help="corrective name (default: the drivers joined by '+')")
    sp.add_argument("--fit", action="store_true",
                    help="the scan is a free performance: fit the weights first and keep the residual over the drivers' region")
    sp.add_argument("--mirror", action="store_true",
                    help="also add the other side's corrective (drivers _L<->_R, reflected across x = 0)")
    sp.add_argument("-o", "--output", required=True, help=".bsproj project to write")
    sp.set_defaults(func=cmd_corrective, output_files=(("output", "-o"),), rig_updated_in_place=True)

    cli_solve.add_parser(sub, rig_arg)
    cli_pairs.add_parser(sub, rig_arg)
    cli_personalize.add_parser(sub, rig_arg)
    cli_batch.add_parser(sub, rig_arg)

    sp = sub.add_parser("sample", help="write the bundled sample rig as an OBJ folder, with its UVs and generated textures")
    sp.add_argument("-o", "--output", required=True, help="folder to write")
    sp.set_defaults(func=cmd_sample, output_folders=(("output", "-o"),))

    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    from app.runtime import limit_blas_threads
    limit_blas_threads()
    if opens_window(argv):
        from app.gui import run_gui
        return run_gui(argv[0] if argv else None)
    parser = build_parser()
    args = parser.parse_args(join_dash_values(parser, argv))   # a mistake in the options: one sentence, exit 2
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        check_outputs(args)      # before any work: an output that cannot be written is refused, nothing written
        return int(args.func(args) or 0)
    except RigInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:   # the reader went away (`blendshape-studio pairs RIG | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as exc:  # a bug or an input no check foresaw: one sentence, the traceback in a crash log
        from model.atomic import disk_error
        full = disk_error(getattr(exc, "filename", None) or getattr(args, "output", None), exc)
        if full is not None:   # a full disk (or quota, a file too large, an I/O error) under a write: not a bug
            print(f"error: {full}", file=sys.stderr)
            return EXIT_INPUT
        from app.crash import describe_unexpected
        print(f"error: {describe_unexpected(exc, f'{args.command!r}')}", file=sys.stderr)
        return EXIT_UNEXPECTED


if __name__ == "__main__":
    sys.exit(main())
