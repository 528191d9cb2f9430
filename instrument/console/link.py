"""The console as the frame loop sees it: a control source like a MIDI port, and an output like
an OSC target. Both run in the frame loop's thread; the server runs in its own process
(server.py), reached over a socket pair of whole packets that is never waited on."""

from __future__ import annotations

import errno
import json
import secrets
import socket
import subprocess
import sys
from collections.abc import Callable, Collection

import numpy as np

from ..control.options import host_port
from ..control.events import ControlEvent
from ..control.hub import MAX_PRESETS
from ..control.state import ControlState
from ..control.spec import rows_for_page
from ..control.values import all_values
from ..errors import UserError
from ..terminal import Console
from ..synthesis.posing import Frame
from ..models.gestures import gesture_labels
from ..synthesis.interpolation import GROUPS
from .presets import check_presets_file
from .server import JSON, MAX_PACKET, frame_packet

SOURCE = "console"  # the source name of the page's events in a controller log
START_SECONDS = 60.0  # the server process has this long to start listening (a busy machine imports slowly)
EVERY_INTERFACE = ("0.0.0.0", "")  # a host meaning "listen on every interface": not an address to open
SOURCES_EVERY = 15  # frames between two updates of the control sources shown on the pages
PRESETS_PART = 32 * 1024  # bytes of presets a packet carries at most: a big table goes over in parts
GONE = (errno.EPIPE, errno.ECONNRESET, errno.ENOTCONN, errno.EBADF)  # the server's end of the pair is closed


def split_address(address: str) -> tuple[str, int, bool]:
    """`[HOST:]PORT` as (host, port, host named); one-line error for anything else."""
    return host_port("run --console", address)


def network_addresses() -> list[str]:
    """This machine's IPv4 addresses another machine may reach, the outbound interface's first.

    The outbound one is found by connecting a UDP socket (which sends nothing) towards an address
    outside this machine and reading which local address the system chose; the others are the
    host name's addresses. Loopback addresses are left out: a tablet cannot open them."""
    found = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("10.254.254.254", 9))  # any address off this machine; no packet is sent
            found.append(probe.getsockname()[0])
        except OSError:  # no route: no network, or only loopback
            pass
    try:
        found += [info[4][0] for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)]
    except OSError:
        pass
    return list(dict.fromkeys(a for a in found if not a.startswith("127.") and a != "0.0.0.0"))


def hello(model, state: ControlState, save_path: str | None, fps: float, has: Collection[str] = ()) -> dict:
    """What a page is told once, on connecting: the model's styles and skeleton, the ranges of the
    targets this run can use (`has`: control/spec.py's NEEDS the run meets), and the server adds
    the names of the presets it holds."""
    skeleton = model.layout.skeleton
    return {
        "type": "hello", "styles": state.style_names, "groups": list(GROUPS), "states": state.states,
        "gestures": list(gesture_labels(model.metadata)),  # the gesture buttons: those the model holds
        "joints": list(skeleton.names), "parents": [j.parent for j in skeleton.joints], "root": model.layout.root,
        "fps": fps, "save": save_path, "order": list(all_values(state)),
        "rows": rows_for_page(has),  # the sliders: control/spec.py's rows (console.js builds them from these)
    }


