"""The gestures a model may hold (layered on the gait's upper body: synthesis/gestures.py), and
where a model keeps them.

A gesture has four labels, stored after the units' (label = 2 * unit + foot) in the same arrays:
its lower and its raise, then the two halves of its repeat (a sway one way and back, or two
pieces of a hold), as two of the planner's pairs (motion/gestures.py PHASES). The metadata entry "gestures" maps each gesture's name to its
first label and the number of half cycles its takes repeat (a tap plays that many); a model
without the entry has no gestures and works as before.
"""

from __future__ import annotations

from ..motion.gestures import PHASES
from .units import GESTURES, named_by_words  # noqa: F401  (GESTURES: the gestures' names, with the units')

GESTURE_WORDS = ((("wave",), "wave"), (("raise", "hands-up", "hands_up"), "raise"))


def gesture_of_words(content: str) -> str | None:
    """The gesture a take's content name says (`wave-both-hands` -> wave), or None."""
    return named_by_words(content, GESTURE_WORDS)


def gesture_labels(metadata: dict) -> dict[str, list[int]]:
    """{gesture: its four labels (PHASES' order)} of a model's metadata; {} without gestures."""
    entry = metadata.get("gestures") or {}
    return {name: [int(g["first"]) + k for k in range(len(PHASES))] for name, g in entry.items()}


def gesture_repeats(metadata: dict) -> dict[str, int]:
    """{gesture: half cycles of its repeat that a tap plays}."""
    return {name: int(g.get("repeats", 2)) for name, g in (metadata.get("gestures") or {}).items()}
