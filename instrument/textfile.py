"""Reading a user's text file (mapping, show file, log, manifest) with one-line errors.

Text is UTF-8; a leading byte-order mark (Windows editors write one) is dropped. Anything else,
UTF-16 included, is refused naming the file and the line where the first bad byte is.
"""

from __future__ import annotations

from pathlib import Path

from .errors import UserError


def read_text(path: str | Path) -> str:
    """The file's text, or a UserError naming the file (and line) and what is wrong."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e.strerror or e}") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        utf16 = data[:2] in (b"\xff\xfe", b"\xfe\xff")
        raise UserError(f"{path}:{line}: not UTF-8 text" + ("; it is UTF-16: save it as UTF-8" if utf16 else "")) from None
