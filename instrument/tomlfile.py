"""Reading TOML files (mappings, manifests, show files) with one-line errors naming the file."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from .errors import UserError
from .textfile import read_text

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def toml_string(text: str) -> str:
    """`text` as a TOML basic string: quotes, backslashes and control characters escaped (JSON's
    escapes are TOML's), so a port name like `Port\\1 "A"` reads back as itself."""
    return json.dumps(text, ensure_ascii=False)


def read_toml(path: str | Path) -> tuple[str, dict]:
    """The file's text (for finding the line of a bad key) and its parsed contents."""
    text = read_text(path)
    return text, parse_toml(text, path)


def parse_toml(text: str, path: str | Path) -> dict:
    """TOML text read from `path` (named in the one-line error)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise UserError(f"{path}: {e}") from None


def key_line(text: str, table: tuple[str, ...], key: str | None = None) -> int:
    """1-based line of `key = ...` inside the table named by `table` (for one-line errors): in
    its `[a.b]` section, else where `a.b = ...` or `a.b.key = ...` is written as a dotted key;
    names quoted or not. Without `key`, or a key not found, the table's own line; 1 when the
    table is not found either."""
    def name(part: str) -> str:
        return rf"""(?:{re.escape(part)}|"{re.escape(part)}"|'{re.escape(part)}')"""

    def dotted(parts: tuple[str, ...]) -> str:
        return r"[ \t]*\.[ \t]*".join(map(name, parts))

    def line(at: int) -> int:
        return text.count("\n", 0, at) + 1

    header = re.search(rf"^[ \t]*\[[ \t]*{dotted(table)}[ \t]*\][ \t]*(#.*)?$", text, re.MULTILINE)
    if header:
        following = re.compile(r"^[ \t]*\[", re.MULTILINE).search(text, header.end())
        end = following.start() if following else len(text)
        found = key is not None and re.compile(rf"(^|[{{,])[ \t]*{name(key)}[ \t]*=", re.MULTILINE).search(
            text, header.start(), end)
        return line(found.start() if found else header.start())
    for parts in ([table + (key,)] if key is not None else []) + [table]:
        found = re.search(rf"(^|[{{,])[ \t]*{dotted(parts)}[ \t]*=", text, re.MULTILINE)
        if found:
            return line(found.start() + len(found.group(1)))
    return 1
