"""Knowing when the JACK server under our MIDI ports went away, and when it is back.

rtmidi gives no sign that its JACK server died: the dead client keeps answering from what it
knew. So a small client of our own ("instrument-watch", opened through libjack with ctypes)
asks JACK to be told of a shutdown. After one, `reconnect` tries to open it again (about once
a second, from the caller's background thread; libjack's calls release the interpreter, so the
frame loop is not held up). libjack's complaints while the server is down ("Cannot connect to
server socket") are kept off the performer's console.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading
from pathlib import Path
from typing import Callable

NO_START_SERVER = 0x01  # JackNoStartServer: never start a server of our own
_SHUTDOWN = ctypes.CFUNCTYPE(None, ctypes.c_void_p)
_MESSAGE = ctypes.CFUNCTYPE(None, ctypes.c_char_p)


RETRY_SECONDS = 1.0


def _candidates() -> list[str]:
    """python-rtmidi's own copy of libjack first (its clients live there), then the system's."""
    try:
        import rtmidi

        bundled = sorted(str(p) for p in Path(rtmidi.__file__).parent.parent.glob("python_rtmidi*/libjack*.so*"))
    except ImportError:
        bundled = []
    return bundled + [ctypes.util.find_library("jack") or "libjack.so.0"]


def _library():
    for name in _candidates():
        try:
            lib = ctypes.CDLL(name)
            break
        except OSError:
            continue
    else:
        return None
    lib.jack_client_open.restype = ctypes.c_void_p
    lib.jack_client_open.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
    lib.jack_on_shutdown.argtypes = [ctypes.c_void_p, _SHUTDOWN, ctypes.c_void_p]
    lib.jack_activate.argtypes = [ctypes.c_void_p]
    lib.jack_client_close.argtypes = [ctypes.c_void_p]
    lib.jack_set_error_function.argtypes = [_MESSAGE]
    lib.jack_set_info_function.argtypes = [_MESSAGE]
    return lib


def _quiet():
    """A C function taking a string and doing nothing visible (libc's strlen: its result is
    ignored), for libjack's error and info messages. Not a Python callback: libjack calls it
    from inside its own locks, where waiting for the interpreter could deadlock the process.
    Made once, at the first watch (finding libc runs `ldconfig`: not for every command's start)."""
    global _QUIET
    if _QUIET is None:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        _QUIET = ctypes.cast(libc.strlen, _MESSAGE)
    return _QUIET


# libjack's complaints would reach the console from whichever thread made a call (the frame
# loop's included) and, on a stalled stderr, block it: the console says what matters instead
_QUIET = None
# the remaking threads (one per device) call libjack one at a time: taking a dead client apart
# while another thread opens a new one has crashed libjack
JACK_CALLS = threading.Lock()


def quiet_libjack():
    """libjack (the copy rtmidi's clients live in) with its error and info messages kept off
    stderr, or None where there is none: with no server, opening a MIDI port printed five lines
    of libjack's ("Cannot connect to server socket err = ...") above the one that says what
    failed and what to do (devices.midi_system)."""
    lib = _library()
    if lib is not None:
        lib.jack_set_error_function(_quiet())
        lib.jack_set_info_function(_quiet())
    return lib


class JackWatch:
    def __init__(self):
        self.lib = quiet_libjack()
        self.client = None
        self.lost = threading.Event()  # set when the server shut down under us
        self.on_shutdown = _SHUTDOWN(lambda arg: self.lost.set())  # referenced, so not collected
        self.reconnect()

    @property
    def available(self) -> bool:
        return self.lib is not None

    def reconnect(self) -> bool:
        """Open the watch client again; True if the server is there."""
        if self.lib is None:
            return False
        self._drop()
        status = ctypes.c_int(0)
        client = self.lib.jack_client_open(b"instrument-watch", NO_START_SERVER, ctypes.byref(status))
        if not client:
            return False
        self.lib.jack_on_shutdown(client, self.on_shutdown, None)
        if self.lib.jack_activate(client) != 0:
            self.lib.jack_client_close(client)
            return False
        self.client = client
        self.lost.clear()
        return True

    def close(self) -> None:
        with JACK_CALLS:
            self._drop()

    def _drop(self) -> None:
        """Close the watch client; one the server shut down under is left alone (libjack has
        taken it apart already, and closing it again can crash the process)."""
        if self.client is not None and self.lib is not None and not self.lost.is_set():
            self.lib.jack_client_close(self.client)
        self.client = None


ABANDONED = threading.Event()  # set once any port was left to the process's end (see `abandon`)
# set by cli.main for a command that is its process's own: its inputs are left to its end (`release`)
ENDS_WITH_PROCESS = threading.Event()


def abandon(port: object) -> None:
    """Leave a port alone for good: never closed, never freed. A port whose server died: taking
    it apart holds the interpreter for about a second (the frame loop with it) or crashes
    libjack, and freeing it would do the same later; what it keeps is a few kilobytes per
    restart. A process that abandoned one ends without the interpreter's teardown (cli.main):
    libjack still holds the dead client, and a show that survived a restart crashed as it exited
    (once in CI)."""
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(port))
    ABANDONED.set()


