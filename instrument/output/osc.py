"""OSC over UDP: targets given as HOST:PORT[/profile], datagrams packed into small bundles (or,
for receivers that reject bundles, HOST:PORT/profile-unbundled: one message per datagram).

A target that is down, unreachable or whose name does not resolve yet never stops the
instrument: the error is reported (once a minute per target) and sending goes on, so the
renderer picks up as soon as it is back.
"""

from __future__ import annotations

import ctypes
import ipaddress
import os
import socket
import struct
import threading
import time
from dataclasses import dataclass

import numpy as np

from ..errors import UserError
from ..terminal import Console

VMC_PORT = 39539
FLAT_PORT = 9000
RESOLVE_WAIT = 1.0  # seconds the start waits for a host name before going on without it
RESOLVE_EVERY = 2.0  # seconds between two tries of a name that does not resolve
MAX_BUNDLE = 1400  # bytes: receivers read 8 KB at most, and one Ethernet frame is safest
PROFILES = ("flat", "vmc")


UNBUNDLED = "-unbundled"  # a profile's suffix: one message per datagram, for receivers that reject bundles


@dataclass(frozen=True)
class OscTarget:
    host: str
    port: int
    profile: str
    bundled: bool = True  # False: every message in a datagram of its own (HOST:PORT/vmc-unbundled)

    def __str__(self) -> str:
        return f"{self.host}:{self.port}/{self.profile}{'' if self.bundled else UNBUNDLED}"


def parse_target(text: str) -> OscTarget:
    """HOST:PORT[/vmc|/flat][-unbundled]; without a profile, port 39539 means VMC and any other the
    flat profile."""
    address, _, profile = text.partition("/")
    bundled = not profile.endswith(UNBUNDLED)
    profile = profile.removesuffix(UNBUNDLED)
    host, sep, port_text = address.rpartition(":")
    if not sep or not host:
        raise UserError(f"--osc {text!r}: expected HOST:PORT[/vmc|/flat][-unbundled], e.g. 127.0.0.1:39539/vmc")
    try:
        port = int(port_text)
    except ValueError:
        raise UserError(f"--osc {text!r}: port {port_text!r} is not a number") from None
    if not 0 < port < 65536:
        raise UserError(f"--osc {text!r}: port must be 1 to 65535")
    profile = profile or ("vmc" if port == VMC_PORT else "flat")
    if profile not in PROFILES:
        raise UserError(f"--osc {text!r}: unknown profile {profile!r} (vmc or flat, either with -unbundled)")
    return OscTarget(host, port, profile, bundled)


def _padded(text: str) -> bytes:
    raw = text.encode("utf-8") + b"\0"
    return raw + b"\0" * (-len(raw) % 4)


_PREFIXES: dict[tuple[str, str], bytes] = {}


def message(address: str, *args: float | int | str) -> bytes:
    """One OSC message: float arguments as float32, ints as int32, strings as strings.

    Encoded directly with struct (python-osc's builder costs half a millisecond a frame), with
    the address and type tags cached; python-osc parses the result in the tests.
    """
    tags = "".join("s" if isinstance(a, str) else "i" if isinstance(a, int) and not isinstance(a, bool) else "f" for a in args)
    prefix = _PREFIXES.get((address, tags))
    if prefix is None:
        prefix = _PREFIXES[(address, tags)] = _padded(address) + _padded("," + tags)
    if "s" not in tags:
        return prefix + struct.pack(">" + tags, *args)
    body = b"".join(_padded(a) if t == "s" else struct.pack(">" + t, a) for t, a in zip(tags, args))
    return prefix + body


def float_prefix(address: str, floats: int, *strings: str) -> bytes:
    """The fixed start of a message whose arguments are `strings` then `floats` float32 values:
    address, type tags and the strings (for `float_messages`)."""
    return _padded(address) + _padded("," + "s" * len(strings) + "f" * floats) + b"".join(_padded(t) for t in strings)


