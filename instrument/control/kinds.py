"""Device kinds: the one rule saying which kind of device an event came from and which mappings
read that kind. The hub (which mapper an event goes to) and the log header reader (whether a
replay has a mapping for every device in the log) both ask here, so they cannot disagree.
"""

from __future__ import annotations

from typing import Callable

from .mapping import Mapping

# kinds whose raw events mean nothing without a mapping: kind -> (name in messages, whether a mapping reads it)
MAPPED: dict[str, tuple[str, Callable[[Mapping], bool]]] = {
    "midi": ("MIDI", lambda m: m.midi is not None),
    "hid": ("HID", lambda m: m.hid is not None or bool(m.hid_usages)),  # by vendor:product, or by usages
}


def kind_of(source: str) -> str:
    """The kind of device a source names: the part of "midi:nanoKONTROL2" before the first colon."""
    return source.partition(":")[0]


def reads(kind: str, mapping: Mapping) -> bool:
    """Whether `mapping` reads raw events of devices of this kind."""
    return kind in MAPPED and MAPPED[kind][1](mapping)


def title(kind: str) -> str:
    return MAPPED[kind][0] if kind in MAPPED else kind
