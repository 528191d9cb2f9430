"""Reading TOML files (mappings, manifests, show files, presets, scores) with one-line errors
naming the file, and the line and key at fault (`TomlFile.error`)."""

from __future__ import annotations

import json
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from .errors import UserError, printable, quoted
from .textfile import read_text

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def toml_string(text: str) -> str:
    """`text` as a TOML basic string: quotes, backslashes and control characters escaped (JSON's
    escapes are TOML's), so a port name like `Port\\1 "A"` reads back as itself."""
    return json.dumps(text, ensure_ascii=False)


def parse_toml(text: str, path: str | Path) -> dict:
    """TOML text read from `path` (named in the one-line error)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:  # "... (at line 3, column 7)", or "(at end of document)": its last line
        found = re.search(r"\(at line (\d+), column \d+\)$", str(e))
        line = int(found.group(1)) if found else max(1, len(text.rstrip().splitlines()))
        raise UserError(f"{path}:{line}: {e}") from None
    except RecursionError:  # arrays or inline tables nested deeper than Python's stack
        raise UserError(f"{path}: arrays or tables nested too deeply") from None
    except ValueError:  # int() refused a number of more digits than Python converts
        limit = sys.get_int_max_str_digits()
        digits = re.search(r"[0-9_]{%d,}" % (limit + 1), text)
        line = text.count("\n", 0, digits.start()) + 1 if digits else 1
        raise UserError(f"{path}:{line}: a number of more than {limit} digits") from None


Key = tuple  # a key's path in the parsed data: names, and indices of arrays (of tables)


def key_lines(text: str) -> dict[Key, int]:
    """The 1-based line where each key of the TOML `text` (already parsed without error) is
    written, by its path in the parsed data: ("presets", "calm", "style/elderly"), ("cue", 2,
    "ramp", "speed"), ("osc", 1) for an array's element. Found by reading the TOML's structure
    (tables, arrays of tables, dotted and quoted keys, inline tables, strings, comments), so a
    comment or a string mentioning a key never matches. The first place a path is written wins.
    Values nested deeper than Python's stack keep the lines found before them."""
    scanner = _KeyScanner(text)
    try:
        scanner.scan()
    except RecursionError:
        pass
    return scanner.lines


