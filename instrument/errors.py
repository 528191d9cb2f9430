"""The one exception type for a user's mistake: the CLI prints it as a single line and exits 1."""

import sys
from collections.abc import Callable
from pathlib import Path


class UserError(Exception):
    """Bad input from the user (a file, an option, a control). Its message is shown as is."""


def quoted(value: object, limit: int = 40) -> str:
    """A user's value as an error message quotes it (repr), cut short: a 5000-digit number or a
    140 kB string in a file stays a readable line. A boolean as the files and messages spell it
    (TOML's and JSON's `true`), not as Python does."""
    text = ("true" if value else "false") if isinstance(value, bool) else repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def printable(text: str, limit: int = 60) -> str:
    """A name from a user's file or message as an error shows it (unquoted), cut short and with
    characters that are not printable escaped: a newline in a key keeps the error one line."""
    text = text[:limit] + ("..." if len(text) > limit else "")
    return text if text.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def located(path: object, message: str, line: int | None = None) -> UserError:
    """A UserError whose text starts with `file:line:` so an editor can jump to it."""
    where = f"{path}:{line}" if line is not None else f"{path}"
    return UserError(f"{where}: {message}")


def run_script(main: Callable[[], None], script: str) -> None:
    """Run an example script's main as the CLI runs a command: a UserError is one line naming the
    script on stderr and exit status 1, never a traceback."""
    try:
        main()
    except UserError as error:
        print(f"{Path(script).name}: error: {error}", file=sys.stderr)
        raise SystemExit(1) from None