def release(port: object, close: Callable[[], None], leave_at_end: bool = False) -> None:
    """Take a device's port apart with `close`, unless a JACK server died under this process, or
    the process ends with it and the port is one to `leave_at_end` (an input: nothing of it is
    still to go out); then the port is left, as a dead one is, to the process's end (cli.main
    ends such a process at once, its files written and closed; the OS and the JACK server
    reclaim its clients). rtmidi's `close_port` on a JACK virtual input crashed `instrument
    run` as it ended, the server alive (a segfault, once in about four full test runs, just
    after the other end closed its own port); past a server restart libjack still holds the
    dead client, where taking any port apart can crash it. An output is closed even at the
    end: its close waits for JACK to send what it queued (a footfall's note-off, the
    feedback's last values), which the process's end would drop. In a process that goes on
    (a test's own ports), ports are closed. Everything recorded is closed before the devices."""
    if ABANDONED.is_set() or (leave_at_end and ENDS_WITH_PROCESS.is_set()):
        abandon(port)
    else:
        close()


class Remaker:
    """Makes a device's JACK port again after a server restart, in a background thread.

    `lost()` says the server went away; `start(old)` abandons the dead port and waits for the
    server to come back, then calls `make()`; `take()` hands the new port over once it exists."""

    def __init__(self, make: Callable[[], object], discard: Callable[[object], None]):
        self.watch = JackWatch()
        self.make, self.discard = make, discard  # discard: for a port made after closing began
        self.thread: threading.Thread | None = None
        self.made: object | None = None
        self.closing = threading.Event()

    def lost(self) -> bool:
        return self.thread is None and self.watch.lost.is_set()

    @property
    def busy(self) -> bool:
        return self.thread is not None

    def start(self, old: object) -> None:
        self.thread = threading.Thread(target=self._run, args=(old,), name="jack-remake", daemon=True)
        self.thread.start()

    def _run(self, old: object) -> None:
        if old is not None:
            abandon(old)
        while not self.closing.wait(RETRY_SECONDS):
            with JACK_CALLS:
                if not self.watch.reconnect():
                    continue
                try:
                    made = self.make()
                except Exception:
                    continue
            if made is not None:  # None: the server is back, the device not yet
                self.made = made
                return

    def follow(self, port: object) -> tuple[str, object | None]:
        """One look, from the device's poll, at a server restart for the device holding `port`:
        ("steady", port); ("lost", None) the server just went away and remaking began;
        ("waiting", None); or ("back", the new port)."""
        if self.busy:
            made = self.take()
            return ("waiting", None) if made is None else ("back", made)
        if self.lost():
            self.start(port)
            return "lost", None
        return "steady", port

    def take(self) -> object | None:
        """The new port, once made (then the Remaker watches again)."""
        if self.made is None:
            return None
        made, self.made, self.thread = self.made, None, None
        return made

    def close(self) -> None:
        self.closing.set()
        if self.thread is not None:
            self.thread.join(5)
            if self.made is not None:
                self.discard(self.made)
        self.watch.close()
