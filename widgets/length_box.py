"""A spin box that holds a length in the rig's units: when the units change, it keeps the same physical length
(its value, range and decimals converted by ``model.units``) and says the new units."""
from __future__ import annotations

import math

from PySide6 import QtWidgets

from model.units import unit_scale


def show_length_in(box: QtWidgets.QDoubleSpinBox, units: str) -> None:
    """Show ``box``'s length in ``units``. The box starts in centimetres (its value a physical default in cm, as
    ``model.units`` writes them); each call converts from the units it shows to ``units``."""
    old = box.property("length_units") or "cm"
    box.setSuffix(f" {units}")
    box.setProperty("length_units", units)
    if old == units:
        return
    f = unit_scale(old, units)
    value, lo, hi = box.value() * f, box.minimum() * f, box.maximum() * f
    box.blockSignals(True)
    box.setDecimals(max(0, box.decimals() - round(math.log10(f))))
    box.setRange(lo, hi)
    box.setSingleStep(box.singleStep() * f)
    box.setValue(value)
    box.blockSignals(False)


def length_units(box: QtWidgets.QDoubleSpinBox) -> str:
    """The units ``box`` shows (cm until ``show_length_in`` set others)."""
    return box.property("length_units") or "cm"