class _KeyScanner:
    """A reader of TOML's structure that notes where each key is: the values themselves are
    tomllib's (this only skips over them)."""

    def __init__(self, text: str):
        self.text, self.at, self.line = text, 0, 1
        self.lines: dict[Key, int] = {}
        self.arrays: dict[Key, int] = {}  # an array of tables -> how many tables it has so far
        self.prefix: Key = ()

    def scan(self) -> None:
        while self._skip(newlines=True) < len(self.text):
            self._statement()

    def _note(self, path: Key, line: int) -> None:
        self.lines.setdefault(path, line)

    def _peek(self, count: int = 1) -> str:
        return self.text[self.at: self.at + count]

    def _advance(self, count: int = 1) -> None:
        self.line += self.text.count("\n", self.at, self.at + count)
        self.at += count

    def _skip(self, newlines: bool) -> int:
        """Past whitespace and comments (and newlines, if asked); the position reached."""
        while self.at < len(self.text):
            char = self.text[self.at]
            if char in " \t\r" or (newlines and char == "\n"):
                self._advance()
            elif char == "#":
                end = self.text.find("\n", self.at)
                self._advance((len(self.text) if end < 0 else end) - self.at)
            else:
                break
        return self.at

    def _resolved(self, names: Key) -> Key:
        """A table path with each array of tables on it replaced by its newest table."""
        path: Key = ()
        for name in names:
            path += (name,)
            if path in self.arrays:
                path += (self.arrays[path] - 1,)
        return path

    def _statement(self) -> None:
        line = self.line
        if self._peek(2) == "[[":
            self._advance(2)
            names = self._key()
            self._skip(False)
            self._advance(2)  # ]]
            array = self._resolved(names[:-1]) + names[-1:]
            self.arrays[array] = self.arrays.get(array, 0) + 1
            self._note(array, line)
            self.prefix = array + (self.arrays[array] - 1,)
            self._note(self.prefix, line)
        elif self._peek() == "[":
            self._advance()
            names = self._key()
            self._skip(False)
            self._advance()  # ]
            self.prefix = self._resolved(names)
            for k in range(1, len(self.prefix) + 1):
                self._note(self.prefix[:k], line)
        else:
            self._pair(self.prefix)

    def _pair(self, prefix: Key) -> None:
        """key = value, noting the key (and each part of a dotted key) under `prefix`."""
        line = self.line
        names = self._key()
        for k in range(1, len(names) + 1):
            self._note(prefix + names[:k], line)
        self._skip(False)
        self._advance()  # =
        self._value(prefix + names)

    def _key(self) -> Key:
        """A dotted key: its names, unquoted."""
        names = []
        while True:
            self._skip(False)
            char = self._peek()
            if char in "\"'":
                names.append(self._string(decode=True))
            else:
                start = self.at
                while self.at < len(self.text) and (self.text[self.at].isalnum() or self.text[self.at] in "_-"):
                    self._advance()
                names.append(self.text[start: self.at])
            self._skip(False)
            if self._peek() != ".":
                return tuple(names)
            self._advance()

    def _string(self, decode: bool = False) -> str:
        """Past a string of any of TOML's four kinds; its value when `decode` (keys: one line)."""
        start = self.at
        quote = self._peek()
        if self._peek(3) == quote * 3:
            end = self.text.find(quote * 3, self.at + 3)
            while self.text.startswith(quote, end + 3):  # up to two quotes may end the content
                end += 1
            if quote == '"':
                while self._escaped(end):
                    end = self.text.find(quote * 3, end + 1)
            self._advance(end + 3 - self.at)
        else:
            end = self.text.find(quote, self.at + 1)
            while quote == '"' and self._escaped(end):
                end = self.text.find(quote, end + 1)
            self._advance(end + 1 - self.at)
        raw = self.text[start: self.at]
        return tomllib.loads(f"k = {raw}")["k"] if decode else raw

    def _escaped(self, at: int) -> bool:
        backslashes = 0
        while at - 1 - backslashes >= 0 and self.text[at - 1 - backslashes] == "\\":
            backslashes += 1
        return backslashes % 2 == 1

    def _value(self, path: Key) -> None:
        self._skip(False)
        char = self._peek()
        if char in "\"'":
            self._string()
        elif char == "[":
            self._advance()
            index = 0
            while self._skip(newlines=True) < len(self.text) and self._peek() != "]":
                self._note(path + (index,), self.line)
                self._value(path + (index,))
                self._skip(newlines=True)
                if self._peek() == ",":
                    self._advance()
                index += 1
            self._advance()  # ]
        elif char == "{":
            self._advance()
            while self._skip(newlines=True) < len(self.text) and self._peek() != "}":
                self._pair(path)
                self._skip(newlines=True)
                if self._peek() == ",":
                    self._advance()
            self._advance()  # }
        else:  # a number, a boolean, a date: up to where the value ends
            while self.at < len(self.text) and self.text[self.at] not in ",]}\n#":
                self._advance()


