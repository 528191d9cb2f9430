"""The console as the frame loop sees it: a control source like a MIDI port, and an output like
an OSC target. Both run in the frame loop's thread and only touch the server's queues."""

from __future__ import annotations

from typing import Callable

from ..control.events import ControlEvent
from ..control.state import MAX_TURN, WEIGHT_LIMIT, ControlState
from ..control.values import all_values
from ..runtime.console import Console
from ..runtime.pose import Pose
from ..synthesis.durations import MAX_SPEED, MIN_SPEED
from ..synthesis.interpolation import GROUPS
from .presets import save_presets
from .server import ConsoleServer, Frame

SOURCE = "console"  # the source name of the page's events in a controller log
SLIDER_WEIGHTS = (-2.0, 4.0)  # the style sliders' travel; the number box beside takes the whole +-WEIGHT_LIMIT


def hello(model, state: ControlState, presets: dict, morph: float, save_path: str | None, fps: float) -> dict:
    """What a page is told once, on connecting: the model's styles and skeleton, the ranges."""
    skeleton = model.layout.skeleton
    return {
        "type": "hello", "styles": state.style_names, "groups": list(GROUPS), "states": state.states,
        "joints": list(skeleton.names), "parents": [j.parent for j in skeleton.joints], "root": model.layout.root,
        "fps": fps, "morph": morph, "save": save_path, "presets": sorted(presets),
        "ranges": {"weight": [-WEIGHT_LIMIT, WEIGHT_LIMIT], "slider": list(SLIDER_WEIGHTS), "speed": [MIN_SPEED, MAX_SPEED],
                   "turn": [-MAX_TURN, MAX_TURN], "liveliness": [0.0, 1.0], "phase": [MIN_SPEED, MAX_SPEED]},
    }


class ConsoleLink:
    """Starts the server; `input` is the device the hub polls, `output` the frame sink."""

    def __init__(self, address: str, model, state: ControlState, presets: dict[str, dict[str, float]], console: Console,
                 fps: float, morph: float = 0.0, token: str | None = None, save_path: str | None = None,
                 sources: Callable[[], str] = lambda: ""):
        self.presets = presets  # the hub's own dict: a stored preset shows up here
        save = (lambda: self._save(save_path)) if save_path else None
        self.server = ConsoleServer(address, hello(model, state, presets, morph, save_path, fps),
                                    frozenset(state.targets()), token, save)
        self.input = ConsoleInput(self.server, console)
        self.output = ConsoleOutput(self.server, state, presets, sources)

    def _save(self, path: str) -> str:  # in the server's thread; copying a dict is atomic under the GIL
        presets = dict(self.presets)
        save_presets(path, presets)
        return f"saved {len(presets)} presets to {path}"


class ConsoleInput:
    """The pages' events, stamped with the frame time like a MIDI port's; says the server's notes."""

    source = SOURCE

    def __init__(self, server: ConsoleServer, console: Console):
        self.server, self.console = server, console

    def poll(self, now: float) -> list[ControlEvent]:
        while self.server.notes:
            key, text = self.server.notes.popleft()
            if key:
                self.console.warn(key, text)
            else:
                self.console.say(text)
        return [ControlEvent(now, SOURCE, control, value) for control, value in self.server.take()]

    def describe(self) -> str:
        return f"console {self.server.url} ({len(self.server.pages)} pages)"

    def close(self) -> None:
        self.server.close()


class ConsoleOutput:
    """Hands each frame to the pages; costs nothing while no page is open."""

    name = "console"

    def __init__(self, server: ConsoleServer, state: ControlState, presets: dict, sources: Callable[[], str]):
        self.server, self.state, self.presets, self.sources = server, state, presets, sources
        self.clock = None

    def watch(self, clock) -> None:
        """Given the frame clock, so the pages show late and dropped frames."""
        self.clock = clock

    def prepare(self, pose: Pose, echo: dict[str, float]) -> Frame | None:
        if not self.server.pages:
            return None
        late, dropped = (self.clock.late, self.clock.dropped) if self.clock else (0, 0)
        return Frame(pose.index, pose.world_positions.copy(), all_values(self.state), late, dropped, sorted(self.presets),
                     self.sources())

    def send(self, frame: Frame) -> None:
        self.server.publish(frame)

    def close(self) -> None:
        pass  # the server is closed with the input, after the loop
