"""One rule for every file a command writes.

Before any work: the folder must exist, the path must not be a folder, and an existing file is
only replaced when the user said --force. While writing: the data goes to NAME.part, renamed onto
NAME once complete, so an interrupted or failed command never leaves half a file in place of a
good one (and the .part is removed on failure). Live recordings (run --bvh, --record) are the
exception: they are written in place, valid after every frame, so a killed run keeps its take.

`write_all` is the one way to write bytes to a file descriptor: a full disk or a file size limit
makes the kernel write part of the data and refuse the rest, which a bare `os.write` ignores.
"""

from __future__ import annotations

import errno
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import UserError


def check_output(path: str | Path, force: bool, inputs: tuple[str | Path, ...] = ()) -> Path:
    """`path` if a command may write there, else a one-line UserError saying why."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{path}: is a folder; give a file name")
    folder = path.parent
    if not folder.is_dir():
        raise UserError(f"{path}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise UserError(f"{path}: cannot write in {folder} (permission denied)")
    for source in inputs:
        if source is not None and Path(source).exists() and path.exists() and path.samefile(source):
            raise UserError(f"{path}: is also the input; write to another file")
    if path.exists() and not force:
        raise UserError(f"{path}: already exists; give --force to overwrite it")
    try:  # the folder may say writable and still refuse (/proc); a new name, so no file of the user's is touched
        handle, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=folder)
        os.close(handle)
        os.unlink(probe)
    except OSError as e:
        raise UserError(f"{path}: cannot write: {e.strerror or e}") from None
    return path


def write_all(fd: int, data: bytes) -> None:
    """Write every byte of `data` to `fd`, or raise OSError (ENOSPC when the kernel takes nothing
    more without saying why); what was written before the error stays written."""
    view = memoryview(data)
    while view:
        written = os.write(fd, view)
        if written == 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        view = view[written:]


@contextmanager
def written(path: str | Path) -> Iterator[Path]:
    """Yields PATH.part to write to; renamed onto PATH when the block ends well, removed if not."""
    path = Path(path)
    part = path.with_name(path.name + ".part")
    try:
        yield part
        os.replace(part, path)
    except OSError as e:
        part.unlink(missing_ok=True)
        raise UserError(f"{path}: cannot write: {e.strerror or e}") from None
    except BaseException:
        part.unlink(missing_ok=True)
        raise
