"""Errors the readers and the model raise: one clear sentence naming the file and the problem."""


class RigInputError(ValueError):
    """Bad input: the message is one sentence a user can act on (file and problem)."""
