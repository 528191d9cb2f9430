"""Reading option values the way every subcommand does: a bad value is one line naming the option."""

from __future__ import annotations

from ..errors import UserError


def number(option: str, text: str, kind=float):
    """`text` as a finite float (or int with kind=int), or a UserError naming `option`."""
    try:
        value = kind(text)
    except ValueError:
        raise UserError(f"{option}: not a {'whole ' if kind is int else ''}number: {text!r}") from None
    if kind is float and value != value or value in (float("inf"), float("-inf")):
        raise UserError(f"{option}: not a finite number: {text!r}")
    return value
