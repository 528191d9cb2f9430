"""Scores: a TOML file of timed cues that plays a performance on its own (format in docs/scores.md).

A score is a control source like a controller log: each frame it hands out control events
("score" source, target = value), which go through the same hub as every other event. So live
input rides on top of it, `--record` writes what it did as plain target values, and that log
replays the performance byte for byte without the score.

Cues run in file order. Each starts `at` a time of the score's clock or `after` the previous cue
has finished, never before the previous cue has started. A ramp (or a preset's recall, a ramp
of each of its targets) moves from where the target stands to its value over `over` seconds of
performance time; a performer who moves a ramped target takes it over and the ramp lets go. A
`wait` stops the score's clock until the performer presses the control mapped to `cue`; a
`repeat` jumps back to a marked cue.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import UserError, quoted
from ..models.gestures import gesture_labels
from ..shipped import demo_score_path
from ..synthesis.parameters import GAITS
from ..synthesis.stream import gait_index
from ..textfile import read_text
from ..tomlfile import Field, TomlFile
from .checks import between, row_of
from .events import ControlEvent
from .presetfile import held_values, model_of, read_presets
from .state import ControlState

if TYPE_CHECKING:
    from ..models.modelfile import Model

SOURCE = "score"
CURVES = ("linear", "ease")
ACTIONS = ("ramp", "preset", "hold", "wait", "repeat")
SECONDS = Field("number", 0, units="seconds")
# the file's schema (tomlfile.Field); what spans keys (one action a cue, at or after, ...) is checked in _cue
TOP = {"name": Field("string"), "loop": Field("bool"), "presets": Field("table"), "cue": Field("tables")}
CUE = {"at": SECONDS, "after": SECONDS, "mark": Field("string"), "over": SECONDS, "curve": Field("choice", choices=CURVES),
       "times": Field("whole", 1), "ramp": Field("table"), "preset": Field("string"), "hold": SECONDS,
       "wait": Field("string"), "repeat": Field("string")}


@dataclass(frozen=True)
class Cue:
    line: int  # where it starts in its file, for messages
    at: float | None = None  # seconds of the score's clock
    after: float = 0.0  # seconds after the previous cue finished (when `at` is not given)
    ramp: dict[str, float] = field(default_factory=dict)  # target -> value (a preset's values too)
    over: float = 0.0  # seconds a ramp takes
    curve: str = "linear"
    hold: float = 0.0
    wait: bool = False
    repeat: int | None = None  # index of the cue to go back to
    times: int | None = None  # how many more times (None: for ever)
    mark: str | None = None


@dataclass(frozen=True)
class Score:
    name: str
    path: str
    cues: tuple[Cue, ...]
    loop: bool = False


def load_score(path: str | Path, state: ControlState, presets: dict[str, dict[str, float]] | None = None,
               loop: bool | None = None, text: str | None = None) -> Score:
    """Read and check a score against the model's targets and the known presets; a mistake is
    one line naming the file, the line and the key. `text`: the file's text, already read."""
    doc = TomlFile(path, text)
    data = doc.data
    model = model_of(state)

    def fail(message: str, key: str, index: int | None = None) -> UserError:
        return doc.error((key,) if index is None else ("cue", index, key), message, key)

    doc.check((), data, TOP)
    known = dict(presets or {})
    known.update(read_presets(doc, model))
    raw = data.get("cue", [])
    if not isinstance(raw, list) or not raw:
        raise UserError(f"{doc.path}:1: cue: a score needs [[cue]] tables")
    cues: list[Cue] = []
    marks: dict[str, int] = {}
    for index, item in enumerate(raw):
        cue = _cue(item, index, doc, model, known, marks, lambda message, key, i=index: fail(message, key, i))
        if cue.at is not None:
            earlier = [c.at for c in cues if c.at is not None]
            if earlier and cue.at < earlier[-1]:
                raise fail(f"{cue.at:g} is before the previous cue's at = {earlier[-1]:g} (cues run in order)", "at", index)
        if cue.repeat is not None and not _lasts(cues[cue.repeat:], cues[cue.repeat].at or 0.0):
            raise fail("the section from its mark takes no time (add a hold, a wait or a ramp's over)", "repeat", index)
        if cue.mark is not None:
            marks[cue.mark] = index
        cues.append(cue)
    if (data.get("loop", False) if loop is None else loop) and not _lasts(cues):
        raise fail("a looping score must take some time (add a hold or a ramp's over)", "loop")
    return Score(data.get("name", Path(path).stem), str(path), tuple(cues), data.get("loop", False) if loop is None else loop)


