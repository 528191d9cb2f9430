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

from ..errors import UserError, quoted
from ..terminal import Console
from ..tomlfile import Field, TomlFile
from .events import ControlEvent
from .score import Score, ScorePlayer, load_score, preset_tour
from .state import ControlState

SOURCE = "attract"
# the [attract] table's schema (tomlfile.Field); score or presets, not both, is checked in load_attract
SCHEMA = {"after": Field("number", 0, above_low=True, units="minutes",
                         required="minutes without performer input before the walk drifts on its own"),
          "score": Field("string"), "presets": Field("list"),
          "morph": Field("number", 0, above_low=True, units="seconds"), "hold": Field("number", 0, above_low=True, units="seconds")}


@dataclass(frozen=True)
class AttractSettings:
    after: float  # seconds of performance time without device input
    score: Score


def load_attract(show: TomlFile, state: ControlState, presets: dict[str, dict[str, float]]) -> AttractSettings | None:
    """The show file's [attract] table, checked; None when it has none."""
    table = show.data.get("attract")
    if table is None:
        return None

    def fail(message: str, key: str) -> UserError:
        return show.error(("attract", key), message, f"attract.{key}")

    show.check(("attract",), table, SCHEMA, "attract.")
    if ("score" in table) == ("presets" in table):
        raise fail("give either score (a score file) or presets (a list of preset names)", "score")
    if "score" in table:
        score = load_score(Path(show.path).parent / table["score"], state, presets, loop=True)
    else:
        names = table["presets"]
        if not names or not all(isinstance(n, str) for n in names):
            raise fail("expected a list of preset names", "presets")
        for name in names:
            if name not in presets:
                raise fail(f"no preset {quoted(name)} (known: {', '.join(sorted(presets)) or 'none'})", "presets")
        known = {name: {t: v for t, v in presets[name].items() if state.knows(t)} for name in names}  # (as a score's preset cue)
        score = preset_tour(names, known, float(table.get("morph", 8.0)), float(table.get("hold", 30.0)))
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
