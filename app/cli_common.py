"""What every ``blendshape-studio`` command shares: the exit code for bad input, argument parsing of
weights and sizes, the checks of every output path before any work, and loading the RIG argument. The commands'
modules (app.cli, app.cli_solve, app.cli_pairs) import it; it imports none of them."""
from __future__ import annotations

import os

import numpy as np

from model.errors import RigInputError

EXIT_INPUT = 2        # bad input: one sentence naming the file and the problem
EXIT_UNEXPECTED = 1   # anything else: one sentence and a crash log with the traceback


def check_outputs(args) -> None:
    """Refuse, before any work, an output option naming what cannot be written (``model.atomic``: a folder where a
    file goes, a file where a folder goes, a device, a path through a file) and two outputs naming the same file.
    Each command lists its outputs: ``output_files`` and ``output_folders``, (dest, option) pairs."""
    from model.atomic import check_output_file, check_output_folder
    seen: dict[str, str] = {}
    for dest, option in getattr(args, "output_files", ()):
        path = getattr(args, dest, None)
        if path is None:
            continue
        check_output_file(path)
        key = os.path.realpath(path)
        if key in seen:
            raise RigInputError(f"{path}: is given for both {seen[key]} and {option}; each output needs its own "
                                "file.")
        seen[key] = option
    for dest, _option in getattr(args, "output_folders", ()):
        path = getattr(args, dest, None)
        if path is not None:
            check_output_folder(path)


def parse_weights(text: str | None) -> dict[str, float]:
    """'jawOpen=1,mouthSmile_L=0.5' -> {'jawOpen': 1.0, 'mouthSmile_L': 0.5}."""
    out: dict[str, float] = {}
    if not text:
        return out
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        name, sep, value = item.partition("=")
        if not sep:
            raise RigInputError(f"--weights: '{item}' is not NAME=VALUE.")
        try:
            v = float(value)
        except ValueError:
            raise RigInputError(f"--weights: the value of '{name}' is not a number: '{value}'.") from None
        if not np.isfinite(v):
            raise RigInputError(f"--weights: the value of '{name}' is not finite.")
        out[name.strip()] = v
    return out


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.split(","))
    except ValueError:
        raise RigInputError(f"--size: '{text}' is not W,H (two whole numbers).") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise RigInputError(f"--size: {w}x{h} is outside 16..8192 pixels.")
    return w, h


def load_rig_arg(args):
    """The rig named by the command's RIG argument (with --neutral and --units where the command has them)."""
    from model.readers import load_rig
    return load_rig(args.rig, neutral=getattr(args, "neutral", None), units=getattr(args, "units", None),
                    mesh=getattr(args, "mesh", None))


def pose_weights(rig, args) -> np.ndarray:
    """The weight vector of --preset then --weights (the latter win), in the rig's shape order."""
    named = {}
    if getattr(args, "preset", None):
        if args.preset not in rig.presets:
            raise RigInputError(f"--preset: the rig has no preset '{args.preset}' "
                                f"(it has: {', '.join(sorted(rig.presets)) or 'none'}).")
        named.update(rig.presets[args.preset])
    named.update(parse_weights(getattr(args, "weights", None)))
    return rig.weights_from_dict(named)