@dataclass(frozen=True)
class Field:
    """What one key of a file's table takes: its type, and for a number its range. A file's
    schema is a dict of key -> Field; `TomlFile.check` reads a table against it. (Control
    targets are checked by their rows instead: control/presetfile.py.)"""

    kind: str  # "number" (real), "whole", "bool", "string", "choice", "list", "table", "value" (a number or a name),
    #            "tables" (a list of tables, each written [[key]])
    low: float | None = None
    high: float | None = None
    above_low: bool = False  # low itself refused (> low)
    below_high: bool = False  # high itself refused (< high)
    choices: tuple[str, ...] = ()
    units: str = ""  # what a number counts, for the message ("seconds")
    required: str = ""  # when required: what the key is for, said when it is missing

    def describe(self) -> str:
        if self.kind in ("number", "whole"):
            text = ("a whole number" if self.kind == "whole" else "a number") + (f" of {self.units}" if self.units else "")
            low = None if self.low is None else f"{self.low:g}"
            high = None if self.high is None else f"{self.high:g}"
            if low is not None and high is not None:
                return f"{text} from {low}{' (not included)' if self.above_low else ''} to {high}" \
                       + (" (not included)" if self.below_high else "")
            if low is not None:
                return f"{text} above {low}" if self.above_low else f"{text}, {low} or more"
            return text
        return {"bool": "true or false", "string": "a string", "list": "a list", "table": "a table",
                "tables": "a list of tables", "value": "a number or a name"}.get(
            self.kind, f"one of {', '.join(self.choices)}")

    def problem(self, value: object) -> str | None:
        """Why `value` does not fit, or None."""
        if self.kind == "choice":
            return None if value in self.choices else f"{quoted(value)} is not one of {', '.join(self.choices)}"
        fits = {"bool": lambda: isinstance(value, bool), "string": lambda: isinstance(value, str),
                "list": lambda: isinstance(value, list), "tables": lambda: isinstance(value, list),
                "table": lambda: isinstance(value, dict),
                "value": lambda: isinstance(value, str) or (isinstance(value, (int, float)) and not isinstance(value, bool)
                                                            and math.isfinite(value)),  # the target's row checks it
                "whole": lambda: isinstance(value, int) and not isinstance(value, bool) and self._inside(value),
                "number": lambda: isinstance(value, (int, float)) and not isinstance(value, bool)
                and math.isfinite(value) and self._inside(value)}[self.kind]
        try:
            return None if fits() else f"expected {self.describe()}"
        except OverflowError:  # an integer too large for a float
            return f"expected {self.describe()}"

    def _inside(self, value: float) -> bool:
        if self.low is not None and (value <= self.low if self.above_low else value < self.low):
            return False
        return self.high is None or (value < self.high if self.below_high else value <= self.high)


class TomlFile:
    """A TOML file read whole: its parsed `data`, and one-line errors `file:line: key: problem`
    naming the line where the key is written (`key_lines`)."""

    def __init__(self, path: str | Path, text: str | None = None):
        self.path = str(path)
        self.text = read_text(path) if text is None else text
        self.data = parse_toml(self.text, path)
        self._lines: dict[Key, int] | None = None

    @property
    def lines(self) -> dict[Key, int]:
        """`key_lines` of the text (found when first asked: only an error needs them)."""
        if self._lines is None:
            self._lines = key_lines(self.text)
        return self._lines

    def line(self, *path: str | int) -> int:
        """The line of the key at `path`, else of the nearest table above it that is written; 1 at worst."""
        for k in range(len(path), 0, -1):
            if path[:k] in self.lines:
                return self.lines[path[:k]]
        return 1

    def check(self, path: Key, table: object, schema: dict[str, Field], prefix: str = "") -> dict:
        """`table` (found at `path`) read against `schema`: an unknown key, a missing one or a
        value that does not fit is a UserError naming the line and the key (shown after
        `prefix`, e.g. "attract."). Checks that span keys are the caller's."""
        if not isinstance(table, dict):
            raise self.error(path, "expected a table", prefix.rstrip(".") or None)
        for key, value in table.items():
            field = schema.get(key)
            if field is None:
                raise self.error(path + (key,), f"unknown key (expected one of {', '.join(schema)})", prefix + key)
            if field.kind == "tables" and isinstance(value, dict):  # [cue] written where each cue is a [[cue]]
                name = prefix + key
                raise self.error(path + (key,), f"write each {key} as [[{name}]] (a table of its own), not [{name}]", name)
            problem = field.problem(value)
            if problem is not None:
                raise self.error(path + (key,), problem, prefix + key)
        for key, field in schema.items():
            if field.required and key not in table:
                raise self.error(path + (key,), f"missing: {field.required}", prefix + key)
        return table

    def error(self, path: Key, problem: str, key: str | None = None) -> UserError:
        """`file:line: key: problem`, the key shown as `key` or its names joined by dots."""
        shown = key if key is not None else ".".join(str(p) for p in path if not isinstance(p, int))
        shown = printable(shown, 80)  # a key of 140 kB, or one with a newline, stays one readable line
        return UserError(f"{self.path}:{self.line(*path)}: {shown}: {problem}" if shown else
                         f"{self.path}:{self.line(*path)}: {problem}")
