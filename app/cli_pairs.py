"""The ``pairs`` command: which shape pairs of a rig need a corrective (ALGORITHMS.md §6; Smith 2006 §4.5),
ranked as the Correctives panel's interference finder ranks them (``model.interference``).

Each row gives the score, the shapes (and the mirror pair it stands for), and where the pair interferes:
the peak of the heat map in rig units and the area above 10% of it in rig units².
"""
from __future__ import annotations

import json

from app.cli_common import load_rig_arg
from model.interference import (MEASURES, hot_area, pair_heat, pair_scores, ranked_pairs, rig_vertex_areas,
                                row_correctives)


def add_parser(sub, rig_arg) -> None:
    sp = sub.add_parser("pairs", help="rank the shape pairs that interfere (need a corrective), as the GUI's finder")
    rig_arg(sp)
    sp.add_argument("--measure", choices=MEASURES, default="overshoot",
                    help="overshoot of the pair's sum where both act (default), Smith's overlap, or overlap "
                         "in the same direction")
    sp.add_argument("--top", type=int, default=20, help="how many rows (default 20)")
    sp.add_argument("--partners-of", metavar="SHAPE", help="only the partners of this shape")
    sp.add_argument("--separate-sides", action="store_true",
                    help="list a pair and its mirror image (_L/_R) as two rows (default: one row)")
    sp.add_argument("--json", action="store_true", help="machine-readable output")
    sp.set_defaults(func=cmd_pairs)


def cmd_pairs(args) -> int:
    from model.errors import RigInputError

    rig = load_rig_arg(args)
    if args.top < 1:
        raise RigInputError(f"--top: {args.top} rows is fewer than one.")
    if rig.n_shapes < 2:
        raise RigInputError(f"{args.rig}: the rig has {rig.n_shapes} shape(s); pairs need two or more.")
    if args.partners_of is not None and args.partners_of not in rig.shape_names:
        raise RigInputError(f"{args.rig}: the rig has no shape named '{args.partners_of}' (--partners-of).")
    areas = rig_vertex_areas(rig)
    rows = ranked_pairs(pair_scores(rig, args.measure, areas), rig.shape_names, args.top,
                        merge_mirrored=not args.separate_sides, partner_of=args.partners_of)
    names = rig.shape_names
    out = []
    for rank, row in enumerate(rows, 1):
        heat = pair_heat(rig, row, args.measure)
        n, area = hot_area(heat, areas)
        out.append({"rank": rank, "shapes": [names[row.i], names[row.j]], "score": round(row.score, 6),
                    "mirror": None if row.mirror is None else [names[row.mirror[0]], names[row.mirror[1]]],
                    "peak": round(float(heat.max()), 6), "vertices": n, "area": round(area, 6),
                    "correctives": row_correctives(rig, row)})
    if args.json:
        print(json.dumps({"measure": args.measure, "units": rig.units, "pairs": out}, indent=2))
        return 0
    what = "overshoot" if args.measure == "overshoot" else "overlap"
    print(f"{len(out)} pairs by {args.measure} ({rig.units}; peak = largest {what}, area where above 10% of it):")
    width = max((len(" × ".join(r["shapes"])) for r in out), default=0)
    for r in out:
        side = "" if r["mirror"] is None else f"  and {' × '.join(r['mirror'])}"
        done = f"  (corrective: {', '.join(r['correctives'])})" if r["correctives"] else ""
        print(f"{r['rank']:4d}  {r['score']:6.3f}  {' × '.join(r['shapes']):<{width}}  peak {r['peak']:.3g}  "
              f"area {r['area']:.3g} {rig.units}²{side}{done}")
    return 0