DEMO_STYLE = re.compile(r'"style/([^"]+)"')
INLINE_TABLE = re.compile(r"\{[^{}]*\}")


def load_demo(model: Model, state: ControlState, presets: dict[str, dict[str, float]] | None = None) -> Score:
    """The built-in demo (examples/demo/demo.toml, looped), for any model. It is written for the
    shipped model's styles; a model without all of them plays the demo's styles by its own in
    turn (the demo's first style by the model's first, its second by the second, round again),
    so a model trained on one's own takes performs the same fades, exaggeration, inversion, pace
    and turn. A cue fades from one style to the next named, which falls on another of the model's
    whenever it has two; with one, the style faded in is kept (the fade out falling on the same
    style is dropped), so it still goes to 2, to -1 and back. Its gaits and gestures are played
    as far as the model has them (`_playable`): a model trained on walks walks on, unwarned of them."""
    path = demo_score_path()
    text = read_text(path)
    mine = state.style_names
    named = list(dict.fromkeys(DEMO_STYLE.findall(text)))
    if not all(name in mine for name in named):
        played_by = {name: mine[k % len(mine)] for k, name in enumerate(named)}
        text = INLINE_TABLE.sub(lambda table: _played_by(table.group(0), played_by), text)
    return _playable(load_score(path, state, presets, loop=True, text=text), model)


def _playable(score: Score, model: Model) -> Score:
    """The score without the ramp entries that set a gait the model has no unit for (`Model.units`)
    or a gesture it does not hold (its metadata's, `gesture_labels`), so the demo sets no gait or
    gesture the show would warn it lacks. A cue left with nothing to ramp holds for its `over` instead,
    so the cues after it keep their times."""
    gestures = gesture_labels(model.metadata)

    def plays(target: str, value: float) -> bool:
        if target == "gait":
            return GAITS[gait_index(value)] in model.units
        return not target.startswith("gesture/") or target.split("/")[1] in gestures

    cues = []
    for cue in score.cues:
        ramp = {target: value for target, value in cue.ramp.items() if plays(target, value)}
        if ramp != cue.ramp:
            cue = replace(cue, ramp=ramp) if ramp else replace(cue, ramp={}, over=0.0, hold=cue.over)
        cues.append(cue)
    return replace(score, cues=tuple(cues))


def _played_by(table: str, played_by: dict[str, str]) -> str:
    """An inline table of the demo (`{ "style/a" = 0.0, "style/b" = 1.0, speed = 1.4 }`) with its
    styles renamed; of two entries that fall on one style, the one that is not 0 (else the later)."""
    entries: dict[str, str] = {}
    for entry in filter(None, (part.strip() for part in table.strip("{} ").split(","))):
        key, _, value = (part.strip() for part in entry.partition("="))
        style = DEMO_STYLE.fullmatch(key)
        key = f'"style/{played_by[style.group(1)]}"' if style else key
        if key not in entries or value.lstrip("+-") not in ("0", "0.0"):
            entries[key] = value
    return "{ " + ", ".join(f"{key} = {value}" for key, value in entries.items()) + " }"


def _lasts(cues: list[Cue], since: float = 0.0) -> bool:
    """Whether playing these cues takes time from score clock `since` (so repeating them cannot spin)."""
    return any(c.wait or c.hold > 0 or c.over > 0 or c.after > 0 or (c.at or 0.0) > since for c in cues)