def float_messages(prefixes: list[bytes], values: np.ndarray) -> list[bytes]:
    """One message per row of `values` (rows, floats), each after its prefix: all the floats of
    a frame are converted to big-endian float32 in one numpy call."""
    data = np.ascontiguousarray(values, dtype=">f4").tobytes()
    width = 4 * values.shape[-1]
    return [p + data[i * width : (i + 1) * width] for i, p in enumerate(prefixes)]


def bundles(messages: list[bytes], limit: int = MAX_BUNDLE) -> list[bytes]:
    """Messages packed in order into as few bundles as fit under `limit` bytes each."""
    out, current, size = [], [], 16  # "#bundle\\0" + time tag
    for m in messages:
        if current and size + 4 + len(m) > limit:
            out.append(_bundle(current))
            current, size = [], 16
        current.append(m)
        size += 4 + len(m)
    if current:
        out.append(_bundle(current))
    return out


def unbundled(datagrams: list[bytes]) -> list[bytes]:
    """The messages of `datagrams` in order, one per datagram: bundles (as `bundles` makes them,
    no nesting) opened, plain messages kept."""
    out = []
    for dgram in datagrams:
        if not dgram.startswith(b"#bundle\0"):
            out.append(dgram)
            continue
        pos = 16
        while pos < len(dgram):
            (size,) = struct.unpack_from(">i", dgram, pos)
            out.append(dgram[pos + 4 : pos + 4 + size])
            pos += 4 + size
    return out


IMMEDIATELY = struct.pack(">Q", 1)  # the OSC time tag meaning "now"


def _bundle(messages: list[bytes]) -> bytes:
    return b"#bundle\0" + IMMEDIATELY + b"".join(struct.pack(">i", len(m)) + m for m in messages)


class Datagrams:
    """A frame's datagrams as views of one buffer the encoder keeps and writes every frame (the
    flat profile's `FrameTemplate`): sent from where they lie, with the headers of one `sendmmsg`
    call made once for the buffer. Good until the encoder's next frame."""

    def __init__(self, data: np.ndarray, bounds: list[tuple[int, int]]):
        self.data = data  # uint8, every datagram back to back; never reallocated
        self.bounds = bounds  # each datagram's start and end in `data`
        self._headers: tuple | None = None  # (mmsghdr array, iovec array) for sendmmsg, made at the first send

    def __len__(self) -> int:
        return len(self.bounds)

    def __iter__(self):
        view = memoryview(self.data)
        return (view[a:b] for a, b in self.bounds)

    def copies(self) -> list[bytes]:
        raw = self.data.tobytes()
        return [raw[a:b] for a, b in self.bounds]

    def headers(self):
        """The mmsghdr array describing every datagram (for a connected socket: no address)."""
        if self._headers is None:
            vectors = (_Iovec * len(self.bounds))()
            messages = (_Mmsghdr * len(self.bounds))()
            address = self.data.ctypes.data
            for k, (a, b) in enumerate(self.bounds):
                vectors[k].base, vectors[k].length = address + a, b - a
                messages[k].header.iov = ctypes.pointer(vectors[k])
                messages[k].header.iovlen = 1
            self._headers = messages, vectors
        return self._headers[0]


class _Iovec(ctypes.Structure):
    _fields_ = [("base", ctypes.c_void_p), ("length", ctypes.c_size_t)]


class _Msghdr(ctypes.Structure):
    _fields_ = [("name", ctypes.c_void_p), ("namelen", ctypes.c_uint32), ("iov", ctypes.POINTER(_Iovec)),
                ("iovlen", ctypes.c_size_t), ("control", ctypes.c_void_p), ("controllen", ctypes.c_size_t),
                ("flags", ctypes.c_int)]


class _Mmsghdr(ctypes.Structure):
    _fields_ = [("header", _Msghdr), ("length", ctypes.c_uint)]


def _find_sendmmsg():
    """libc's sendmmsg (Linux), or None: then every datagram is a `send` of its own."""
    try:
        function = ctypes.CDLL(None, use_errno=True).sendmmsg
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int]
    function.restype = ctypes.c_int
    return function


SENDMMSG = _find_sendmmsg()
SENDMMSG_MOST = 1024  # datagrams one sendmmsg call takes (the kernel's UIO_MAXIOV)