class ConsoleLink:
    """Starts the server process; `input` is the device the hub polls, `output` the frame sink."""

    def __init__(self, address: str, model, state: ControlState, presets: dict[str, dict[str, float]], console: Console,
                 fps: float, token: str | None = None, save_path: str | None = None,
                 sources: Callable[[], str] = lambda: "", has: Collection[str] = ()):
        host, port, named = split_address(address)
        if save_path is not None:
            check_presets_file(save_path)  # at start, not at the first save: a show file given by mistake
        # a named host may be reached from the network: then the page needs the token
        self.token = token or (secrets.token_urlsafe(16) if named else None)
        self.host, self.pages, self.open, self.console = host, 0, True, console
        self.failure: str | None = None  # why the link stopped, once it has
        self.save_asked = False  # a page asked to save: the presets then the save go to the server in order
        # looked up once (a host name lookup may wait on DNS): describe() is called from the frame loop
        self.addresses = network_addresses() if host in EVERY_INTERFACE else []
        self.sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.process = subprocess.Popen([sys.executable, "-m", "instrument.console.server", str(theirs.fileno())],
                                        pass_fds=[theirs.fileno()])
        theirs.close()
        config = {"host": host, "port": port, "token": self.token, "targets": state.targets(), "save": save_path,
                  "max_presets": MAX_PRESETS, "hello": hello(model, state, save_path, fps, has)}
        self.sock.sendall(JSON + json.dumps(config).encode("utf-8"))
        self.sock.settimeout(START_SECONDS)
        try:
            answer = json.loads(self.sock.recv(1 << 16)[1:] or b"{}")
        except (OSError, ValueError):
            answer = {}
        if "ready" not in answer:
            self.close()
            raise UserError(f"--console {address!r}: cannot listen: {answer.get('error', 'the server did not start')}")
        self.port = answer["ready"]
        self.sock.setblocking(False)
        self.input = ConsoleInput(self, console)
        self.output = ConsoleOutput(self, presets, sources)

    def url_at(self, host: str, token: bool = True) -> str:
        """The page's URL at `host`; with the token only when told at start (never in a health line)."""
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token and token else "")

    def page_url(self, token: bool = True) -> str:
        """The URL to open: on a console listening on every interface, at this machine's network address."""
        if self.host in EVERY_INTERFACE:
            return self.url_at(next(iter(self.addresses), "127.0.0.1"), token)
        return self.url_at(self.host, token)

    @property
    def url(self) -> str:
        return self.page_url()

    def announcement(self) -> list[str]:
        """The lines said at start: the URL to open, and on every interface, which address is for what."""
        if self.host not in EVERY_INTERFACE:
            return [f"console: {self.url}"]
        addresses = self.addresses
        if not addresses:
            return [f"console: {self.url_at('127.0.0.1')} (listening on {self.host}, but this machine has no network "
                    "address: only this machine can open the console)"]
        lines = [f"console: {self.url_at(addresses[0])} (open this on a tablet or computer on the network)"]
        lines += [f"console: {self.url_at(a)} (another address of this machine)" for a in addresses[1:]]
        return lines + [f"console: {self.url_at('127.0.0.1')} (on this machine)"]

    def send(self, packet: bytes) -> bool:
        """To the server, never waiting; True if it went. When the server's queue is full (a
        stalled server) the packet is not sent: a frame is simply skipped, presets go next frame."""
        if not self.open:
            return False
        if len(packet) > MAX_PACKET:  # a packet the pair cannot carry: refused here, said, the link goes on
            self.console.warn("console packet", f"console: a {len(packet)}-byte packet is too large for the link; not sent")
            return False
        try:
            self.sock.send(packet)
            return True
        except BlockingIOError:
            return False
        except OSError as error:
            if error.errno in GONE:
                self.lost(f"the server process stopped ({error.strerror})")
            else:  # no memory for the packet, or too large after all: this one is lost, the link goes on
                self.console.warn("console packet", f"console: a packet to the server failed ({error.strerror or error})")
            return False

    def lost(self, why: str) -> None:
        """The link is gone for good: said once on the console, and in health (the output is down)."""
        if self.open:
            self.open, self.failure = False, why
            self.console.warn("console gone", f"console: {why}; the show goes on without it")

    def close(self) -> None:
        self.open = False
        self.sock.close()  # the server sees the end of the pair and stops
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


class ConsoleInput:
    """The pages' events, stamped with the frame time like a MIDI port's; says the server's notes."""

    source = SOURCE

    def __init__(self, link: ConsoleLink, console: Console):
        self.link, self.console = link, console

    def poll(self, now: float) -> list[ControlEvent]:
        events = []
        while self.link.open:
            try:
                packet = self.link.sock.recv(1 << 16)
            except BlockingIOError:
                break
            except OSError:
                packet = b""
            if not packet:
                self.link.lost("the server process stopped")
                break
            item = json.loads(packet[1:])
            if "save" in item:  # sent on by the output, after the presets stored so far (ConsoleOutput.prepare)
                self.link.save_asked = True
            elif "event" in item:
                control, value = item["event"]
                events.append(ControlEvent(now, SOURCE, control, float(value)))
            elif "note" in item:
                key, text = item["note"]
                if key:
                    self.console.warn(key, text)
                else:
                    self.console.say(text)
            elif "pages" in item:
                self.link.pages = item["pages"]
        return events

    def describe(self) -> str:
        """For the status line, health lines and status replies: never the token."""
        if self.link.failure:
            return f"console {self.link.page_url(token=False)} (stopped: {self.link.failure})"
        return f"console {self.link.page_url(token=False)} ({self.link.pages} {'page' if self.link.pages == 1 else 'pages'})"

    def close(self) -> None:
        self.link.close()


