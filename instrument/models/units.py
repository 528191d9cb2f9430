"""The motion units a model may hold, in the order a model stores them.

Each unit has a right and a left step's labels (label = 2 * unit + foot; a stand's "steps" are
pieces of still standing, motion/standing.py). A model trained on walks alone holds only "walk"
(and its metadata may not even say so: `Model.units`).
"""

from collections.abc import Sequence

UNITS = ("walk", "run", "turn-left", "turn-right", "stand")

# the gestures a model may hold, in the order it stores them after the units' labels
# (models/gestures.py: where; the `gesture/<name>` targets). Here, in a module that imports
# nothing, so the control table can name them without loading the numerical code.
GESTURES = ("wave", "raise")
JOINED = 8  # a unit word this long is two joined (turnleft): found anywhere in a name (`named_by_words`)


def unit_labels(units: Sequence[str], unit: str) -> range:
    """`unit`'s labels among a model's `units` (in its label order): its right and left step,
    label = 2 * unit + foot."""
    k = units.index(unit)
    return range(2 * k, 2 * k + 2)


def named_by_words(content: str, table: tuple[tuple[tuple[str, ...], str], ...]) -> str | None:
    """The name a file's content part says by the first (words, name) row of `table` one of whose
    words starts a word of it, in any case (`walk-turn-left` -> turn-left, `WalkTurnLeft` ->
    turn-left, `Running` -> run, `wave-both-hands` -> wave), or None. Inside a word a unit's word
    is not one: `forest-walk` holds "rest" and was read as a stand, `brunch` a run. A word of
    JOINED letters or more (turn-left's and turn-right's, two words in one: `turnleft`) is one
    anywhere, as no word of a name hides one: `WALKTURNLEFT` and `walkturnleft` show no word's
    start. Each character is lower-cased alone, so positions stay those of `content` (`İ` lowers
    to two characters)."""
    lowered = "".join(ch.lower()[0] for ch in content)
    return next((name for words, name in table
                 if any(word in lowered if len(word) >= JOINED else _starts_a_word(content, lowered, word) for word in words)),
                None)


def _starts_a_word(content: str, lowered: str, word: str) -> bool:
    """Whether `word` is found in `lowered` (`content` lower-cased) where a word of `content`
    starts: at its start, after a character that is no letter, or at a capital after a small letter."""
    at = lowered.find(word)
    while at >= 0:
        if at == 0 or not content[at - 1].isalpha() or (content[at].isupper() and content[at - 1].islower()):
            return True
        at = lowered.find(word, at + 1)
    return False
