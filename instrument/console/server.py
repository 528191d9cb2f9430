"""The console's web server: the page and one WebSocket per page, in a thread of its own.

aiohttp serves both the page's files and the WebSockets from one asyncio loop (the websockets
library would need its HTTP hook to serve files), and its writer applies back-pressure per
connection, which is how a slow page is found and dropped.

The frame loop never waits for this thread: it hands each frame over with one thread-safe call
(`publish`) and takes the pages' events from a deque (`take`). Each page has a sender task that
always sends the newest frame: a page that cannot keep up skips frames, and one that has not
taken a frame for SLOW_SECONDS is dropped. Nothing here writes to the terminal: notes for the
performer are queued and said by the frame loop's side (link.py).
"""

from __future__ import annotations

import asyncio
import json
import math
import secrets
import threading
from collections import deque
from dataclasses import dataclass, field
from importlib import resources
from typing import Callable
from urllib.parse import urlsplit

import numpy as np

from ..errors import UserError
from .messages import MAX_MESSAGE, Refused, parse

SLOW_SECONDS = 5.0  # a page that has not taken a frame for this long is dropped
INBOX_LIMIT = 10_000  # events waiting for the frame loop; beyond this a flood is refused
STATIC = {"/": ("index.html", "text/html"), "/console.js": ("console.js", "text/javascript"),
          "/console.css": ("console.css", "text/css")}
SECURITY = {"Content-Security-Policy": "default-src 'self'; img-src 'self' data:; connect-src 'self'",
            "Cache-Control": "no-store", "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer"}


@dataclass
class Frame:
    """What a page is sent each frame: the character's joints and every control value."""

    index: int
    positions: np.ndarray  # (J, 3) world positions, model units
    values: dict[str, float]  # every target's value (NaN: a part weight following its style)
    late: int
    dropped: int
    presets: list[str]
    sources: str

    def json(self, pages: int) -> str:
        values = {k: (None if math.isnan(v) else round(v, 4)) for k, v in self.values.items()}
        return json.dumps({"type": "frame", "frame": self.index, "late": self.late, "dropped": self.dropped,
                           "p": np.round(self.positions, 2).ravel().tolist(), "v": values, "presets": self.presets,
                           "sources": self.sources, "pages": pages}, separators=(",", ":"))


@dataclass(eq=False)
class Page:
    ws: object  # aiohttp.web.WebSocketResponse
    transport: object  # its TCP transport, aborted when the page is dropped
    newest: str | None = None
    ready: asyncio.Event = field(default_factory=asyncio.Event)
    sending_since: float | None = None


def split_address(address: str) -> tuple[str, int, bool]:
    """`[HOST:]PORT` as (host, port, host named); one-line error for anything else."""
    host, _, port = address.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        raise UserError(f"--console {address!r}: expected [HOST:]PORT") from None
    if not 0 <= number <= 65535:
        raise UserError(f"--console {address!r}: port must be 0 to 65535")
    return host or "127.0.0.1", number, bool(host)


