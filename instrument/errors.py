"""The one exception type for a user's mistake: the CLI prints it as a single line and exits 1."""


class UserError(Exception):
    """Bad input from the user (a file, an option, a control). Its message is shown as is."""


def located(path: object, message: str, line: int | None = None) -> UserError:
    """A UserError whose text starts with `file:line:` so an editor can jump to it."""
    where = f"{path}:{line}" if line is not None else f"{path}"
    return UserError(f"{where}: {message}")
