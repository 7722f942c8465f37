"""What every ``blendshape-studio`` command shares: the exit code for bad input, the argument parser whose errors
are one sentence, argument parsing of weights and sizes, the checks of every output path before any work, and
loading the RIG argument. The commands' modules (app.cli, app.cli_solve, app.cli_pairs) import it; it imports none
of them."""
from __future__ import annotations

import argparse
import os
import re
from contextlib import contextmanager

import numpy as np

from model.errors import RigInputError
from model.rig import MAX_WEIGHT
from model.beside_inputs import check_not_input

EXIT_INPUT = 2        # bad input: one sentence naming the file and the problem
EXIT_UNEXPECTED = 1   # anything else: one sentence and a crash log with the traceback


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose errors (an unknown choice, a missing value or option) are one sentence on stderr,
    ``error: ...``, with exit code 2, as every other bad input is, instead of the usage block. The command's
    subparsers are of this class too (``add_subparsers`` makes its parsers of the parent's class)."""

    def error(self, message: str):
        message = " ".join(str(message).split()).rstrip(".")
        self.exit(EXIT_INPUT, f"error: {message} (see {self.prog} --help).\n")


_DASH_VALUE = re.compile(r"^-[\d.]")


def join_dash_values(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """``argv`` with a value that starts with a dash and a digit given to an option that takes a value joined to
    it (``--size -5,100`` as ``--size=-5,100``): argparse would take ``-5,100`` for an option and stop with
    "expected one argument"; given as the option's value, the option's own check says what is wrong with it."""
    def valued(p: argparse.ArgumentParser) -> set[str]:
        return {flag for a in p._actions if a.option_strings and a.nargs is None for flag in a.option_strings}

    target = parser
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction) and argv and argv[0] in a.choices:
            target = a.choices[argv[0]]
    takes_value = valued(target)
    out: list[str] = []
    for arg in argv:
        if out and out[-1] in takes_value and _DASH_VALUE.match(arg):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def print_warnings(messages) -> None:
    """What a reader decided for a file (a take cut short, a rate assumed), one ``warning:`` line each on stderr."""
    import sys
    for message in messages or ():
        print(f"warning: {message}", file=sys.stderr)


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
        check_not_an_input(args, path, option)
        key = os.path.realpath(path)
        if key in seen:
            raise RigInputError(f"{path}: is given for both {seen[key]} and {option}; each output needs its own "
                                "file.")
        seen[key] = option
    for dest, _option in getattr(args, "output_folders", ()):
        path = getattr(args, dest, None)
        if path is not None:
            check_output_folder(path)


# What a command reads, by the option naming it (a file, a folder, or a list of them): an output may not be one of
# them, nor a file read with a folder given there (the command would write over what it reads, or the next run would
# read the output as part of the input: a posed OBJ in the rig's folder as one more shape).
_INPUTS = (("rig", "RIG"), ("take", "TAKE"), ("map", "--map"), ("animation", "--animation"),
           ("neutral_scan", "--neutral-scan"), ("target", "--target"), ("scans", "--scans"), ("takes", "TAKES"))


def check_not_an_input(args, path, option: str, fix: str | None = None) -> None:
    """Refuse an output file that is one of the command's inputs, a file a ``.gltf`` input refers to (its buffers and
    images: ``model.beside_inputs.gltf_files``), or a file the reader of an input folder (the rig's, the scans', a
    folder of takes) reads there (``model.beside_inputs.check_beside``). ``corrective`` may write its project over
    the RIG project it adds to (``rig_updated_in_place``). ``fix``: what to do instead (default: give ``option``
    another file)."""
    for dest, name in _INPUTS:
        values = getattr(args, dest, None)
        for value in values if isinstance(values, list) else [] if values is None else [values]:
            check_not_input(path, value, name, "this command reads", fix or f"give {option} {{}}",
                            reads="rig" if dest == "rig" else "takes" if dest == "takes" else "scans",
                            same_ok=dest == "rig" and getattr(args, "rig_updated_in_place", False))


@contextmanager
def about(path):
    """A RigInputError raised inside whose sentence does not name ``path`` (the rig or take the command works on)
    is raised again naming it: "The threshold t=0.5 leaves no region ..." becomes "RIG: the threshold ..."."""
    try:
        yield
    except RigInputError as exc:
        text = str(exc)
        if str(path) in text:
            raise
        raise RigInputError(f"{path}: {text[:1].lower()}{text[1:]}") from None


RATE_HELP = "frames a second of a take whose file gives no rate (a weights CSV without a time column: default 30 " \
            "with a warning; a plain marker CSV: 60 with a warning); a file's own rate is kept"


def add_rate_option(sp, help_text: str = "") -> None:
    """--rate, one option wherever a take is read (take-info, solve, batch, export --animation)."""
    sp.add_argument("--rate", type=float, default=None, metavar="FPS", help=help_text or RATE_HELP)


def check_rate(args) -> None:
    """--rate, checked before any file is read (``model.take_data.given_rate``): a number of frames a second."""
    from model.take_data import given_rate
    if getattr(args, "rate", None) is not None:
        args.rate = given_rate(args.rate)


def check_threshold(args) -> None:
    """--threshold, a quantile of the rig's moving skin, in [0, 1] (before the rig is read)."""
    t = getattr(args, "threshold", None)
    if t is not None and not 0.0 <= t <= 1.0:
        raise RigInputError(f"{args.rig}: --threshold {t:g} is outside 0 to 1 (a quantile of the rig's moving "
                            "skin).")


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
        if abs(v) > MAX_WEIGHT:     # as for presets and poses: 1e308 posed the surface to inf and NaN, written out
            raise RigInputError(f"--weights: the value of '{name}' is outside ±{MAX_WEIGHT:g}.")
        out[name.strip()] = v
    return out


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.split(","))
    except ValueError:
        raise RigInputError(f"--size: '{text}' is not W,H (two whole numbers).") from None
    if w <= 0 or h <= 0:
        raise RigInputError(f"--size: {w}x{h} is not a positive size in pixels (16..8192 each).")
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise RigInputError(f"--size: {w}x{h} is outside 16..8192 pixels.")
    return w, h


