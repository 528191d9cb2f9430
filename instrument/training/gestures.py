"""What training does for gestures (models/gestures.py): each gesture take's phases as segments
of the gesture's four labels, trained beside the units' (the same average model and style
adaptation, so style weights, exaggeration and inversion apply to a wave as to a walk)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..models.gestures import GESTURES
from ..motion.gestures import PHASES
from .corpus import Take


def model_gestures(takes: Sequence[Take]) -> list[str]:
    """The gestures the takes perform (those with phases), in GESTURES' order."""
    present = {t.gesture for t in takes if t.gesture and t.phases}
    return [g for g in GESTURES if g in present]


def gesture_segments(takes: Sequence[Take], states: int, gestures: Sequence[str]) -> list[list[np.ndarray]]:
    """For each gesture and each of its phases (PHASES' order), the observation segments of the
    takes' phases long enough for every state."""
    return [[take.observations[s.start:s.end] for take in takes if take.gesture == gesture
             for s in take.phases if s.label == phase and s.frames >= states]
            for gesture in gestures for phase in PHASES]


def gesture_metadata(takes: Sequence[Take], gestures: Sequence[str], first: int) -> dict:
    """The model's "gestures" entry: each gesture's first label (after the `first` labels before
    it) and the half cycles of repeat its takes hold (the median: what a tap plays)."""
    entry = {}
    for k, gesture in enumerate(gestures):
        counts = [sum(s.label.startswith("repeat") for s in t.phases) for t in takes if t.gesture == gesture and t.phases]
        entry[gesture] = {"first": first + len(PHASES) * k, "repeats": max(2, int(np.median(counts)))}
    return entry
