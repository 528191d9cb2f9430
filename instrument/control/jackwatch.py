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

NO_START_SERVER = 0x01  # JackNoStartServer: never start a server of our own
_SHUTDOWN = ctypes.CFUNCTYPE(None, ctypes.c_void_p)
_MESSAGE = ctypes.CFUNCTYPE(None, ctypes.c_char_p)


def _library():
    name = ctypes.util.find_library("jack") or "libjack.so.0"
    try:
        lib = ctypes.CDLL(name)
    except OSError:
        return None
    lib.jack_client_open.restype = ctypes.c_void_p
    lib.jack_client_open.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.POINTER(ctypes.c_int)]
    lib.jack_on_shutdown.argtypes = [ctypes.c_void_p, _SHUTDOWN, ctypes.c_void_p]
    lib.jack_activate.argtypes = [ctypes.c_void_p]
    lib.jack_client_close.argtypes = [ctypes.c_void_p]
    lib.jack_set_error_function.argtypes = [_MESSAGE]
    lib.jack_set_info_function.argtypes = [_MESSAGE]
    return lib


_QUIET = _MESSAGE(lambda text: None)  # kept alive for as long as libjack may call it


class JackWatch:
    def __init__(self):
        self.lib = _library()
        self.client = None
        self.lost = threading.Event()  # set when the server shut down under us
        self.on_shutdown = _SHUTDOWN(lambda arg: self.lost.set())  # referenced, so not collected
        if self.lib is not None:
            self.lib.jack_set_error_function(_QUIET)
            self.lib.jack_set_info_function(_QUIET)
        self.reconnect()

    @property
    def available(self) -> bool:
        return self.lib is not None

    def reconnect(self) -> bool:
        """Open the watch client again; True if the server is there."""
        if self.lib is None:
            return False
        self.close()
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
        if self.client is not None and self.lib is not None:
            self.lib.jack_client_close(self.client)  # after a shutdown this only frees what is left
        self.client = None
