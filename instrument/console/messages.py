"""What a page may send, checked in one place before anything reaches the control state.

A page sends JSON objects, one a WebSocket message:

    {"set": "style/elderly", "value": 1.2}   a target of the control state, inside its range
    {"set": "gait", "value": "run"}          a target with named values: the name or its number
    {"preset": "calm"}                       recall a preset (over the morph time: the target "morph")
    {"store": "calm"}                        store the current values as preset "calm"
    {"save": true}                           write the presets to the preset file

Anything else (not JSON, unknown keys or targets, wrong types, values out of range, names with
odd characters) is refused with a reason, the same a file or OSC would get (control/checks.py);
it never reaches the frame loop.
"""

from __future__ import annotations

from ..control.checks import row_of, unknown, value_refusal
from ..control.spec import PRESET_NAME, TABLE
from ..textfile import NotJson, parse_json

MAX_MESSAGE = 4096  # bytes: the largest message a page has any reason to send


class Refused(ValueError):
    """A page's message that is not acted on; the text says why."""


def parse(text: str, targets: frozenset[str]) -> tuple[str, str, float]:
    """One page message as (kind, control, value) for the control hub, or Refused.

    kind is "event" (a control event: control and value) or "save". `targets` are the model's
    (ControlState.targets); each value goes through the one check of every input (control/checks.py),
    so the page refuses what a file, OSC or a log would."""
    if len(text) > MAX_MESSAGE:
        raise Refused("message too long")
    try:
        item = parse_json(text)
    except NotJson:
        raise Refused("not JSON") from None
    if not isinstance(item, dict):
        raise Refused("expected a JSON object")
    if set(item) == {"set", "value"}:
        target, value = item["set"], item["value"]
        row = TABLE[target.split("/")[0]] if isinstance(target, str) and target in targets else None  # the model's
        if row is None or row.kind in ("preset", "store"):
            raise Refused(unknown(target, [t[len("style/"):] for t in targets if t.startswith("style/")]).text)
        why = value_refusal(row, target, value)
        if why is not None:
            raise Refused(why.text)
        return "event", target, float(row.number(value))  # gait's "run" as its 2
    if len(item) == 1 and ("preset" in item or "store" in item):
        kind, name = next(iter(item.items()))
        if not isinstance(name, str) or not PRESET_NAME.fullmatch(name):
            raise Refused(f"{kind}: a name of 1 to 40 letters, digits, '_', '.', '-'")
        target = f"{kind}/{name}"
        if row_of(target, (), 0) is None:
            raise Refused(unknown(target).text)
        return "event", target, 1.0
    if set(item) == {"save"} and item["save"] is True:
        return "save", "", 0.0
    raise Refused(f"unknown message {sorted(item)[:4]}")