def _cue(item: object, index: int, doc: TomlFile, model: tuple, presets: dict, marks: dict, fail) -> Cue:
    doc.check(("cue", index), item, CUE)
    actions = [a for a in ACTIONS if a in item]
    if len(actions) != 1:
        raise fail(f"a cue does one thing: one of {', '.join(ACTIONS)}" + (f", not {' and '.join(actions)}" if actions else ""),
                   actions[1] if len(actions) > 1 else "cue")
    action = actions[0]
    if "at" in item and "after" in item:
        raise fail("give at or after, not both", "after")
    for key in ("over", "curve"):
        if key in item and action not in ("ramp", "preset"):
            raise fail(f"only for a ramp or a preset, not for {action}", key)
    if "times" in item and action != "repeat":
        raise fail("only for a repeat", "times")
    curve = item.get("curve", "linear")
    mark = item.get("mark")
    if mark in marks:
        raise fail("expected a name no other cue has", "mark")
    kwargs: dict = {}
    if action == "ramp":
        kwargs["ramp"] = held_values(doc, ("cue", index, "ramp"), item["ramp"], model, "ramp")
    elif action == "preset":
        if item["preset"] not in presets:
            raise fail(f"no preset {quoted(item['preset'])} (known: {', '.join(sorted(presets)) or 'none'})", "preset")
        # a shipped mapping's preset may name a style this model lacks (kept for a warning): not rampable
        kwargs["ramp"] = {t: v for t, v in presets[item["preset"]].items() if row_of(t, *model) is not None}
    elif action == "hold":
        if item["hold"] <= 0:
            raise fail("expected a positive number of seconds", "hold")
        kwargs["hold"] = float(item["hold"])
    elif action == "wait":
        if item["wait"] != "cue":
            raise fail("the only thing to wait for is \"cue\" (the performer's control mapped to target cue)", "wait")
        kwargs["wait"] = True
    else:
        if item["repeat"] not in marks:
            raise fail(f"no earlier cue has mark = {quoted(item['repeat'])}", "repeat")
        times = item.get("times")
        kwargs.update(repeat=marks[item["repeat"]], times=times)
    return Cue(line=doc.line("cue", index), at=float(item["at"]) if "at" in item else None, after=float(item.get("after", 0.0)),
               over=float(item.get("over", 0.0)), curve=curve, mark=mark, **kwargs)


def endless_cue(score: Score, pressable: bool) -> tuple[int, str] | None:
    """(line, why) of the first cue that keeps the score from ever finishing on its own: a repeat
    without `times`, or a `wait` when nothing can press the cue (`pressable` False: no controller,
    as in an offline render); None if it finishes."""
    for cue in score.cues:
        if cue.repeat is not None and cue.times is None:
            return cue.line, "the score repeats a section for ever (give the repeat times)"
        if cue.wait and not pressable:
            return cue.line, "the score waits for a cue that no controller is there to press"
    return None


def preset_tour(names: list[str], presets: dict[str, dict[str, float]], morph: float, hold: float) -> Score:
    """A looping score that drifts through presets: morph into each, stay a while, go on."""
    cues = []
    for name in names:
        cues.append(Cue(line=0, ramp=dict(presets[name]), over=morph, curve="ease"))
        cues.append(Cue(line=0, hold=hold))
    return Score("preset tour", "attract", tuple(cues), loop=True)


def eased(share: float, curve: str) -> float:
    """Share of a ramp done, shaped: linear, or ease (smoothstep: slow in, slow out)."""
    return share if curve == "linear" else share * share * (3.0 - 2.0 * share)


@dataclass
class _Ramp:
    start: float  # performance time
    over: float
    first: float
    last: float
    curve: str
    sent: float | None = None  # the value last handed out

    def value(self, now: float) -> float:
        share = 1.0 if self.over <= 0 else min(max((now - self.start) / self.over, 0.0), 1.0)
        if share >= 1.0:
            return self.last
        return between(self.first + (self.last - self.first) * eased(share, self.curve), self.first, self.last)


