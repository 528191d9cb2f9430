"""The console's web server: the page and one WebSocket per page, in a process of its own.

aiohttp serves both the page's files and the WebSockets from one asyncio loop (the websockets
library would need its HTTP hook to serve files), and its writer applies back-pressure per
connection, which is how a slow page is found and dropped.

It runs in its own process (`python -m instrument.console.server FD`), not in a thread: a
thread would share the interpreter lock with the realtime frame loop, and when the machine is
busy a preempted server thread holding the lock keeps the frame loop waiting (measured: five
browser pages on the same two cores made a tenth of the frames late in a thread, none from a
process). The frame loop talks to it over a socket pair of whole packets (link.py): it sends
each frame without waiting and reads the pages' events when it polls.

Each page has a sender task that always sends the newest frame: a page that cannot keep up
skips frames, and one that has not taken a frame for SLOW_SECONDS is dropped.
"""

from __future__ import annotations

import asyncio
import json
import math
import secrets
import signal
import socket
import struct
import sys
from dataclasses import dataclass, field
from importlib import resources
from urllib.parse import urlsplit

import numpy as np

from ..errors import UserError
from .messages import MAX_MESSAGE, Refused, parse
from .presets import save_presets

SLOW_SECONDS = 5.0  # a page that has not taken a frame for this long is dropped
MAX_PAGES = 32  # pages open at once; one more is refused (each costs a frame's JSON sent every frame)
MAX_PACKET = 64 * 1024  # bytes: the largest packet between the frame loop and the server (presets go in parts)
LOOPBACK = ("127.0.0.1", "localhost", "::1")  # the names a page on this machine reaches the console by
EVERY_INTERFACE = ("0.0.0.0", "", "::")  # listening on every interface: a token is always needed, it protects
STATIC = {"/": ("index.html", "text/html"), "/console.js": ("console.js", "text/javascript"),
          "/console.css": ("console.css", "text/css")}
SECURITY = {"Content-Security-Policy": "default-src 'self'; img-src 'self' data:; connect-src 'self'",
            "Cache-Control": "no-store", "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer"}
HEADER = struct.Struct("<qiii")  # a frame packet: index, late frames, dropped frames, characters; then float32
# positions (characters x joints x 3, the followed character first), float64 values
FRAME, JSON = b"F", b"J"  # the first byte of every packet between the frame loop and the server


def frame_packet(index: int, late: int, dropped: int, positions: np.ndarray, values: np.ndarray) -> bytes:
    """A frame as one packet (made by the frame loop: a few microseconds, no JSON); `positions`
    (joints, 3) for one character or (characters, joints, 3) for a crowd."""
    characters = 1 if positions.ndim == 2 else positions.shape[0]
    return (FRAME + HEADER.pack(index, late, dropped, characters) + positions.astype("<f4").tobytes()
            + values.astype("<f8").tobytes())


def frame_json(packet: bytes, joints: int, order: list[str], extra: dict) -> str:
    """A frame packet as the JSON a page is sent: the joints' positions ("p", of the character the
    view follows; "crowd", the others', one after the other) and every control value."""
    index, late, dropped, characters = HEADER.unpack_from(packet, 1)
    start = 1 + HEADER.size
    positions = np.round(np.frombuffer(packet, "<f4", characters * joints * 3, start).astype(float), 2)
    values = np.frombuffer(packet, "<f8", len(order), start + characters * joints * 12)
    shown = {t: (None if math.isnan(v) else round(v, 4)) for t, v in zip(order, values.tolist())}
    crowd = {"crowd": positions[joints * 3:].tolist()} if characters > 1 else {}
    return json.dumps({"type": "frame", "frame": index, "late": late, "dropped": dropped,
                       "p": positions[: joints * 3].tolist(), **crowd, "v": shown, **extra}, separators=(",", ":"))


@dataclass(eq=False)
class Page:
    ws: object  # aiohttp.web.WebSocketResponse
    transport: object  # its TCP transport, aborted when the page is dropped
    newest: str | None = None
    ready: asyncio.Event = field(default_factory=asyncio.Event)
    sending_since: float | None = None


