"""Reading TOML files (mappings, manifests, show files) with one-line errors naming the file."""

from __future__ import annotations

import json
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
