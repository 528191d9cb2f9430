"""Devices and their kinds: the protocol every input device follows, and the registry that says,
by kind, how a device's raw events become target values.

A device (a MIDI port, a HID controller, an OSC surface, the console, a log, a score, or one of
your own: docs/extending.md) is polled once a frame and hands out `RawEvent`s whose `source`
names its kind and itself. The hub looks the kind up here: a `DeviceKind` says which mappings
read that kind (none for a direct kind, whose control ids are target names) and makes the
decoder of one device, so each device has its own (two MIDI controllers, two mappings, two
decoders). The same rule decides, before a replay starts, whether the log's devices have the
mappings they need (control/loghead.py), so the hub and the log reader cannot disagree.

The built-in kinds are registered below; a kind not registered is direct (an old log's "demo").
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol

from .events import RawEvent, Source, TargetEvent
from .mapping import Mapper, Mapping
from .spec import TABLE
from .targets import raw_problem

SPEED_RANGE = (TABLE["speed"].low, TABLE["speed"].high)  # what the lock may set, as the performer

if TYPE_CHECKING:  # (the hub and the state pull in numpy and the synthesis: not needed to read a mapping)
    from .hub import ControlHub
    from .state import ControlState


class Device(Protocol):
    """An input device as the live loop sees it. It never raises into the performance: a device
    that goes away says so on the console, returns no events and tries again. A single device
    also has `source`, the `Source` its events carry (its kind and its name, stable all run long:
    the hub keeps one decoder per source)."""

    def poll(self, now: float) -> list[RawEvent]:
        """What came since the last poll, stamped `now` (performance seconds); quick, never blocking."""

    def describe(self) -> str:
        """One short line for the status and health lines: which device, and whether it is on."""

    def close(self) -> None:
        """Let the device go (the end of the show, or a start-up that failed)."""


class Decoder(Protocol):
    """Turns the raw events of one device into target values in the control state."""

    def apply(self, state: ControlState, event: RawEvent) -> str | None:
        """Apply one event; None once applied, else why it was refused ("not mapped", ...)."""


DecoderFactory = Callable[["Mapping | None", "ControlHub"], Decoder]


@dataclass(frozen=True)
class DeviceKind:
    name: str  # the first part of a source: "midi" in "midi:nanoKONTROL2"
    title: str  # in messages: "no MIDI mapping"
    decoder: DecoderFactory  # a new device's decoder, given its mapping (None for a direct kind) and the hub
    reads: Callable[[Mapping], bool] | None = None  # whether a mapping is for devices of this kind; None: direct
    fits: Callable[[Mapping, str], int] = lambda mapping, name: 0  # how well a mapping fits the device `name`

    def mapping_for(self, name: str, mappings: list[Mapping]) -> Mapping | None:
        """Of the mappings that read this kind, the one fitting device `name` best (the first on a tie)."""
        readers = [m for m in mappings if self.reads is not None and self.reads(m)]
        return max(readers, key=lambda m: self.fits(m, name), default=None)


class DirectDecoder:
    """A direct device: its control ids are target names (speed, style/NAME, preset/NAME, ...)."""

    def __init__(self, mapping: None, hub: ControlHub):
        self.hub = hub

    def apply(self, state: ControlState, event: RawEvent) -> str | None:
        return self.hub.apply_target(state, TargetEvent(event.time, event.control, event.value))


class MappedDecoder:
    """A device read through its mapping: the raw event is checked (a MIDI id, a HID value in its
    range), then the mapping's `Mapper` (14-bit pairs, NRPN, relative encoders, pick-up) turns it
    into target events, which the hub checks and applies as it does a direct device's. One per
    device: what a control remembers is its own."""

    def __init__(self, mapping: Mapping, hub: ControlHub):
        self.mapper = Mapper(mapping, hub.presets)
        self.hub = hub

    def apply(self, state: ControlState, event: RawEvent) -> str | None:
        """None once the mapping used the raw event (so it is recorded: what its controls remember
        moved, and a replay needs it), whether or not the state took its targets (a target the
        model lacks was warned about at the start)."""
        why = raw_problem(event.source, event.control, event.value)
        if why is not None:
            return why
        targets = self.mapper.decode(state, event)
        if targets is None:
            return "not mapped"
        for target in targets:
            self.hub.apply_target(state, target)
        return None


class TempoDecoder:
    """The beat lock's decisions (runtime/tempo.py), events of source `tempo`: `speed/K` is the
    speed the lock set for character K at one of its footfalls. They are events like a device's
    so a `--record` log keeps them and `run --replay` plays the synced performance exactly."""

    def __init__(self, mapping: None, hub: ControlHub):
        pass

    def apply(self, state: ControlState, event: RawEvent) -> str | None:
        kind, _, character = event.control.partition("/")
        if kind != "speed" or not character.isdigit():
            return "unknown target"
        low, high = SPEED_RANGE
        if not low <= event.value <= high:
            return "out of range"
        state.lock_speeds[int(character)] = float(event.value)
        return None


REGISTRY: dict[str, DeviceKind] = {}
DIRECT = DeviceKind("direct", "direct", DirectDecoder)  # any kind not registered


def register(kind: DeviceKind) -> None:
    """Make a kind of device known (again: a later registration of the same name wins)."""
    REGISTRY[kind.name] = kind


def kind(name: str) -> DeviceKind:
    return REGISTRY.get(name, DIRECT)


def unreadable_kinds(sources: set[str], mappings: list[Mapping]) -> list[str]:
    """Titles of the kinds ("MIDI", "HID") of these sources that need a mapping and have none."""
    kinds = {Source(s).kind for s in sources}
    return [k.title for name, k in REGISTRY.items()
            if name in kinds and k.reads is not None and not any(k.reads(m) for m in mappings)]


def midi_fits(mapping: Mapping, name: str) -> int:
    """2: the mapping's port pattern and the device's name (a port name or the pattern it was
    opened by) match one another; 1: a mapping for any port ("."); 0: neither (or not a MIDI mapping)."""
    if mapping.midi is None:
        return 0
    if mapping.midi == ".":
        return 1
    try:
        return 2 if re.search(mapping.midi, name, re.IGNORECASE) or re.search(name, mapping.midi, re.IGNORECASE) else 0
    except re.error:  # a device name that is not a pattern
        return 0


def _hid_fits(mapping: Mapping, name: str) -> int:
    """2: the mapping names the device's vendor:product; 1: it fits devices by usages."""
    if mapping.hid and any(f"{v:04x}:{p:04x}" == name for v, p in mapping.hid):
        return 2
    return 1 if mapping.hid_usages else 0


register(DeviceKind("midi", "MIDI", MappedDecoder, lambda m: m.midi is not None, midi_fits))
register(DeviceKind("hid", "HID", MappedDecoder, lambda m: m.hid is not None or bool(m.hid_usages), _hid_fits))
register(DeviceKind("tempo", "tempo", TempoDecoder))
for _direct in ("osc", "console", "score"):  # named, so that docs and messages can list them
    register(DeviceKind(_direct, _direct, DirectDecoder))
