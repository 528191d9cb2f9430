"""The motion units a model may hold, in the order a model stores them.

Each unit has a right and a left step's labels (label = 2 * unit + foot; a stand's "steps" are
pieces of still standing, motion/standing.py). A model trained on walks alone holds only "walk"
(and its metadata may not even say so: `Model.units`).
"""

UNITS = ("walk", "run", "turn-left", "turn-right", "stand")

# the gestures a model may hold, in the order it stores them after the units' labels
# (models/gestures.py: where; the `gesture/<name>` targets). Here, in a module that imports
# nothing, so the control table can name them without loading the numerical code.
GESTURES = ("wave", "raise")


def named_by_words(content: str, table: tuple[tuple[tuple[str, ...], str], ...]) -> str | None:
    """The name a file's content part says by the first (words, name) row of `table` one of whose
    words it holds, in any case (`walk-turn-left` -> turn-left, `wave-both-hands` -> wave), or None."""
    lowered = content.lower()
    return next((name for words, name in table if any(word in lowered for word in words)), None)