class ConsoleServer:
    """The server, in its own process. `link` is its end of the socket pair to the frame loop;
    `config` holds the address, the token, the page's hello, the targets and the preset file."""

    def __init__(self, link: socket.socket, config: dict):
        self.link = link
        self.host, self.port = config["host"], config["port"]
        self.token: str | None = config["token"]
        self.hello, self.order = config["hello"], config["hello"]["order"]
        self.joints = len(self.hello["joints"])
        self.targets = frozenset(config["targets"])
        self.save_path: str | None = config["save"]
        self.max_presets: int = config["max_presets"]
        self.presets: dict[str, dict[str, float]] = {}  # as the frame loop sends them, in parts
        self.names: list[str] = []  # the presets' names, sorted, as the pages were last told
        self.extra = {"sources": "", "pages": 0}  # sent with every frame
        self.files = {route: (resources.files(__package__).joinpath("static", name).read_bytes(), kind)
                      for route, (name, kind) in STATIC.items()}
        self.pages: set[Page] = set()
        self.unsaid = 0  # refusals not yet said on the terminal
        self.loop = asyncio.new_event_loop()

    def run(self) -> None:
        from aiohttp import web

        asyncio.set_event_loop(self.loop)
        app = web.Application(client_max_size=MAX_MESSAGE)
        app.router.add_get("/ws", self._socket)
        for route in self.files:
            app.router.add_get(route, self._file)
        app.router.add_get("/favicon.ico", lambda request: web.Response(status=204))
        runner = web.AppRunner(app, handle_signals=False, access_log=None)
        self.loop.run_until_complete(runner.setup())
        try:
            listener = socket.create_server((self.host, self.port))
        except OSError as e:
            self._tell_instrument({"error": e.strerror or str(e)})
            self.loop.run_until_complete(runner.cleanup())
            return
        self.port = listener.getsockname()[1]  # the port chosen when 0 was asked for
        self.loop.run_until_complete(web.SockSite(runner, listener).start())
        self._tell_instrument({"ready": self.port})
        self.link.setblocking(False)
        self.loop.add_reader(self.link.fileno(), self._from_instrument)
        try:
            self.loop.run_forever()  # until the instrument closes its end
        finally:
            for page in list(self.pages):
                self._drop(page)
            self.loop.run_until_complete(runner.cleanup())

    # --- the frame loop's side ----------------------------------------------------------------

    def _from_instrument(self) -> None:
        """Read every packet waiting; only the newest frame is sent on (a backlog is skipped)."""
        newest = None
        presets_came = False
        while True:
            try:
                packet = self.link.recv(MAX_PACKET)
            except BlockingIOError:
                break
            except OSError:
                packet = b""
            if not packet:  # the instrument has stopped
                self.loop.remove_reader(self.link.fileno())
                self.loop.stop()
                return
            if packet[:1] == FRAME:
                newest = packet
            else:
                item = json.loads(packet[1:])
                if "presets" in item:  # a part: the presets stored since the last
                    self.presets.update(item["presets"])
                    presets_came = True
                if "save" in item:  # a page asked for it; every preset stored before has come
                    self._save(item["save"])
                if "sources" in item:
                    self.extra["sources"] = item["sources"]
        if presets_came and sorted(self.presets) != self.names:
            self.names = sorted(self.presets)
            for page in self.pages:
                self._tell(page, {"type": "presets", "presets": self.names})
        if self.unsaid and self._note(f"console: refused {self.unsaid} page messages (too many at once)", "console flood"):
            self.unsaid = 0
        if newest is not None and self.pages:
            self._broadcast(newest)

    def _tell_instrument(self, item: dict) -> bool:
        """False if it could not be sent: the instrument's queue is full (it reads it every frame
        and while it waits for the next, so only a flood fills it) or it is stopping."""
        try:
            self.link.send(JSON + json.dumps(item).encode("utf-8"))
            return True
        except OSError:
            return False

    def _note(self, text: str, key: str = "") -> bool:
        """Something for the performer's terminal; with a key, a warning said at most once a minute."""
        return self._tell_instrument({"note": [key, text]})

    # --- the pages' side ----------------------------------------------------------------------

    def _allowed(self, request) -> bool:
        """The token when one is needed, a Host this console is known by, and no page of another
        site talking to us (a browser lets any web page open a WebSocket to 127.0.0.1: its Origin
        gives it away)."""
        if self.token is not None and not secrets.compare_digest(request.query.get("token", ""), self.token):
            return False
        if not self._known_host(request.headers.get("Host", "")):
            self._note(f"console: refused a request for host {request.headers.get('Host', '')[:60]!r} "
                       "(not this console's address)", "console host")
            return False
        origin = request.headers.get("Origin")
        return origin is None or urlsplit(origin).netloc == request.host

    def _known_host(self, host: str) -> bool:
        """The Host header names this console: its own address or this machine's loopback, and
        its port. Against DNS rebinding: another site's page whose name was made to point at
        127.0.0.1 sends its own name (and a matching Origin), which is neither. On every
        interface any name may reach it, and the token that is always needed there protects it."""
        if self.host in EVERY_INTERFACE:
            return True
        try:
            parts = urlsplit("//" + host)
            name, port = parts.hostname, parts.port or 80
        except ValueError:
            return False
        return port == self.port and name is not None and name in (*LOOPBACK, self.host.lower().strip("[]"))

    async def _file(self, request):
        from aiohttp import web

        if request.path == "/" and not self._allowed(request):
            return web.Response(status=403, text="forbidden: open the URL printed at start (with its token)")
        body, kind = self.files[request.path]
        return web.Response(body=body, content_type=kind, headers=SECURITY)

    async def _socket(self, request):
        from aiohttp import WSMsgType, web

        if not self._allowed(request):
            return web.Response(status=403, text="forbidden")
        if len(self.pages) >= MAX_PAGES:
            self._note(f"console: refused a page: already {MAX_PAGES} open, the most the console serves", "console pages")
            return web.Response(status=503, text=f"too many pages: the console serves {MAX_PAGES} at once")
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE)  # no heartbeat: a stalled page is found by its frames
        await ws.prepare(request)
        page = Page(ws, request.transport)
        self._count(page, add=True)
        self._note(f"console: a page connected from {request.remote} ({len(self.pages)} open)")
        sender = asyncio.ensure_future(self._sender(page))
        try:
            await ws.send_str(json.dumps({**self.hello, "presets": self.names}))
            async for message in ws:
                if message.type == WSMsgType.TEXT:
                    self._receive(page, message.data)
                elif message.type == WSMsgType.BINARY:
                    self._refuse(page, "binary messages are not understood")
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            sender.cancel()
            if page in self.pages:
                self._count(page, add=False)
                self._note(f"console: a page closed ({len(self.pages)} open)")
        return ws

    def _count(self, page: Page, add: bool) -> None:
        (self.pages.add if add else self.pages.discard)(page)
        self.extra["pages"] = len(self.pages)
        self._tell_instrument({"pages": len(self.pages)})

    def _receive(self, page: Page, text: str) -> None:
        try:
            kind, control, value = parse(text, self.targets)
        except Refused as refusal:
            self._refuse(page, str(refusal))
            return
        if kind == "save":
            if self.save_path is None:
                self._tell(page, {"type": "saved", "error": "no preset file: start with --presets FILE"})
            elif not self._tell_instrument({"save": True}):  # it answers with the presets, then the save
                self._refuse(page, "too many messages at once")
        elif control.startswith("store/") and control[6:] not in self.presets and len(self.presets) >= self.max_presets:
            self._refuse(page, f"already {self.max_presets} presets, the most a show holds: store over an existing name")
        elif not self._tell_instrument({"event": [control, value]}):
            self._refuse(page, "too many messages at once")

    def _refuse(self, page: Page, reason: str) -> None:
        if not self._note(f"console: refused a page's message: {reason}", "console refused"):
            self.unsaid += 1  # the instrument's queue is full: said with the next frame
        self._tell(page, {"type": "refused", "reason": reason})

    def _save(self, count: int) -> None:
        """Write the presets, when the frame loop says they have all come (`count` of them): every
        page is told how it went."""
        try:
            if len(self.presets) != count:
                raise UserError(f"{self.save_path}: not saved: {count - len(self.presets)} of the {count} presets "
                                "are too large for the console")
            save_presets(self.save_path, self.presets)
        except UserError as error:
            self._note(f"console: {error}", "console save")
            for page in self.pages:
                self._tell(page, {"type": "saved", "error": str(error)})
            return
        said = f"saved {len(self.presets)} presets to {self.save_path}"
        self._note(f"console: {said}")
        for page in self.pages:
            self._tell(page, {"type": "saved", "text": said})

    def _tell(self, page: Page, item: dict) -> None:
        if not page.ws.closed:
            asyncio.ensure_future(self._send_quietly(page, json.dumps(item)))

    @staticmethod
    async def _send_quietly(page: Page, text: str) -> None:
        try:
            await page.ws.send_str(text)
        except (ConnectionError, RuntimeError):
            pass

    def _broadcast(self, packet: bytes) -> None:
        text = frame_json(packet, self.joints, self.order, self.extra)  # once for all pages
        now = self.loop.time()
        for page in list(self.pages):
            if page.sending_since is not None and now - page.sending_since > SLOW_SECONDS:
                self._drop(page)
                self._note(f"console: dropped a page that took no frame for {SLOW_SECONDS:g} s", "console slow")
                continue
            page.newest = text
            page.ready.set()

    async def _sender(self, page: Page) -> None:
        """Send the newest frame whenever there is one; a slow page skips the frames in between."""
        try:
            while True:
                await page.ready.wait()
                page.ready.clear()
                page.sending_since = self.loop.time()
                await page.ws.send_str(page.newest)
                page.sending_since = None
        except (ConnectionError, RuntimeError):
            self._drop(page)

    def _drop(self, page: Page) -> None:
        if page in self.pages:
            self._count(page, add=False)
        if page.transport is not None:
            page.transport.abort()


def main() -> None:
    """The server process: its end of the socket pair is file descriptor argv[1]; the first
    packet on it is the configuration."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the instrument's: it closes the pair, and we end
    link = socket.socket(fileno=int(sys.argv[1]))
    config = json.loads(link.recv(1 << 20)[1:])  # the model's names and skeleton: well under a megabyte
    ConsoleServer(link, config).run()


if __name__ == "__main__":
    main()
