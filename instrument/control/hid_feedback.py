"""HID feedback: LEDs on while connected, and a light bar showing the leading style's colour.

Both are output reports sized and laid out from the device's report descriptor: LED-page
outputs (a SpaceMouse's LED) are set by usage; a light bar lives in a vendor-defined output
report (the DualShock 4's report 5), so the mapping file names its report and bytes:

    [feedback]
    leds = true                 # every LED-page output on while the device is connected
    report = 5                  # the output report carrying the light bar (length from the descriptor)
    fixed = { 1 = 2 }           # bytes that must be set for it to take effect (byte 1 = 0x02)
    light-bar = 6               # red, green, blue at bytes 6, 7, 8
    [feedback.colours]          # the leading style (largest weight above 0); "none" when no style leads
    elderly = "#ff8000"
    none = "#202020"

It is an output of the live loop: reports go out when the colour changes and again after each
reconnection; a device that is gone is the input's business (it reconnects), never an error here.
"""

from __future__ import annotations

import re
from collections.abc import Collection
from dataclasses import dataclass, field

from ..errors import quoted
from ..terminal import Console
from .checks import row_of, unknown
from .hid import LEDS, HidInput

FEEDBACK_KEYS = ("leds", "report", "fixed", "light-bar", "colours")
NO_STYLE = "none"  # the colour's name for no style leading


@dataclass(frozen=True)
class FeedbackSpec:
    leds: bool = False
    report: int | None = None
    fixed: tuple[tuple[int, int], ...] = ()
    light_bar: int | None = None  # byte of red; green and blue follow
    colours: dict[str, tuple[int, int, int]] = field(default_factory=dict)


def _colour(text: object) -> tuple[int, int, int] | None:
    match = re.fullmatch(r"#([0-9a-fA-F]{2})([0-9a-fA-F]{2})([0-9a-fA-F]{2})", str(text))
    return tuple(int(g, 16) for g in match.groups()) if match else None


def _byte(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 255


def parse_feedback(table: object, fail, model: tuple[Collection[str], int]) -> FeedbackSpec:
    """A mapping file's [feedback] table, checked; `fail(message, *path)` makes the error located at
    the key's full path ("feedback", "colours", name): a name alone is ambiguous (`name` or `report`
    under [feedback.colours] is also a key elsewhere, whose line it named). A colour is for a style
    of `model` (styles, states), checked as its `style/<name>` target would be (control/checks.py),
    or "none": a misspelt style's colour was kept and never shown."""
    if not isinstance(table, dict):
        raise fail("must be a table", "feedback")
    for key in table:
        if key not in FEEDBACK_KEYS:
            raise fail(f"unknown key in [feedback] (expected {', '.join(FEEDBACK_KEYS)})", "feedback", key)
    leds = table.get("leds", False)
    if not isinstance(leds, bool):
        raise fail("must be true or false", "feedback", "leds")
    report, light_bar = table.get("report"), table.get("light-bar")
    for key, value in (("report", report), ("light-bar", light_bar)):
        if value is not None and not _byte(value):
            raise fail("must be a whole number 0 to 255", "feedback", key)
    if (report is None) != (light_bar is None):
        raise fail("a light bar needs both report and light-bar", "feedback", "light-bar" if light_bar is None else "report")
    fixed = table.get("fixed", {})
    if not isinstance(fixed, dict) or not all(k.isdigit() and _byte(int(k)) and _byte(v) for k, v in fixed.items()):
        raise fail("expected { byte = value, ... }, whole numbers 0 to 255", "feedback", "fixed")
    colours = {}
    given = table.get("colours", {})
    if not isinstance(given, dict):  # colours = "#ff0000" (a crash before: no table to read)
        raise fail('expected a [feedback.colours] table of style = "#rrggbb"', "feedback", "colours")
    for name, text in given.items():
        if name != NO_STYLE and row_of(f"style/{name}", *model) is None:
            raise fail(f"{unknown(f'style/{name}', *model).text}; or {NO_STYLE}, for no style leading",
                       "feedback", "colours", name)
        colour = _colour(text)
        if colour is None:
            raise fail(f"{quoted(text)}: expected a colour as \"#rrggbb\"", "feedback", "colours", name)
        colours[name] = colour
    return FeedbackSpec(leds, report, tuple((int(k), v) for k, v in fixed.items()), light_bar, colours)


def leading_style(echo: dict[str, float]) -> str:
    """The style with the largest weight above 0, or "none"."""
    weights = {k[len("style/"):]: v for k, v in echo.items() if k.startswith("style/")}
    best = max(weights, key=weights.get, default=None)
    return best if best is not None and weights[best] > 0 else NO_STYLE


class HidFeedback:
    """Output reports for one HID input device, built from its descriptor and the mapping's [feedback]."""

    def __init__(self, device: HidInput, spec: FeedbackSpec, console: Console):
        self.device, self.spec, self.console = device, spec, console
        self.name = f"hid feedback {device.source}"
        self.connection = 0  # the device's connection the reports were last sent for
        self.colour: tuple[int, int, int] | None = None

    def _led_reports(self) -> list[bytes]:
        out = []
        for report_id, (length, fields) in self.device.descriptor.outputs.items():
            leds = [f for f in fields if f.page == LEDS]
            if not leds:
                continue
            value = report_id
            for f in leds:
                value |= (f.maximum & ((1 << f.size) - 1)) << f.bit
            out.append(self._framed(report_id, value.to_bytes(length, "little")))
        return out

    def _light_bar_report(self, colour: tuple[int, int, int]) -> bytes | None:
        spec = self.spec
        layout = self.device.descriptor.outputs.get(spec.report)
        if layout is None or spec.light_bar + 3 > layout[0] or any(b >= layout[0] for b, _ in spec.fixed):
            self.console.warn(self.name, f"{self.device.source}: its descriptor has no output report {spec.report} "
                              "long enough for the light bar; no light bar")
            return None
        data = bytearray(layout[0])
        data[0] = spec.report
        for at, value in spec.fixed:
            data[at] = value
        data[spec.light_bar:spec.light_bar + 3] = bytes(colour)
        return self._framed(spec.report, bytes(data))

    @staticmethod
    def _framed(report_id: int, data: bytes) -> bytes:
        return data if report_id else b"\x00" + data  # hidapi: unnumbered reports start with a 0 byte

    def prepare(self, frame) -> list[bytes]:
        echo = frame.echo
        if self.device.device is None or self.device.descriptor is None:
            return []
        fresh = self.device.connections != self.connection
        reports = self._led_reports() if fresh and self.spec.leds else []
        if self.spec.light_bar is not None:
            colours = self.spec.colours
            colour = colours.get(leading_style(echo), colours.get(NO_STYLE, (0, 0, 0)))
            if fresh or colour != self.colour:
                report = self._light_bar_report(colour)
                if report is not None:
                    reports.append(report)
                self.colour = colour
        self.connection = self.device.connections
        return reports

    def send(self, reports: list[bytes]) -> None:
        for report in reports:
            if not self.device.write(report):
                self.console.warn(self.name, f"{self.device.source} did not take a feedback report; trying again")
                self.connection = 0  # not taken: send everything again next frame
                self.colour = None

    def close(self) -> None:
        pass
