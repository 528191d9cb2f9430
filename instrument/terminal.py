"""What the performer reads: warnings (each subject of each kind at most once a minute) and a status line.

Writing to the console never blocks or stops the frame loop. Lines are queued and written by a
background thread straight to the file descriptor, so a terminal or pipe that nobody reads
(stderr into a full pipe) stalls only that thread; a closed one (`| head -3`, `2>&-`) is
noticed once and from then on nothing more is written. While the writer is stuck, new lines
past QUEUE_LIMIT are dropped and counted: a show goes on without its console, never the
other way round.
"""

from __future__ import annotations

import io
import os
import sys
import threading
import time
from collections import deque

QUEUE_LIMIT = 1000  # lines waiting for a stuck writer; more are dropped (counted in `dropped`)
SUBJECTS_PER_KEY = 8  # distinct subjects of one kind of warning said a minute; more are left to the callers' counts


class Console:
    def __init__(self, quiet: bool = False, stream=None, now=time.monotonic, repeat_after: float = 60.0):
        self.quiet = quiet
        self.stream = stream if stream is not None else sys.stderr  # None when Python started with fd 2 closed
        self.now = now
        self.repeat_after = repeat_after
        self.last_said: dict[str, dict[str, float]] = {}  # key -> {subject: when it was last said}
        try:
            self.tty = self.stream is not None and self.stream.isatty()
        except (OSError, ValueError):
            self.tty = False
        self.status_shown = False
        self.dropped = 0  # lines not shown: the writer was stuck, or the console is closed
        self.closed = self.stream is None
        self.fd = _fileno(self.stream)
        self.pending: deque[str] = deque()
        self.writing = False  # the writer holds lines taken from `pending`
        self.wake = threading.Condition()
        self.writer: threading.Thread | None = None

    def warn(self, key: str, message: str, subject: str = "") -> bool:
        """Say `message` unless the same key and subject (the OSC address, the control, the
        device the message is about) was said less than a minute ago; True if said. Each distinct
        subject is named once a minute: a second typo of another address is shown, not only
        counted. At most SUBJECTS_PER_KEY subjects of a key are said a minute, so a peer sending
        a flood of distinct bad addresses cannot flood the terminal (the callers count them all)."""
        t = self.now()
        said = self.last_said.setdefault(key, {})
        for old in [s for s, at in said.items() if t - at >= self.repeat_after]:
            del said[old]
        if subject in said or len(said) >= SUBJECTS_PER_KEY:
            return False
        said[subject] = t
        self._line(f"warning: {message}")
        return True

    def say(self, message: str) -> None:
        self._line(message)

    def status(self, text: str) -> None:
        if self.quiet:
            return
        if self.tty:
            self._write("\r" + text[:200].ljust(100))
            self.status_shown = True
        else:
            self._write(text + "\n")

    def _line(self, text: str) -> None:
        if self.status_shown:
            text = "\n" + text
            self.status_shown = False
        self._write(text + "\n")

    def _write(self, text: str) -> None:
        if self.closed:
            self.dropped += 1
            return
        if self.fd is None:  # a Python stream without a file descriptor (tests' capture): write it at once
            try:
                self.stream.write(text)
                self.stream.flush()
            except (OSError, ValueError):
                self.closed = True
            return
        with self.wake:
            if len(self.pending) >= QUEUE_LIMIT:
                self.dropped += 1
                return
            self.pending.append(text)
            self.wake.notify()
        if self.writer is None:
            self.writer = threading.Thread(target=self._drain, name="console", daemon=True)
            self.writer.start()

    def _drain(self) -> None:
        while True:
            with self.wake:
                while not self.pending:
                    self.wake.wait()
                text = "".join(self.pending)
                self.writing = True  # before the queue empties: flush() looks at both without the lock
                self.pending.clear()
            data = text.encode("utf-8", errors="replace")
            try:
                while data:
                    data = data[os.write(self.fd, data):]
            except OSError:  # closed pipe, closed descriptor: the show goes on silently
                self.closed = True
                return
            finally:
                self.writing = False

    def flush(self, timeout: float = 1.0) -> bool:
        """Wait up to `timeout` seconds for queued lines to be written; True if they were."""
        deadline = time.monotonic() + timeout
        while (self.pending or self.writing) and not self.closed and time.monotonic() < deadline:
            time.sleep(0.005)
        return not (self.pending or self.writing)


def _fileno(stream) -> int | None:
    """The descriptor under a text stream, its Python buffer flushed first, or None."""
    if stream is None or not isinstance(stream, io.TextIOWrapper):
        return None
    try:
        stream.flush()
        return stream.fileno()
    except (OSError, ValueError):
        return None
