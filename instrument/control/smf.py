"""MIDI-only controller logs as Standard MIDI Files: type 1, one track per device, 1 ms ticks.

At 1000 ticks per beat and 60 beats per minute one tick is one millisecond, so event times
survive the round trip to the millisecond (a log's frame times are multiples of 1/fps, which
land back on the same frames when read). Track names carry the device (the log's `source`) in
UTF-8, which the SMF leaves open (mido's Latin-1 cannot hold a name like `Контроллер`); a name
that is not UTF-8 (an older file's Latin-1) is read as Latin-1.
"""

from __future__ import annotations

from pathlib import Path

import mido

from ..errors import UserError, printable, quoted
from .checks import raw_problem
from .events import ControlEvent

TICKS_PER_BEAT = 1000
TEMPO = 1_000_000  # microseconds per beat: 60 bpm, so a tick is a millisecond
MAX_DELTA = 0x0FFFFFFF  # ticks: the largest time between two events a MIDI file can hold (about 74 hours)


def _message(event: ControlEvent) -> mido.Message:
    kind, channel, number = (event.control.split("/") + ["", "", ""])[:3]
    channel = int(channel) - 1
    value = int(round(event.value))
    if kind == "cc":
        return mido.Message("control_change", channel=channel, control=int(number), value=value)
    if kind == "note":
        return mido.Message("note_on", channel=channel, note=int(number), velocity=value)
    if kind == "pitchbend":
        return mido.Message("pitchwheel", channel=channel, pitch=value - 8192)
    raise ValueError(event.control)


def export_smf(events: list[ControlEvent], path: str | Path, log: str | Path = "the log") -> int:
    """Write the MIDI events of a log (named `log` in errors); returns how many events were
    written. Each event is checked first as a device's raw event is (control/checks.py), so a log
    edited to hold channel 17 or t = 1e308 is refused naming the event, not written half."""
    tracks: dict[str, list[ControlEvent]] = {}
    for event in events:
        where = f"{log}: event {quoted(event.control)} of {quoted(event.source)} at t = {event.time:g} s"
        if not event.source.startswith("midi:"):
            raise UserError(f"{where}: only MIDI events go into a MIDI file")
        problem = raw_problem(event.source, event.control, event.value)
        if problem is not None:
            raise UserError(f"{where}: {problem}")
        previous = tracks.setdefault(event.source, [])
        if _tick(event) - (_tick(previous[-1]) if previous else 0) > MAX_DELTA:
            raise UserError(f"{where}: more than {MAX_DELTA // 3_600_000} hours after the event before it (a MIDI file cannot hold the gap)")
        previous.append(event)
    midi = mido.MidiFile(type=1, ticks_per_beat=TICKS_PER_BEAT, charset="utf-8")
    tempo = mido.MidiTrack([mido.MetaMessage("set_tempo", tempo=TEMPO, time=0)])
    midi.tracks.append(tempo)
    for source, track_events in tracks.items():
        track = mido.MidiTrack([mido.MetaMessage("track_name", name=source[len("midi:"):], time=0)])
        now = 0
        for event in track_events:
            tick = _tick(event)
            track.append(_message(event).copy(time=tick - now))
            now = tick
        midi.tracks.append(track)
    midi.save(str(path))
    return len(events)


def _tick(event: ControlEvent) -> int:
    return int(round(event.time * 1000)) if event.time < MAX_DELTA else MAX_DELTA + 1  # (1e308 s: past any gap)


def import_smf(path: str | Path, fps: float = 30.0) -> list[ControlEvent]:
    """Events of a MIDI file, each on the frame at or after its time (frames of `fps`)."""
    from .devices import midi_raw

    try:
        midi = mido.MidiFile(str(path))
    except OSError as e:
        if e.errno is not None:  # a missing or unreadable file, said as every other input says it (mido's own
            raise UserError(f"{path}: cannot read: {e.strerror or e}") from None  # "MThd not found" has no errno)
        raise UserError(f"{path}: not a readable MIDI file ({printable(str(e), 120)})") from None
    except (EOFError, ValueError, KeyError, IndexError) as e:  # (mido's parser: whatever a broken file makes it raise)
        why = "it ends before its header or a track does" if isinstance(e, EOFError) and not str(e) else str(e)
        raise UserError(f"{path}: not a readable MIDI file ({printable(why, 120)})") from None
    if midi.ticks_per_beat <= 0:  # (mido reads the field signed: SMPTE timing is negative)
        raise UserError(f"{path}: the MIDI file's time division is {midi.ticks_per_beat}: expected ticks per beat above 0 "
                        "(SMPTE time is not read)")
    scale = 1.0 / midi.ticks_per_beat  # beats per tick; tempo is read from the file
    events: list[ControlEvent] = []
    tempo = 500_000
    for track in midi.tracks:
        name = _utf8(next((m.name for m in track if m.type == "track_name"), "midi"))
        seconds, tick_tempo = 0.0, tempo
        for message in track:
            seconds += message.time * scale * tick_tempo / 1e6
            if message.type == "set_tempo":
                tick_tempo = tempo = message.tempo
                continue
            raw = midi_raw(message) if not message.is_meta else None
            if raw is not None:
                frame = round(seconds * fps)
                events.append(ControlEvent(frame / fps, f"midi:{name}", raw[0], raw[1]))
    events.sort(key=lambda e: e.time)
    return events


def _utf8(name: str) -> str:
    """A track name mido read as Latin-1, as the UTF-8 it was written in (else as it was read)."""
    try:
        return name.encode("latin-1").decode("utf-8")
    except UnicodeError:
        return name
