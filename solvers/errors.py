"""The one error type the readers, the model and the solvers raise: one clear sentence naming the file
(or the argument) and the problem. It lives here, at the bottom of the dependency chain
(app -> widgets -> model -> solvers), so solvers need nothing from model; ``model.errors`` re-exports it."""


class RigInputError(ValueError):
    """Bad input: the message is one sentence a user can act on (file and problem)."""


def shown(value, limit: int = 60) -> str:
    """``value`` as it goes into a one-sentence message: a hostile file can hold a name a megabyte long."""
    text = str(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def repeated(items) -> list[str]:
    """The items that occur more than once, sorted, as a "duplicate ..." sentence lists them: one pass
    (``collections.Counter``), not ``list.count`` per item, which took minutes on 10⁵ names."""
    from collections import Counter
    return sorted(item for item, n in Counter(items).items() if n > 1)
