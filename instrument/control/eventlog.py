"""The --record controller log, written off the frame thread in batches, bounded in size.

The frame loop only appends an accepted event's line to a list; a writer thread takes the list
about every WRITE_EVERY seconds and writes it with one `os.write`, so whole lines reach the
file in order and a flood of events costs the frame loop no system calls. Closing writes what
is left, then the time the run stopped at (`end`, when the run says it: control.events), so a
replay plays the take to its end. A run killed outright loses at most the last WRITE_EVERY seconds, and a line it cut
is dropped with a warning when the log is read. The file stops growing at LIMIT bytes (about
2.5 hours of a 10,000 messages a second flood): the run goes on, and says so.

A disk that refuses a batch (full, a size limit, an I/O error) ends the recording at once: the
part of the batch that got written is cut off, so the log ends on a whole line; `warn` is told
in one line when it happens (not only at the end of the show), and the run goes on.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path

from ..errors import UserError
from ..outputfile import write_all
from .events import ControlEvent, end_line

WRITE_EVERY = 0.1  # seconds between two batches
LIMIT = 1 << 30  # bytes: a log never grows past this
PENDING_LIMIT = 1_000_000  # lines waiting for a stuck disk; more are counted as not recorded


class EventLog:
    def __init__(self, path: str | Path, header: str, replace: bool = False, warn: Callable[[str], None] | None = None):
        """A new log at `path` (an existing file only with `replace`), starting with `header`: the
        line that tells a replay what it needs (control.loghead). `warn` hears, from the writer
        thread, the one line saying the recording stopped."""
        self.path = Path(path)
        try:
            self.fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if replace else os.O_EXCL), 0o644)
        except FileExistsError:
            raise UserError(f"{self.path}: already exists; record to a new file, or give --force") from None
        except OSError as e:
            raise UserError(f"{self.path}: cannot record: {e.strerror or e}") from None
        first = (header + "\n").encode("utf-8")
        try:
            write_all(self.fd, first)
        except OSError as e:  # a disk full from the start: no empty log is left behind
            os.close(self.fd)
            self.path.unlink(missing_ok=True)
            raise UserError(f"{self.path}: cannot record: {e.strerror or e}") from None
        self.header_size = len(first)
        self.warn = warn
        self.pending: list[str] = []
        self.written = 0  # bytes in the file after the header
        self.lost = 0  # events not recorded: the size limit reached, the disk stuck or failing
        self.error: str | None = None  # why recording stopped, once it has
        self.end: float | None = None  # the performance time the run stopped at, once it has
        self.lock = threading.Lock()
        self.done = threading.Event()
        self.writer = threading.Thread(target=self._run, name="record", daemon=True)
        self.writer.start()

    def write(self, event: ControlEvent) -> None:
        """Queue one event's line (frame thread: no system call)."""
        if self.error is not None or len(self.pending) >= PENDING_LIMIT:
            self.lost += 1
            return
        line = event.to_json() + "\n"
        with self.lock:
            self.pending.append(line)

    def _run(self) -> None:
        while not self.done.wait(WRITE_EVERY):
            self._write_batch()
        self._write_batch()

    def _write_batch(self) -> None:
        with self.lock:
            batch, self.pending = self.pending, []
        if not batch or self.error is not None:
            self.lost += len(batch) if self.error is not None else 0
            return
        data = "".join(batch).encode("utf-8")
        if self.written + len(data) > LIMIT:
            self.lost += len(batch)
            self._stop(f"the log reached its limit of {LIMIT >> 20} MiB", "recording stopped (the show goes on)")
            return
        try:
            write_all(self.fd, data)  # one write unless the disk cuts it short: a kill cuts at most the last line
            self.written += len(data)
        except OSError as e:
            self.lost += len(batch)
            try:
                os.ftruncate(self.fd, self.header_size + self.written)  # the log ends on a whole line
            except OSError:
                pass  # a cut last line: the reader drops it with a warning
            self._stop(f"cannot write: {e.strerror or e}",
                       "recording stopped; the log keeps the events before it (the show goes on)",
                       said=f"{e.strerror or e}")

    def _stop(self, error: str, consequence: str, said: str | None = None) -> None:
        """End the recording: the warning first, then `error`, so whoever sees the recording
        stopped (the frame thread, a test) sees it after the console has been told."""
        try:
            if self.warn is not None:
                self.warn(f"{self.path}: {said or error}: {consequence}")
        finally:
            self.error = error

    def close(self) -> None:
        if self.fd is None:
            return
        self.done.set()
        self.writer.join()
        if self.end is not None and self.error is None and not self.lost:  # a log that lost events is not a whole take
            try:
                write_all(self.fd, (end_line(self.end) + "\n").encode("utf-8"))
            except OSError:
                os.ftruncate(self.fd, self.header_size + self.written)  # as before: it replays to its last event
        os.close(self.fd)
        self.fd = None
