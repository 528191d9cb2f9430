"""The console as the frame loop sees it: a control source like a MIDI port, and an output like
an OSC target. Both run in the frame loop's thread; the server runs in its own process
(server.py), reached over a socket pair of whole packets that is never waited on."""

from __future__ import annotations

import json
import secrets
import socket
import subprocess
import sys
from typing import Callable

import numpy as np

from ..control.events import ControlEvent
from ..control.state import ControlState
from ..control.targets import MAX_TURN, TABLE, WEIGHT_LIMIT
from ..control.values import all_values
from ..errors import UserError
from ..terminal import Console
from ..synthesis.posing import CrowdPose, Pose
from ..synthesis.durations import MAX_SPEED, MIN_SPEED
from ..synthesis.interpolation import GROUPS
from .server import JSON, frame_packet

SOURCE = "console"  # the source name of the page's events in a controller log
SLIDER_WEIGHTS = (-2.0, 4.0)  # the style sliders' travel; the number box beside takes the whole +-WEIGHT_LIMIT
MORPH_SLIDER = (0.0, 10.0)  # the morph time slider's travel in seconds; the number box takes the table's whole range
START_SECONDS = 60.0  # the server process has this long to start listening (a busy machine imports slowly)
EVERY_INTERFACE = ("0.0.0.0", "")  # a host meaning "listen on every interface": not an address to open
SOURCES_EVERY = 15  # frames between two updates of the control sources shown on the pages


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


def hello(model, state: ControlState, presets: dict, save_path: str | None, fps: float) -> dict:
    """What a page is told once, on connecting: the model's styles and skeleton, the ranges."""
    skeleton = model.layout.skeleton
    return {
        "type": "hello", "styles": state.style_names, "groups": list(GROUPS), "states": state.states,
        "joints": list(skeleton.names), "parents": [j.parent for j in skeleton.joints], "root": model.layout.root,
        "fps": fps, "save": save_path, "presets": sorted(presets), "order": list(all_values(state)),
        "ranges": {"weight": [-WEIGHT_LIMIT, WEIGHT_LIMIT], "slider": list(SLIDER_WEIGHTS), "speed": [MIN_SPEED, MAX_SPEED],
                   "turn": [-MAX_TURN, MAX_TURN], "liveliness": [TABLE["liveliness"].low, TABLE["liveliness"].high],
                   "spread": [TABLE["spread"].low, TABLE["spread"].high], "phase": [MIN_SPEED, MAX_SPEED],
                   "morph": [TABLE["morph"].low, TABLE["morph"].high], "morph_slider": list(MORPH_SLIDER)},
    }


class ConsoleLink:
    """Starts the server process; `input` is the device the hub polls, `output` the frame sink."""

    def __init__(self, address: str, model, state: ControlState, presets: dict[str, dict[str, float]], console: Console,
                 fps: float, token: str | None = None, save_path: str | None = None,
                 sources: Callable[[], str] = lambda: ""):
        host, port, named = split_address(address)
        # a named host may be reached from the network: then the page needs the token
        self.token = token or (secrets.token_urlsafe(16) if named else None)
        self.host, self.pages, self.open = host, 0, True
        # looked up once (a host name lookup may wait on DNS): describe() is called from the frame loop
        self.addresses = network_addresses() if host in EVERY_INTERFACE else []
        self.sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.process = subprocess.Popen([sys.executable, "-m", "instrument.console.server", str(theirs.fileno())],
                                        pass_fds=[theirs.fileno()])
        theirs.close()
        config = {"host": host, "port": port, "token": self.token, "targets": state.targets(), "save": save_path,
                  "hello": hello(model, state, presets, save_path, fps)}
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
        self.output = ConsoleOutput(self, state, presets, sources)

    def url_at(self, host: str) -> str:
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    @property
    def url(self) -> str:
        """The URL to open: on a console listening on every interface, at this machine's network address."""
        if self.host in EVERY_INTERFACE:
            return self.url_at(next(iter(self.addresses), "127.0.0.1"))
        return self.url_at(self.host)

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

    def send(self, packet: bytes) -> None:
        """To the server, never waiting: when its queue is full (a stalled server) the packet is dropped."""
        if self.open:
            try:
                self.sock.send(packet)
            except BlockingIOError:
                pass
            except OSError:  # the server process is gone: the input says so
                self.open = False

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
                self.link.open = False
                self.console.warn("console gone", "console: the server process stopped; the show goes on without it")
                break
            item = json.loads(packet[1:])
            if "event" in item:
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
        return f"console {self.link.url} ({self.link.pages} pages)"

    def close(self) -> None:
        self.link.close()


SHOWN_CHARACTERS = 20  # of a crowd, the most the page draws (character 0, which it follows, and the next)


class ConsoleOutput:
    """Hands each frame to the server as one packet; costs nothing while no page is open. Of a
    crowd it sends the first SHOWN_CHARACTERS (a page's frame grows by about 0.5 kB of JSON a character of 22 joints)."""

    name = "console"
    whole_crowd = True  # the live loop hands it every character's pose

    def __init__(self, link: ConsoleLink, state: ControlState, presets: dict, sources: Callable[[], str]):
        self.link, self.state, self.presets, self.sources = link, state, presets, sources
        self.clock = None
        self.sent_presets: tuple = ()

    def watch(self, clock) -> None:
        """Given the frame clock, so the pages show late and dropped frames."""
        self.clock = clock

    def prepare(self, pose: Pose | CrowdPose, echo: dict[str, float]) -> list[bytes] | None:
        if not self.link.pages:
            return None
        packets = []
        stored = tuple(map(id, self.presets.values()))  # a stored preset is a new dict: cheap to notice
        if stored != self.sent_presets:
            self.sent_presets = stored
            packets.append(JSON + json.dumps({"presets": self.presets}).encode("utf-8"))
        if pose.index % SOURCES_EVERY == 0:
            packets.append(JSON + json.dumps({"sources": self.sources()}).encode("utf-8"))
        late, dropped = (self.clock.late, self.clock.dropped) if self.clock else (0, 0)
        values = np.fromiter(all_values(self.state).values(), float)
        positions = pose.world_positions  # (joints, 3), or (characters, joints, 3) of a crowd
        if positions.ndim == 3:
            positions = positions[:SHOWN_CHARACTERS]
        packets.append(frame_packet(pose.index, late, dropped, positions, values))
        return packets

    def send(self, packets: list[bytes]) -> None:
        for packet in packets:
            self.link.send(packet)

    def close(self) -> None:
        pass  # the server is closed with the input, after the loop
