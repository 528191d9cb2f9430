"""Reading OSC packets from control surfaces: strict, lazy, and never raising.

A packet is a message or a bundle of elements (messages or nested bundles). `messages` walks a
packet lazily, so a 65 kB bundle of thousands of messages can be taken a few at a time between
frames; `first_number` reads a message's address and its first argument. Anything malformed
ends the walk of that packet with `Malformed`, which the input counts and warns about once.
Values are numbers, or a string (`first_string`) a target with named values takes for its
number (`/walk/gait s "run"`, control/spec.py `Row.number`); a blob, nil, boolean or missing
argument is refused rather than read as 1.0. A control takes one value: arguments after the
first (`extra_tags`) are left, and the input says so.
"""

from __future__ import annotations

import struct
from typing import Iterator

BUNDLE = b"#bundle\0"
MAX_DEPTH = 8  # nested bundles deeper than this are malformed (a crafted packet cannot recurse far)
NUMBERS = {ord("i"): (">i", 4), ord("f"): (">f", 4), ord("d"): (">d", 8), ord("h"): (">q", 8)}


class Malformed(ValueError):
    """The packet is not OSC."""


def messages(data: bytes, depth: int = 0) -> Iterator[bytes]:
    """Each message of a packet in order, as bytes (lazily: a bundle is split as it is walked)."""
    if not data.startswith(b"#"):
        yield data
        return
    if not data.startswith(BUNDLE) or len(data) < 16 or depth >= MAX_DEPTH:
        raise Malformed("not a bundle")
    at = 16  # "#bundle\0" and the time tag
    while at < len(data):
        if at + 4 > len(data):
            raise Malformed("bundle element size cut off")
        (size,) = struct.unpack_from(">i", data, at)
        at += 4
        if size <= 0 or size % 4 or at + size > len(data):
            raise Malformed("bundle element size wrong")
        element = data[at: at + size]
        at += size
        if element.startswith(b"#"):
            yield from messages(element, depth + 1)
        else:
            yield element


def _string(data: bytes, at: int) -> tuple[str, int]:
    """An OSC string at `at` and where the next field starts."""
    end = data.find(b"\0", at)
    if end < 0:
        raise Malformed("string not terminated")
    try:
        text = data[at:end].decode("utf-8")
    except UnicodeDecodeError:
        raise Malformed("string not UTF-8") from None
    return text, (end + 4) & ~3


def _head(message: bytes) -> tuple[str, str, int]:
    """(address, the arguments' type tags ('' if none), where the arguments start)."""
    if not message.startswith(b"/"):
        raise Malformed("address does not start with /")
    address, at = _string(message, 0)
    if at >= len(message):
        return address, "", at  # no type tags at all (old senders): no argument
    tags, at = _string(message, at)
    if not tags.startswith(","):
        raise Malformed("type tags do not start with ,")
    return address, tags[1:], at


def first_number(message: bytes) -> tuple[str, float | None, str]:
    """(address, first argument if it is a number else None, its type tag or '' if none)."""
    address, tags, at = _head(message)
    tag = tags[:1]
    if not tag:
        return address, None, ""
    spec = NUMBERS.get(ord(tag))
    if spec is None:
        return address, None, tag
    fmt, size = spec
    if at + size > len(message):
        raise Malformed("argument cut off")
    return address, float(struct.unpack_from(fmt, message, at)[0]), tag


def first_string(message: bytes) -> str:
    """The first argument of a message whose type tag is 's' (`first_number` said so)."""
    _, tags, at = _head(message)
    if tags[:1] != "s":
        raise Malformed("the first argument is not a string")
    return _string(message, at)[0]


def extra_tags(message: bytes) -> str:
    """The type tags of the arguments after the first ('' when there are none)."""
    return _head(message)[1][1:]
