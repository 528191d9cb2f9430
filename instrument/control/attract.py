"""Attract mode for installations: when nobody has touched a control for a while, the walk
drifts on its own (a score, or a tour of presets) until a performer moves something.

It sits between the devices and the hub as one more control source: it passes every device
event on, and while the room is idle it adds the events of its score. The first event from a
device ends it at once; the state stays where the drift left it, so a fader with pick-up
(`takeover = "pickup"`) takes over only when it reaches its parameter and nothing jumps.
Idle time is performance time, so a recorded log replays the same.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..errors import UserError
from ..terminal import Console
from ..tomlfile import read_toml
from .events import ControlEvent
from .score import Score, ScorePlayer, load_score, preset_tour
from .state import ControlState

SOURCE = "attract"
KEYS = ("after", "score", "presets", "morph", "hold")


@dataclass(frozen=True)
class AttractSettings:
    after: float  # seconds of performance time without device input
    score: Score


def load_attract(show: str | Path, state: ControlState, presets: dict[str, dict[str, float]]) -> AttractSettings | None:
    """The show file's [attract] table, checked; None when it has none."""
    show = Path(show)
    text, data = read_toml(show)
    table = data.get("attract")
    if table is None:
        return None

    def fail(message: str, key: str) -> UserError:
        begin = max(text.find("[attract]"), 0)
        at = text.find(key, begin)
        return UserError(f"{show}:{text.count(chr(10), 0, at if at >= 0 else begin) + 1}: attract.{key}: {message}")

    if not isinstance(table, dict):
        raise fail("expected an [attract] table", "attract")
    for key in table:
        if key not in KEYS:
            raise fail(f"unknown key (expected one of {', '.join(KEYS)})", key)
    for key in ("after", "morph", "hold"):
        value = table.get(key)
        if value is not None and (not isinstance(value, (int, float)) or isinstance(value, bool) or not value > 0):
            raise fail("expected a positive number" + (" of minutes" if key == "after" else " of seconds"), key)
    if "after" not in table:
        raise fail("missing: minutes without performer input before the walk drifts on its own", "after")
    if ("score" in table) == ("presets" in table):
        raise fail("give either score (a score file) or presets (a list of preset names)", "score")
    if "score" in table:
        if not isinstance(table["score"], str):
            raise fail("expected the path of a score file", "score")
        score = load_score(show.parent / table["score"], state, presets, loop=True)
    else:
        names = table["presets"]
        if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
            raise fail("expected a list of preset names", "presets")
        for name in names:
            if name not in presets:
                raise fail(f"no preset {name!r} (known: {', '.join(sorted(presets)) or 'none'})", "presets")
        score = preset_tour(names, presets, float(table.get("morph", 8.0)), float(table.get("hold", 30.0)))
    return AttractSettings(float(table["after"]) * 60.0, score)


class Attract:
    """One control source made of the devices' own, plus the idle drift."""

    def __init__(self, settings: AttractSettings, sources: list[Callable[[float], list[ControlEvent]]],
                 state: ControlState, console: Console):
        self.settings, self.sources, self.state, self.console = settings, sources, state, console
        self.last_input = 0.0  # performance time of the last device event
        self.player: ScorePlayer | None = None

    @property
    def active(self) -> bool:
        return self.player is not None

    def poll(self, now: float) -> list[ControlEvent]:
        events = [event for source in self.sources for event in source(now)]
        if events:
            self.last_input = now
            if self.player is not None:
                self.player = None
                self.console.say(f"attract mode off at {now:.1f} s: a performer is back")
            return events
        if self.player is None and now - self.last_input >= self.settings.after:
            self.player = ScorePlayer(self.settings.score, self.state, start=now, source=SOURCE)
            self.console.say(f"attract mode on at {now:.1f} s: no input for {self.settings.after / 60:g} min, "
                             f"playing {self.settings.score.name}")
        return self.player.due(now) if self.player is not None else []
