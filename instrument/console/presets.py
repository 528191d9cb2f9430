"""Presets written as the TOML the CLI reads (`--presets FILE`, or a show file's [presets.NAME]).

A save replaces the file whole, so it only ever replaces a file that holds nothing but presets:
a show file or a mapping given to --presets by mistake is refused, at start and at every save,
rather than lost."""

from __future__ import annotations

import contextlib
import os
import tomllib
from pathlib import Path

from ..errors import UserError

HEADER = "# presets saved by the instrument's console: [presets.NAME] tables of target = value"
# what a TOML basic string cannot hold as itself: the control characters, DEL, the quote and the backslash
ESCAPES = {**{c: f"\\u{c:04x}" for c in (*range(0x20), 0x7F)}, ord('"'): '\\"', ord("\\"): "\\\\",
           ord("\b"): "\\b", ord("\t"): "\\t", ord("\n"): "\\n", ord("\f"): "\\f", ord("\r"): "\\r"}


def toml_string(text: str) -> str:
    """`text` as a TOML basic string. Every other character is written as itself (UTF-8): JSON's
    escapes are not TOML's (a character beyond U+FFFF becomes a surrogate pair, which TOML refuses)."""
    return '"' + text.translate(ESCAPES) + '"'


def presets_toml(presets: dict[str, dict[str, float]]) -> str:
    lines = [HEADER, ""]
    for name in sorted(presets):
        lines.append(f"[presets.{toml_string(name)}]")
        lines += [f"{toml_string(target)} = {round(value, 6)!r}" for target, value in presets[name].items()]
        lines.append("")
    return "\n".join(lines)


def check_presets_file(path: str | Path) -> None:
    """Refuse a file a save must not replace: one holding anything besides [presets.NAME] tables
    (a show file, a mapping). A file that does not exist yet, or is empty, is fine."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise UserError(f"{path}: cannot read it as a presets file ({getattr(error, 'strerror', None) or error}); "
                        "a save would replace it") from None
    other = sorted(key for key in data if key != "presets")
    if other:
        raise UserError(f"{path}: holds more than presets ({', '.join(other[:4])}): a save from the console would "
                        "replace the whole file; give --presets a file of its own")


def save_presets(path: str | Path, presets: dict[str, dict[str, float]]) -> None:
    """Replace `path` whole (written beside it, then renamed: a crash never leaves half a file),
    once it is known to hold only presets."""
    path = Path(path)
    check_presets_file(path)
    temporary = path.with_name(f".{path.name}.saving")
    try:
        with open(temporary, "w", encoding="utf-8") as out:
            out.write(presets_toml(presets))
            out.flush()
            os.fsync(out.fileno())  # on the disk before it replaces the old file: a power cut keeps one of the two
        os.replace(temporary, path)
    except OSError as e:  # a full disk, a read-only folder: the old file stays as it was
        with contextlib.suppress(OSError):
            temporary.unlink()
        raise UserError(f"{path}: cannot save presets: {e.strerror or e}") from None
