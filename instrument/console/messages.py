"""What a page may send, checked in one place before anything reaches the control state.

A page sends JSON objects, one a WebSocket message:

    {"set": "style/elderly", "value": 1.2}   a target of the control state (clamped by the state)
    {"preset": "calm"}                       recall a preset (over the morph time: the target "morph")
    {"store": "calm"}                        store the current values as preset "calm"
    {"save": true}                           write the presets to the preset file

Anything else (not JSON, unknown keys or targets, wrong types, names with odd characters) is
refused with a reason; it never reaches the frame loop.
"""

from __future__ import annotations

import json
import math

from ..control.targets import PRESET_NAME

MAX_MESSAGE = 4096  # bytes: the largest message a page has any reason to send


class Refused(ValueError):
    """A page's message that is not acted on; the text says why."""


def parse(text: str, targets: frozenset[str]) -> tuple[str, str, float]:
    """One page message as (kind, control, value) for the control hub, or Refused.

    kind is "event" (a control event: control and value) or "save"."""
    if len(text) > MAX_MESSAGE:
        raise Refused("message too long")
    try:
        item = json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        raise Refused("not JSON") from None
    if not isinstance(item, dict):
        raise Refused("expected a JSON object")
    if set(item) == {"set", "value"}:
        target, value = item["set"], item["value"]
        if not isinstance(target, str) or target not in targets:
            raise Refused(f"unknown target {str(target)[:60]!r}")
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
            raise Refused(f"{target}: value must be a finite number")
        return "event", target, float(value)
    if len(item) == 1 and ("preset" in item or "store" in item):
        kind, name = next(iter(item.items()))
        if not isinstance(name, str) or not PRESET_NAME.fullmatch(name):
            raise Refused(f"{kind}: a name of 1 to 40 letters, digits, '_', '.', '-'")
        return "event", f"{kind}/{name}", 1.0
    if set(item) == {"save"} and item["save"] is True:
        return "save", "", 0.0
    raise Refused(f"unknown message {sorted(item)[:4]}")
