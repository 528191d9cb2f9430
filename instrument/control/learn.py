"""MIDI learn: work out, from a control being moved, what message and mode it sends."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Learned:
    message: str  # cc, cc14, nrpn, note, pitchbend
    channel: int
    number: int
    mode: str

    @property
    def button(self) -> bool:
        """Whether it can be a button that sets a value (mode "set": control/mapping.py)."""
        return self.message in ("note", "cc") and not self.mode.startswith("relative")

    def toml(self, target: str, value_range: tuple[float, float] | None, value: str | None = None) -> str:
        """The [[control]] table; with `value`, a button that sets the target to it (gait=run)."""
        lines = ["[[control]]", f'message = "{self.message}"']
        if self.channel != 1:
            lines.append(f"channel = {self.channel}")
        if self.message != "pitchbend":
            lines.append(f"number = {self.number}")
        if value is not None:
            return "\n".join(lines + ['mode = "set"', f'target = "{target}"', f'value = "{value}"']) + "\n"
        if self.mode != "absolute":
            lines.append(f'mode = "{self.mode}"')
        lines.append(f'target = "{target}"')
        if value_range is not None and not self.mode.startswith("relative") and self.message != "note":
            lines.append(f"range = [{value_range[0]}, {value_range[1]}]")
            lines.append('takeover = "pickup"')
        elif value_range is not None and self.message == "note" and not value_range[0] <= 0 < 1 <= value_range[1]:
            lines.append(f"range = [{value_range[0]}, {value_range[1]}]")  # a button's 0 and 1 would be out of range
        return "\n".join(lines) + "\n"


def detect(raw: list[tuple[str, float]]) -> Learned | None:
    """What sent these raw events (control id, value), in the order they came; None if nothing."""
    if not raw:
        return None
    kinds = [c.split("/") for c, _ in raw]
    notes = [(k, v) for k, (c, v) in zip(kinds, raw) if k[0] == "note"]
    if notes:
        return Learned("note", int(notes[0][0][1]), int(notes[0][0][2]), "momentary")
    bends = [k for k in kinds if k[0] == "pitchbend"]
    if bends:
        return Learned("pitchbend", int(bends[0][1]), 0, "absolute")
    ccs = [(int(k[1]), int(k[2]), int(v)) for k, (_, v) in zip(kinds, raw) if k[0] == "cc"]
    numbers = {n for _, n, _ in ccs}
    channel = ccs[0][0]
    if {99, 98} <= numbers:
        msb = next(v for _, n, v in ccs if n == 99)
        lsb = next(v for _, n, v in ccs if n == 98)
        mode = "absolute" if numbers & {6, 38} else "relative-twos"  # increment/decrement buttons still step
        return Learned("nrpn", channel, msb * 128 + lsb, mode)
    for n in sorted(numbers):
        if n < 32 and n + 32 in numbers:
            return Learned("cc14", channel, n, "absolute")
    number = max(numbers, key=lambda n: sum(1 for _, m, _ in ccs if m == n))
    values = [v for _, n, v in ccs if n == number]
    return Learned("cc", channel, number, _mode(values))


def _mode(values: list[int]) -> str:
    """Absolute, or the encoding of a relative encoder turned up first and then down."""
    if len(values) < 4:
        return "absolute"
    near = lambda v, centre: abs(v - centre) <= 15  # noqa: E731
    if not all(near(v, 0) or near(v, 64) or near(v, 128) for v in values) or any(v == 64 for v in values):
        return "absolute"
    half = len(values) // 2
    up, down = values[:half], values[half:]
    if all(1 <= v <= 15 for v in up):  # up is a small positive number
        return "relative-twos" if any(v >= 113 for v in down) else "relative-signed"
    if all(65 <= v <= 79 for v in up):  # up is just above 64
        return "relative-signed2" if any(v <= 15 for v in down) else "relative-offset"
    return "absolute"