class UdpOut:
    """One socket per target; errors are reported, never raised.

    A host name is resolved in a background thread, tried again every RESOLVE_EVERY seconds
    until it resolves: a show starts even when the renderer's machine is not on the network yet,
    and sends to it from the frame after its name resolves. Until then its frames are dropped.
    """

    def __init__(self, target: OscTarget, console: Console, lookup=socket.getaddrinfo):
        self.target, self.console, self.lookup = target, console, lookup
        self.sock: socket.socket | None = None
        self.connected = False
        self.next_attempt = 0.0
        self.sent = 0
        self.failed = 0
        self.resolved: tuple | None = None  # getaddrinfo's first answer, set by the resolver
        self.batched = True  # a frame's `Datagrams` go out by sendmmsg where libc has it (False: one send each)
        self.closing = threading.Event()
        self.resolver = threading.Thread(target=self._resolve, name=f"resolve {target.host}", daemon=True)
        self.resolver.start()
        self.resolver.join(RESOLVE_WAIT)  # a name that resolves at once is ready for the first frame
        if self.resolved is None:
            console.warn(f"osc {target}",
                         f"OSC target {target}: cannot resolve {target.host!r} yet; the show goes on, still trying")
        else:
            self._open()

    def _resolve(self) -> None:
        while True:
            try:
                self.resolved = self.lookup(self.target.host, self.target.port, type=socket.SOCK_DGRAM)[0]
                return
            except (socket.gaierror, UnicodeError, OSError):
                if self.closing.wait(RESOLVE_EVERY):
                    return

    def _open(self) -> None:
        family, _, _, _, self.address = self.resolved
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        ip = ipaddress.ip_address(self.address[0])
        if ip.is_multicast:
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
        elif family == socket.AF_INET and (str(ip) == "255.255.255.255" or str(ip).endswith(".255")):
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self._connect()

    def _connect(self) -> None:
        """Connect the socket, so that a target that is down is reported (refused); an unreachable
        network is reported and tried again about once a second."""
        now = time.monotonic()
        if now < self.next_attempt:
            return
        self.next_attempt = now + 1.0
        try:
            self.sock.connect(self.address)
            self.connected = True
        except OSError as e:
            self._failed(e)

    def _failed(self, error: OSError) -> None:
        self.failed += 1
        self.console.warn(f"osc {self.target}", f"OSC target {self.target}: {error.strerror or error} (still trying)")

    @property
    def down(self) -> bool:
        """Nothing can be sent yet: the host name has not resolved (health reports the target down)."""
        return self.resolved is None

    def send(self, datagrams: list[bytes] | Datagrams) -> None:
        if self.sock is None:
            if self.resolved is None:
                return
            self.console.say(f"OSC target {self.target}: {self.target.host!r} resolved to {self.resolved[4][0]}; sending")
            self._open()
        if not self.connected:
            self._connect()
            if not self.connected:
                return
        if isinstance(datagrams, Datagrams) and SENDMMSG is not None and self.batched:
            self._send_batch(datagrams)
            return
        for dgram in datagrams:
            try:
                self.sock.send(dgram)
                self.sent += 1
            except OSError as e:  # refused, unreachable, buffer full: report and go on with the next frame
                self._failed(e)
                return

    def _send_batch(self, datagrams: Datagrams) -> None:
        """Every datagram of the frame in as few system calls as the kernel allows (one per
        SENDMMSG_MOST); an error stops the frame as a plain `send`'s does."""
        headers, count, done = datagrams.headers(), len(datagrams), 0
        size = ctypes.sizeof(_Mmsghdr)
        while done < count:
            sent = SENDMMSG(self.sock.fileno(), ctypes.addressof(headers) + done * size, min(count - done, SENDMMSG_MOST), 0)
            if sent < 0:  # refused, unreachable, buffer full: report and go on with the next frame
                error = ctypes.get_errno()
                self._failed(OSError(error, os.strerror(error)))
                return
            done += sent
            self.sent += sent

    def close(self) -> None:
        self.closing.set()
        if self.sock is not None:
            self.sock.close()
