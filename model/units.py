"""Units of length, and the one place where the application's own lengths meet a rig's units.

A rig knows its units (``Rig.units``: 'cm', 'mm' or 'm'; glTF is metres). Every length the application chooses
rather than reads — the take solve's defaults (RBF kernel length, phantom ring, head-motion noise, warp length,
and the weights of terms that are squared lengths: λ_t, λ_s, λ_r, λ_a), the drag solve's λ_r, the nudge step,
the automatic marker map's distances — is a physical quantity, written in centimetres (cm, cm² for the
weights of squared lengths), and converted to the rig's units here. So the same face solves to the same
weights whether it was written in metres, centimetres or millimetres (``tests/test_units.py``).
"""
from __future__ import annotations

from .errors import RigInputError

UNITS = ("cm", "mm", "m")
UNIT_IN_METRES = {"mm": 0.001, "cm": 0.01, "m": 1.0}


def unit_scale(from_units: str, to_units: str) -> float:
    """Factor that converts a length in ``from_units`` to ``to_units``."""
    for u in (from_units, to_units):
        if u not in UNIT_IN_METRES:
            raise RigInputError(f"Unknown units '{u}': use one of {', '.join(UNIT_IN_METRES)}.")
    return UNIT_IN_METRES[from_units] / UNIT_IN_METRES[to_units]


def in_units(value_cm: float, units: str, power: int = 1) -> float:
    """A physical quantity given in cm^power (a length for 1, the weight of a squared length for 2, a
    dimensionless number for 0) in ``units``^power."""
    return float(value_cm) * unit_scale("cm", units) ** power if power else float(value_cm)


def length(cm: float, units: str) -> float:
    """A length given in centimetres, in ``units``."""
    return in_units(cm, units, 1)


def area(cm2: float, units: str) -> float:
    """A squared length (or the weight of one, such as a regularisation λ against marker misfits²) given in
    cm², in ``units``²."""
    return in_units(cm2, units, 2)


def take_solver_options(options: dict, units: str) -> dict:
    """The take solver's options (``solvers.take_solve.TakeSolver``) for a rig in ``units``: ``options`` give
    physical values (lengths in cm, weights of squared lengths in cm², ``solvers.take_solve.DEFAULTS``); every
    length option, given or left to its default, comes back converted (``solvers.take_solve.option_length_power``).
    The other options pass through."""
    from solvers.take_solve import DEFAULTS, LENGTH_OPTIONS, option_length_power
    out = dict(options)
    residual = out.get("residual") or DEFAULTS["residual"]
    for name in LENGTH_OPTIONS:
        value = out.get(name)
        out[name] = in_units(DEFAULTS[name] if value is None else value, units, option_length_power(name, residual))
    return out
