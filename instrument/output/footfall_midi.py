"""Footfalls as MIDI notes (`run --midi-out NAME`): a sampler plays the footsteps.

Each foot contact of character 0 (synthesis/footfalls.py) is a note on a virtual MIDI output port
that a sampler or a DAW connects to: LEFT_NOTE for the left foot, RIGHT_NOTE for the right, on
channel CHANNEL (the General MIDI drum channel, where 36 and 38 are a kick and a snare), with a
velocity from the foot's speed at impact (FULL_SPEED m/s or faster: 127). The note is let go
the next frame. A port that cannot send is said on the console (the walk goes on)."""

from __future__ import annotations

from ..control.devices import midi_backend, midi_system
from ..control.jackwatch import release
from ..synthesis.posing import Frame

LEFT_NOTE, RIGHT_NOTE = 36, 38
CHANNEL = 9  # mido's 0-based channel: MIDI channel 10
FULL_SPEED = 1.5  # m/s of a foot at impact that gives velocity 127
MIN_VELOCITY = 1  # a note on with velocity 0 is a note off


def velocity(speed: float) -> int:
    """A footfall's velocity: its impact speed over FULL_SPEED, 1 to 127."""
    return max(MIN_VELOCITY, min(127, round(127 * speed / FULL_SPEED)))


class FootfallMidi:
    """A sink sending character 0's footfalls as notes on a virtual MIDI output port."""

    character = 0

    def __init__(self, name: str, api: str | None = None):
        import mido

        self.mido = mido
        self.name = f"midi-out {name}"
        with midi_system(api):  # no MIDI system: one line naming the fix
            self.port = midi_backend(api).open_output(name, virtual=True)
        self.sounding: list[int] = []  # notes on since the frame before

    def prepare(self, frame: Frame) -> list | None:
        notes = [LEFT_NOTE if f.side == 0 else RIGHT_NOTE for f in frame.footfalls if f.character == self.character]
        speeds = [f.speed for f in frame.footfalls if f.character == self.character]
        messages = [self.mido.Message("note_off", channel=CHANNEL, note=n) for n in self.sounding]
        messages += [self.mido.Message("note_on", channel=CHANNEL, note=n, velocity=velocity(s)) for n, s in zip(notes, speeds)]
        self.sounding = notes
        return messages or None

    def send(self, messages: list) -> None:
        for message in messages:
            self.port.send(message)

    def close(self) -> None:
        for note in self.sounding:
            self.port.send(self.mido.Message("note_off", channel=CHANNEL, note=note))
        release(self.port, self.port.close)