SHOWN_CHARACTERS = 20  # of a crowd, the most the page draws (character 0, which it follows, and the next)


class ConsoleOutput:
    """Hands each frame to the server as one packet; frames cost nothing while no page is open. Of a
    crowd it sends the first SHOWN_CHARACTERS (a page's frame grows by about 0.5 kB of JSON a character of 22 joints).

    The presets go to the server whether a page is open or not (a save needs them), as they change:
    each stored preset once, in packets of at most PRESETS_PART bytes, each marked sent only once it
    went (a full queue sends the rest next frame). A save a page asked for follows them, so what is
    saved is every preset stored before it."""

    name = "console"

    def __init__(self, link: ConsoleLink, presets: dict, sources: Callable[[], str]):
        self.link, self.presets, self.sources = link, presets, sources
        self.clock = None
        self.sent_presets: dict[str, dict] = {}  # name -> the preset (the very dict) the server has
        self.sent_all: int | None = None  # the presets' store count (hub.Presets.stored) when the server had them all

    @property
    def down(self) -> bool:
        """The link has failed: health shows the console as down."""
        return not self.link.open

    def watch(self, clock) -> None:
        """Given the frame clock, so the pages show late and dropped frames."""
        self.clock = clock

    def prepare(self, frame: Frame) -> list[tuple[bytes, Callable | None]] | None:
        """The packets of this frame, each with what to note once it went."""
        packets = self._preset_packets()
        if self.link.save_asked:
            # with how many there are: a server that holds fewer (one too large for the link) does not save
            packets.append((JSON + json.dumps({"save": len(self.presets)}).encode("utf-8"), self._saved))
        if self.link.pages:
            if frame.index % SOURCES_EVERY == 0:
                packets.append((JSON + json.dumps({"sources": self.sources()}).encode("utf-8"), None))
            late, dropped = (self.clock.late, self.clock.dropped) if self.clock else (0, 0)
            values = np.fromiter(frame.values.values(), float)
            positions = frame.crowd.world_positions[:SHOWN_CHARACTERS]  # (characters, joints, 3)
            packets.append((frame_packet(frame.index, late, dropped, positions, values), None))
        return packets or None

    def _preset_packets(self) -> list[tuple[bytes, Callable]]:
        """The presets stored since the server last had them, in parts (a stored preset is a new dict)."""
        stored = getattr(self.presets, "stored", None)  # a plain dict (the bench's) is compared every frame
        if stored is not None and stored == self.sent_all:
            return []
        sent = self.sent_presets
        changed = [(name, values) for name, values in self.presets.items() if sent.get(name) is not values]
        packets, part, size = [], {}, 0
        for name, values in changed:
            text = json.dumps({name: values})
            if len(text) > PRESETS_PART:  # only a preset file's own names can be that long: not on the pages
                sent[name] = values
                self.link.console.warn("console preset", f"console: preset {name[:40]!r}... is too large for the pages (and a save)")
                continue
            if part and size + len(text) > PRESETS_PART:
                packets.append(self._presets_packet(part))
                part, size = {}, 0
            part[name], size = values, size + len(text)
        if part:
            packets.append(self._presets_packet(part))
        if not packets:
            self.sent_all = stored
        else:  # once the last part went, the server has them all (a part not sent: compared again next frame)
            packet, went = packets[-1]
            packets[-1] = (packet, lambda: (went(), setattr(self, "sent_all", stored)))
        return packets

    def _presets_packet(self, part: dict[str, dict]) -> tuple[bytes, Callable]:
        return JSON + json.dumps({"presets": part}).encode("utf-8"), lambda: self.sent_presets.update(part)

    def _saved(self) -> None:
        self.link.save_asked = False

    def send(self, packets: list[tuple[bytes, Callable | None]]) -> None:
        for packet, went in packets:
            if not self.link.send(packet):
                return  # in order or not at all: what follows waits for the next frame
            if went is not None:
                went()

    def close(self) -> None:
        pass  # the server is closed with the input, after the loop
