"""Reading a user's text file (mapping, show file, log, manifest) with one-line errors.

Text is UTF-8; a leading byte-order mark (Windows editors write one) is dropped. Anything else,
UTF-16 included, is refused naming the file and the line where the first bad byte is.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .errors import UserError


def read_text(path: str | Path, *, latin1_fallback: bool = False) -> str:
    """The file's text, or a UserError naming the file (and line) and what is wrong.

    With `latin1_fallback`, a file that is not UTF-8 is read as Latin-1 instead of refused: motion
    capture exporters write joint names in the machine's 8-bit code page, and every byte is a
    Latin-1 character, so the numbers still read and the names stay distinct."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e.strerror or e}") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        if latin1_fallback:
            return data.decode("latin-1")
        line = data[: e.start].count(b"\n") + 1
        utf16 = data[:2] in (b"\xff\xfe", b"\xfe\xff")
        raise UserError(f"{path}:{line}: not UTF-8 text" + ("; it is UTF-16: save it as UTF-8" if utf16 else "")) from None


class NotJson(ValueError):
    """A line of a user's file (a log, a page's message) that is not JSON; the text says why in a few words."""


def parse_json(text: str) -> object:
    """One JSON value, or NotJson: bad syntax, nesting too deep for Python's stack, or an integer
    of more digits than Python converts (sys.get_int_max_str_digits) are all "not JSON" to a user."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise NotJson(e.msg) from None
    except RecursionError:
        raise NotJson("nested too deeply") from None
    except ValueError:  # int() refused a number of too many digits
        raise NotJson(f"a number of more than {sys.get_int_max_str_digits()} digits") from None