def load_rig_arg(args):
    """The rig named by the command's RIG argument (with --neutral, --units and --mesh where the command has them)."""
    from model.readers import load_rig
    check_rig_options(args)
    return load_rig(args.rig, neutral=getattr(args, "neutral", None), units=getattr(args, "units", None),
                    mesh=getattr(args, "mesh", None))


def check_rig_options(args) -> None:
    """--neutral, --units and --mesh given to a rig they say nothing of are refused (they were ignored: `--units mm`
    on a project, `--mesh` on an OBJ folder)."""
    suffix = "" if os.path.isdir(args.rig) else os.path.splitext(str(args.rig))[1].lower()
    kind = {".gltf": "a glTF", ".glb": "a glTF", ".bsproj": "a project"}.get(suffix, "an OBJ folder")
    for option, dest, kinds, what in (("--neutral", "neutral", ("an OBJ folder",), "the neutral OBJ of an OBJ folder"),
                                      ("--mesh", "mesh", ("a glTF",), "the mesh of a glTF to read"),
                                      ("--units", "units", ("an OBJ folder", "a glTF"),
                                       "the units of an OBJ folder or a glTF (a project keeps its own)")):
        if getattr(args, dest, None) and kind not in kinds:
            raise RigInputError(f"{args.rig}: is {kind}, and {option} names {what}.")


def check_shape_names(rig, names, option: str, where) -> None:
    """RigInputError naming the rig (``where``) and the option when ``names`` holds names the rig has no shape of."""
    unknown = [n for n in names if n not in rig.shape_names]
    if unknown:
        shown_names = ", ".join(f"'{n}'" for n in unknown[:5]) + (" ..." if len(unknown) > 5 else "")
        raise RigInputError(f"{where}: the rig has no shape{'s' if len(unknown) > 1 else ''} named {shown_names} "
                            f"({option}).")


def pose_weights(rig, args) -> np.ndarray:
    """The weight vector of --preset then --weights (the latter win), in the rig's shape order."""
    named = {}
    if getattr(args, "preset", None):
        if args.preset not in rig.presets:
            raise RigInputError(f"{args.rig}: the rig has no preset '{args.preset}' (--preset; it has: "
                                f"{', '.join(sorted(rig.presets)) or 'none'}).")
        named.update(rig.presets[args.preset])
    given = parse_weights(getattr(args, "weights", None))
    check_shape_names(rig, given, "--weights", args.rig)
    named.update(given)
    return rig.weights_from_dict(named)