class ScorePlayer:
    """Plays a score by performance time: `due(now)` gives the events up to `now`.

    It may be asked many times for the same `now` (the live loop reads sources while it
    waits): a value is handed out once, when it changes. Same interface as LogReplay."""

    def __init__(self, score: Score, state: ControlState, start: float = 0.0, source: str = SOURCE):
        self.score, self.state, self.source = score, state, source
        self.loop = score.loop
        self.events = score.cues  # truthy: there is something to play
        self.offset = start  # performance time = score clock + offset (grows while waiting)
        self.index = 0  # the next cue to start
        self.previous_start = self.previous_end = 0.0  # score clock
        self.busy_until = 0.0  # score clock: when the cues started so far are all done
        self.started: dict[int, float] = {}  # cue index -> score clock at its start (for repeats)
        self.repeats_left: dict[int, int | None] = {}
        self.waiting: float | None = None  # score clock of a running wait
        self.presses = 0
        self.ramps: dict[str, _Ramp] = {}
        self.done = False

    @property
    def finished(self) -> bool:
        return self.done

    def due(self, now: float) -> list[ControlEvent]:
        for target in [t for t, r in self.ramps.items() if r.sent is not None and self.state.get(t) != r.sent]:
            del self.ramps[target]  # someone else moved it: the performer has it now
        self._start_cues(now)
        events = []
        for target, ramp in list(self.ramps.items()):
            value = ramp.value(now)
            if value != ramp.sent:
                ramp.sent = value
                events.append(ControlEvent(now, self.source, target, value))
            if now >= ramp.start + ramp.over:
                del self.ramps[target]
        return events

    def _start_cues(self, now: float) -> None:
        cues = self.score.cues
        while not self.done:
            if self.waiting is not None:
                self.offset = now - self.waiting  # the score's clock stood still until now
                if self.state.cue_presses == self.presses:
                    return
                self.previous_end = self.busy_until = max(self.busy_until, self.waiting)
                self.waiting = None
                self.index += 1
                continue
            clock = now - self.offset
            if self.index >= len(cues):
                if clock < self.busy_until or self.ramps:
                    return
                if not self.loop:
                    self.done = True
                    return
                self.offset += self.busy_until  # the next pass starts where this one ended
                self.index, self.previous_start, self.previous_end, self.busy_until = 0, 0.0, 0.0, 0.0
                self.started.clear()
                continue
            cue = cues[self.index]
            start = max(cue.at if cue.at is not None else self.previous_end + cue.after, self.previous_start)
            if start > clock:
                return
            self.started[self.index] = start
            self.previous_start = start
            end = start
            if cue.ramp:
                begin = start + self.offset
                for target, value in cue.ramp.items():
                    if target in self.ramps:  # from where the ramp it replaces stands at this moment
                        first = self.ramps[target].value(begin)
                    else:
                        first = self.state.get(target)
                    if math.isnan(first):  # a part weight that follows its style
                        first = self.state.get("style/" + target.split("/")[1])
                    self.ramps[target] = _Ramp(begin, cue.over, first, value, cue.curve)
                end = start + cue.over
            elif cue.hold:
                end = start + cue.hold
            elif cue.wait:
                self.waiting, self.presses = start, self.state.cue_presses
                continue
            elif cue.repeat is not None:
                left = self.repeats_left.get(self.index, cue.times)
                if left is None or left > 0:
                    self.repeats_left[self.index] = None if left is None else left - 1
                    back = cue.repeat
                    self.offset += start - self.started[back]  # the section plays again from here, same spacing
                    self.index, self.previous_start, self.previous_end = back, self.started[back], self.started[back]
                    self.busy_until = self.started[back]
                    continue
                self.repeats_left.pop(self.index, None)  # done: counts afresh if the section comes round again
            self.previous_end = end
            self.busy_until = max(self.busy_until, end)
            self.index += 1
