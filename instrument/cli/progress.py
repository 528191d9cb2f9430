"""What a long wait is: a one-line progress bar on stderr (plain lines when stderr is not a
terminal), and the notice that the kernels are being compiled on a first run."""

from __future__ import annotations

import os
import sys
import threading


class Progress:
    def __init__(self, quiet: bool = False, width: int = 30):
        self.quiet = quiet
        self.width = width
        self.tty = sys.stderr.isatty()
        self.last_phase = ""

    def __call__(self, done: int, total: int, phase: str) -> None:
        if self.quiet:
            return
        if self.tty:
            filled = int(self.width * done / max(total, 1))
            sys.stderr.write(f"\r{phase:<10} [{'#' * filled}{'.' * (self.width - filled)}] {done}/{total}")
            if done >= total:
                sys.stderr.write("\n")
            sys.stderr.flush()
        elif done >= total and phase != self.last_phase:
            print(f"{phase}: {total}/{total}", file=sys.stderr)
            self.last_phase = phase


class CompileNotice:
    """Says on stderr, the moment numba starts compiling one of the instrument's kernels, what the
    wait is: the first command on a machine (or after an upgrade) compiles them for about half a
    minute before anything else happens, and silence then looks like a hang. Later commands load
    them from the cache and say nothing. One line, never more: the command's own console owns
    the terminal's status line."""

    def __init__(self, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        self.said = False

    def on_start(self, function) -> None:
        if self.said or not getattr(function, "__module__", "").startswith("instrument."):
            return
        self.said = True
        line = ("compiling the walk's kernels for this machine (once: half a minute or more on a first run, "
                f"then cached in {os.environ.get('NUMBA_CACHE_DIR', 'numba cache')})\n")
        # from a thread of its own: a stderr nobody reads never holds up the compile (nor a frame loop that set it off)
        threading.Thread(target=self._write, args=(line,), name="compile notice", daemon=True).start()

    def _write(self, line: str) -> None:
        try:
            self.stream.write(line)
            self.stream.flush()
        except (AttributeError, OSError, ValueError):  # no stderr, or a closed one: the command goes on
            pass


def watch_compiling(stream=None) -> CompileNotice:
    """Register a CompileNotice with numba's compile events (imports numba: only for commands that use it)."""
    from numba.core import event

    notice = CompileNotice(stream)

    class Listener(event.Listener):
        def on_start(self, ev) -> None:
            notice.on_start(ev.data["dispatcher"].py_func)

        def on_end(self, ev) -> None:
            pass

    event.register("numba:compile", Listener())
    return notice
