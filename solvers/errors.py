"""The one error type the readers, the model and the solvers raise: one clear sentence naming the file
(or the argument) and the problem. It lives here, at the bottom of the dependency chain
(app -> widgets -> model -> solvers), so solvers need nothing from model; ``model.errors`` re-exports it."""


class RigInputError(ValueError):
    """Bad input: the message is one sentence a user can act on (file and problem)."""


def shown(value, limit: int = 60) -> str:
    """``value`` as it goes into a one-sentence message: a hostile file can hold a name a megabyte long."""
    text = str(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"