class ConsoleServer:
    def __init__(self, address: str, hello: dict, targets: frozenset[str], token: str | None = None,
                 save: Callable[[], str] | None = None):
        import aiohttp  # noqa: F401  (imported here: only `run --console` needs it)

        self.host, port, named = split_address(address)
        # a named host may be reached from the network: then the page needs the token
        self.token = token or (secrets.token_urlsafe(16) if named else None)
        self.hello, self.targets, self.save = hello, targets, save
        self.files = {route: (resources.files(__package__).joinpath("static", name).read_bytes(), kind)
                      for route, (name, kind) in STATIC.items()}
        self.inbox: deque[tuple[str, float]] = deque()  # (control, value), taken by the frame loop
        self.notes: deque[tuple[str, str]] = deque()  # (key, text) for the performer; key "" = say, else warn
        self.refused = 0
        self.pages: set[Page] = set()
        self.loop = asyncio.new_event_loop()
        self.started = threading.Event()
        self.error: str | None = None
        self.port = port
        self.thread = threading.Thread(target=self._run, args=(port,), name="console", daemon=True)
        self.thread.start()
        self.started.wait(30)
        if self.error or not self.started.is_set():
            self.close()
            raise UserError(f"--console {address!r}: cannot listen: {self.error or 'the server did not start'}")

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    # --- the frame loop's side (any thread) -------------------------------------------------

    def publish(self, frame: Frame) -> None:
        """Hand a frame to every page; returns at once."""
        if self.pages:
            self.loop.call_soon_threadsafe(self._broadcast, frame)

    def take(self) -> list[tuple[str, float]]:
        out = []
        while self.inbox:
            out.append(self.inbox.popleft())
        return out

    def close(self) -> None:
        if self.thread.is_alive() and not self.loop.is_closed():
            self.loop.call_soon_threadsafe(self.loop.stop)  # run_forever stops at once, or as soon as it starts
        self.thread.join(10)

    # --- the server thread -------------------------------------------------------------------

    def _run(self, port: int) -> None:
        from aiohttp import web

        asyncio.set_event_loop(self.loop)
        app = web.Application(client_max_size=MAX_MESSAGE)
        app.router.add_get("/ws", self._socket)
        for route in self.files:
            app.router.add_get(route, self._file)
        app.router.add_get("/favicon.ico", lambda request: web.Response(status=204))
        runner = web.AppRunner(app, handle_signals=False, access_log=None)
        try:
            self.loop.run_until_complete(runner.setup())
            site = web.TCPSite(runner, self.host, port)
            self.loop.run_until_complete(site.start())
            self.port = site._server.sockets[0].getsockname()[1]  # the port chosen when 0 was asked for
        except OSError as e:
            self.error = e.strerror or str(e)
            self.loop.run_until_complete(runner.cleanup())
            self.loop.close()
            self.started.set()
            return
        self.started.set()
        try:
            self.loop.run_forever()
        finally:
            for page in list(self.pages):
                self._drop(page)
            self.loop.run_until_complete(runner.cleanup())
            self.loop.close()

    def _allowed(self, request) -> bool:
        """The token when one is needed, and no page of another site talking to us (a browser
        lets any web page open a WebSocket to 127.0.0.1: its Origin gives it away)."""
        if self.token is not None and not secrets.compare_digest(request.query.get("token", ""), self.token):
            return False
        origin = request.headers.get("Origin")
        return origin is None or urlsplit(origin).netloc == request.host

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
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE)  # no heartbeat: a stalled page is found by its frames
        await ws.prepare(request)
        page = Page(ws, request.transport)
        self.pages.add(page)
        self.notes.append(("", f"console: a page connected from {request.remote} ({len(self.pages)} open)"))
        sender = asyncio.ensure_future(self._sender(page))
        try:
            await ws.send_str(json.dumps(self.hello))
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
                self.pages.discard(page)
                self.notes.append(("", f"console: a page closed ({len(self.pages)} open)"))
        return ws

    def _receive(self, page: Page, text: str) -> None:
        try:
            kind, control, value = parse(text, self.targets)
        except Refused as refusal:
            self._refuse(page, str(refusal))
            return
        if kind == "save":
            self._save(page)
        elif len(self.inbox) >= INBOX_LIMIT:
            self._refuse(page, "too many messages at once")
        else:
            self.inbox.append((control, value))

    def _refuse(self, page: Page, reason: str) -> None:
        self.refused += 1
        self.notes.append(("console refused", f"console: refused a page's message: {reason}"))
        self._tell(page, {"type": "refused", "reason": reason})

    def _save(self, page: Page) -> None:
        if self.save is None:
            self._tell(page, {"type": "saved", "error": "no preset file: start with --presets FILE"})
            return
        try:
            said = self.save()
        except UserError as error:
            self.notes.append(("console save", f"console: {error}"))
            self._tell(page, {"type": "saved", "error": str(error)})
            return
        self.notes.append(("", f"console: {said}"))
        for other in self.pages:
            self._tell(other, {"type": "saved", "text": said})

    def _tell(self, page: Page, item: dict) -> None:
        if not page.ws.closed:
            asyncio.ensure_future(self._send_quietly(page, json.dumps(item)))

    @staticmethod
    async def _send_quietly(page: Page, text: str) -> None:
        try:
            await page.ws.send_str(text)
        except (ConnectionError, RuntimeError):
            pass

    def _broadcast(self, frame: Frame) -> None:
        text = frame.json(len(self.pages))  # once for all pages
        now = self.loop.time()
        for page in list(self.pages):
            if page.sending_since is not None and now - page.sending_since > SLOW_SECONDS:
                self._drop(page)
                self.notes.append(("console slow", f"console: dropped a page that took no frame for {SLOW_SECONDS:g} s"))
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
        self.pages.discard(page)
        if page.transport is not None:
            page.transport.abort()
