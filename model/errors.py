"""Errors the readers and the model raise: one clear sentence naming the file and the problem.

The type itself is defined in ``solvers.errors`` (solvers import nothing from model); this is its name for
model/ and app/."""
from solvers.errors import RigInputError, repeated, shown

__all__ = ["RigInputError", "repeated", "shown"]
