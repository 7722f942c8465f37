"""Left/right naming of shapes: the mirror name of ``browInnerUp_L`` is ``browInnerUp_R``.

Recognised side suffixes, in both cases where rigs use them: ``_L``/``_R`` (ICT FaceKit), ``_l``/``_r``,
``.L``/``.R`` (Blender), ``Left``/``Right`` (ARKit), ``_left``/``_right``. A name without a side suffix
(``jawOpen``, ``mouthFunnel``) is its own mirror image.
"""
from __future__ import annotations

_SUFFIXES = (("_L", "_R"), ("_l", "_r"), (".L", ".R"), ("Left", "Right"), ("_left", "_right"))


def mirror_name(name: str) -> str:
    """The name of the other side's shape (the name itself when it has no side suffix)."""
    for left, right in _SUFFIXES:
        if name.endswith(left) and len(name) > len(left):
            return name[: -len(left)] + right
        if name.endswith(right) and len(name) > len(right):
            return name[: -len(right)] + left
    return name


def is_left(name: str) -> bool:
    """Whether the name carries a left-side suffix (``_L``, ``.L``, ``Left``, ...)."""
    return any(name.endswith(left) and len(name) > len(left) for left, _ in _SUFFIXES)


def mirror_drivers(names) -> list[str]:
    """Each name's mirror name; equal as a set to ``names`` when the set is its own mirror image."""
    return [mirror_name(n) for n in names]


def mirror_indices(names: list[str]) -> list[int]:
    """For each shape, the index of its mirror shape; a shape without one (no suffix, or the other side
    missing from the rig) maps to itself."""
    pos = {n: k for k, n in enumerate(names)}
    return [pos.get(mirror_name(n), k) for k, n in enumerate(names)]


def check_mirrorable(what: str, delta, neutral, mirror, units: str = "") -> None:
    """Raise RigInputError (one sentence) unless nearly every vertex the field ``delta`` moves has a mirror
    vertex across x = 0 (at most 1% without one within 0.5% of the rig's size)."""
    from solvers.symmetry import unmatched_vertices
    from .errors import RigInputError
    bad, moved, tol = unmatched_vertices(neutral, mirror, delta)
    if bad > 0.01 * moved:
        raise RigInputError(f"Cannot mirror {what}: the rig is not symmetric across x = 0 where it acts "
                            f"({bad:,} of its {moved:,} vertices have no mirror vertex within "
                            f"{tol:.2g}{' ' + units if units else ''}).")
