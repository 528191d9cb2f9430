"""The first line of a recorded controller log: the mappings in force while it was recorded,
and the crowd it played.

A log holds raw device events (`midi:...` cc/1/1 = 64); only a mapping says what they mean. The
header line carries each mapping's name, its TOML and that text's SHA-256, so `run --replay LOG`
reads the events exactly as the recording did, with no --mapping given and even after the
mapping file has changed or gone. A log of device events with no mapping to read them is an
error, not a silent replay of nothing. A crowd is a function of the controls, its size and its
spacing: the header carries the last two (`"crowd": {"characters": N, "spacing": METRES}`), so
`run --replay LOG` walks the same crowd without --characters or --spacing.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import located, printable, quoted
from ..textfile import NotJson, parse_json, read_text
from .events import RawEvent
from .kinds import unreadable_kinds
from .mapping import Mapping, load_mapping

if TYPE_CHECKING:
    from .state import ControlState

HEADER_KEY = "instrument_log"  # {"instrument_log": 1, "mappings": [...]}
VERSION = 1
PER_DEVICE = "per-device"  # the header's "decoders": each device had its own (before: one per kind)


def header_line(mappings: list[Mapping], characters: int = 1, spacing: float | None = None,
                per_device: bool = True) -> str:
    """The JSON header line (no newline) for a log recorded with these mappings (and, for a
    crowd, its size and spacing in metres), each device read by its own decoder (`per_device`)."""
    entries = [{"name": m.name, "file": m.path, "sha256": hashlib.sha256(m.text.encode("utf-8")).hexdigest(), "toml": m.text}
               for m in mappings]
    header: dict = {HEADER_KEY: VERSION, "mappings": entries}
    if per_device:
        header["decoders"] = PER_DEVICE
    if characters > 1:
        header["crowd"] = {"characters": characters, "spacing": spacing}
    return json.dumps(header, ensure_ascii=False)


def is_header(item: object) -> bool:
    return isinstance(item, dict) and HEADER_KEY in item


def _header(path: str | Path) -> tuple[dict | None, int]:
    """A log's header and its line number ((None, 0) for a log without one)."""
    for number, line in enumerate(read_text(path).splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            item = parse_json(line)
        except NotJson:
            return None, 0  # not a header: read_log names the bad line
        return (item, number) if is_header(item) else (None, 0)
    return None, 0


def logged_mappings(path: str | Path, state: ControlState | None = None) -> list[Mapping]:
    """The mappings a log's header carries (none for a log without a header)."""
    item, number = _header(path)
    if item is None:
        return []
    entries = item.get("mappings")
    if not isinstance(entries, list) or not all(isinstance(e, dict) and isinstance(e.get("toml"), str) for e in entries):
        raise located(path, "header: 'mappings' must be a list of objects with a 'toml' text", number)
    mappings = []
    for entry in entries:
        text = entry["toml"]
        if entry.get("sha256") != hashlib.sha256(text.encode("utf-8")).hexdigest():
            raise located(path, f"header: mapping {quoted(entry.get('name'))} does not match its sha256 (the log was edited)", number)
        mappings.append(load_mapping(f"{path}:{number}: mapping {printable(str(entry.get('name', '?')))}", state, text=text))
    return mappings


def logged_crowd(path: str | Path) -> tuple[dict, str]:
    """The crowd a log's header names, as raw {"characters": ..., "spacing": ...} for the
    caller to check against the options' table, and where it stands ({} when none)."""
    item, number = _header(path)
    crowd = None if item is None else item.get("crowd")
    if crowd is None:
        return {}, ""
    if not isinstance(crowd, dict) or set(crowd) - {"characters", "spacing"}:
        raise located(path, "header: 'crowd' must be an object with 'characters' and 'spacing'", number)
    return crowd, f"{path}:{number}: header crowd"


def logged_per_device(path: str | Path) -> bool:
    """Whether a log was recorded with a decoder per device (control/hub.py): a log recorded
    before (a header without "decoders", or none) is read as it was played, one per kind."""
    item, _ = _header(path)
    return item is not None and item.get("decoders") == PER_DEVICE


def unreadable_sources(events: list[RawEvent], mappings: list[Mapping]) -> list[str]:
    """Device kinds ("MIDI", "HID") that have events in the log but no mapping to read them
    (the rule the hub routes by: control/kinds.py)."""
    return unreadable_kinds({e.source for e in events}, mappings)
