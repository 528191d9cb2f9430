"""A show, read and checked whole before anything is opened: the one path from a show file and a
command line to the settings `instrument run` plays.

`plan_show` reads the show file (each key checked as the command line's option is:
control/options.py), then everything `run` would otherwise find only once it is playing: the
model, the presets, the mappings, a replayed log or a score, the [attract] table, the OSC targets
and where the recordings go. It opens no device, port or output, and writes no file. `run` plays
what it returns; `run --check` stops there; `instrument service` calls it before it writes a unit,
so a unit is never written for a show `run` would refuse, and the refusal is the same line.

An error about an option the show file gave names the file, the line and the key first
(`show.toml:4: model: ...`), whatever check found it.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..control.hid import choose_mapping as choose_hid_mapping
from ..control.kinds import midi_fits
from ..control.loghead import logged_crowd, logged_mappings, logged_per_device, unreadable_sources
from ..control.mapping import load_mapping, preset_problems, style_problems, target_line
from ..control.options import RUN, RUN_BY_KEY, Option, host_port, read
from ..control.options import value as option_value
from ..control.presetfile import model_of, read_presets, read_presets_file
from ..errors import UserError, quoted
from ..output.osc import FLAT_PORT, VMC_PORT, OscTarget, parse_target
from ..outputfile import check_output
from ..shipped import default_model_path, demo_score_path, shipped_mappings
from ..synthesis.parameters import DEFAULT_SPACING, DEFAULT_VMC_CHARACTERS
from ..terminal import Console
from ..tomlfile import TomlFile
from .arguments import check_needs

if TYPE_CHECKING:
    from ..control.attract import AttractSettings
    from ..control.events import LogReplay
    from ..control.hub import ControlHub
    from ..control.score import ScorePlayer
    from ..control.state import ControlState

DEFAULT_TARGETS = (f"127.0.0.1:{VMC_PORT}/vmc", f"127.0.0.1:{FLAT_PORT}/flat")
# beyond the row's kind, checked as the file is read: the rows' readers, and --osc's (output/osc.py, a layer
# above the table's in control/)
SHOW_FILE_CHECKS = {"osc": parse_target} | {option.key: option.reader for option in RUN if option.reader}
READS = ("model", "replay", "score", "humanoid", "mapping")  # files that must exist before the show starts


def apply_show_file(args: argparse.Namespace) -> TomlFile:
    """Fill options not given on the command line from the show file, each checked as the command
    line's are (control/options.py), an error naming the file, the key's line and the key; the file
    read, for its [presets] (checked once the model is known: `read_presets`) and [attract]."""
    show = TomlFile(args.config)
    path = show.path
    for key, value in show.data.items():
        if key in ("presets", "attract"):  # read once the model is known (control/presetfile.py, control/attract.py)
            if not isinstance(value, dict):  # its shape is known before the model is loaded
                tables = "[presets.NAME] tables" if key == "presets" else "an [attract] table"
                raise UserError(f"{path}:{show.line(key)}: {key}: expected {tables}")
            continue
        option = RUN_BY_KEY.get(key)
        where = f"{path}:{show.line(key)}: {key}"
        if option is None or not option.in_file:
            written = RUN_BY_KEY.get(key.replace("_", "-"))  # TOML habit: osc_in for osc-in
            hint = f"; did you mean {written.key}?" if written is not None and written.in_file else ""
            raise UserError(f"{where}: unknown option (the show file takes the flags of `instrument run`{hint})")
        value = file_value(option, value, where)
        for k, text in enumerate(value if isinstance(value, list) else [value]) if key in SHOW_FILE_CHECKS else ():
            try:
                SHOW_FILE_CHECKS[key](text)
            except (UserError, ValueError) as e:
                line = show.line(key, k) if isinstance(value, list) else show.line(key)
                raise UserError(f"{path}:{line}: {key}: {str(e).removeprefix('--osc ')}") from None
        if getattr(args, option.dest) is None:  # the command line wins
            if option.kind in ("path", "paths"):  # relative to the show file
                base = Path(path).parent
                value = [str(base / v) for v in value] if isinstance(value, list) else str(base / value)
            setattr(args, option.dest, value)
    return show


def file_value(option: Option, value: object, where: str) -> object:
    """A show file's value for `option`, as the command line would give it (text, a list of
    texts, or True/False for a flag), checked as its row says; a one-line error naming `where`."""
    if option.kind == "flag":
        if not isinstance(value, bool):
            raise UserError(f"{where}: expected true or false")
        return value
    if option.kind in ("list", "paths"):
        value = value if isinstance(value, list) else [value]
        if not all(isinstance(v, str) for v in value):
            raise UserError(f"{where}: expected a string or a list of strings")
        return value
    if option.kind == "path" and not isinstance(value, str):
        raise UserError(f"{where}: expected a file name in quotes, not {quoted(value)}")
    if not isinstance(value, (str, int, float)) or isinstance(value, bool):
        raise UserError(f"{where}: expected a string or a number")
    text = str(value)
    if option.kind == "address":
        host_port(f"run {option.flag}", text, where=where)
    elif option.kind == "number":
        option_value(f"run {option.flag}", text, where=where)
    elif option.kind == "choice" and text not in option.choices:
        raise UserError(f"{where}: expected one of {', '.join(option.choices)}, not {quoted(value)}")
    return text


@dataclass
class ShowPlan:
    """What `run` plays, every part checked; nothing in it is open yet. `args` holds the options
    with the show file's filled in and the defaults set."""

    args: argparse.Namespace
    show_file: TomlFile | None
    fps: float
    seconds: float | None
    health_every: float
    characters: int
    spacing: float
    bvh_character: int
    vmc_characters: int
    model: Any  # models.modelfile.Model
    state: ControlState
    mappings: list
    hub: ControlHub
    replay: LogReplay | ScorePlayer | None
    score_path: str | None
    targets: list[OscTarget]
    profiles: dict  # the OSC targets' profiles by kind ("vmc", "flat"), made
    attract: AttractSettings | None
    live: bool  # a controller (MIDI, HID, OSC in, the console) plays
    console: Console  # quiet as the options say

    def has(self) -> frozenset[str]:
        """What of the targets' NEEDS (control/spec.py) this run meets: a tempo source, a crowd.
        The console offers only the targets that do something in it."""
        return frozenset(({"sync"} if self.args.sync else set()) | ({"crowd"} if self.characters > 1 else set()))

    def writes(self) -> tuple[Path, ...]:
        """The folders its recordings (--bvh, --record) go to."""
        return tuple(Path(p).resolve().parent for p in (self.args.bvh, self.args.record) if p)


class _Origins:
    """Where each option the show file gave is written (`show.toml:4: model`), so an error about it
    found after the file is read still names the file, line and key."""

    def __init__(self, show: TomlFile | None, given: set[str]):
        self.path = None if show is None else f"{show.path}:"
        self.at = {} if show is None else {
            key.replace("-", "_"): f"{show.path}:{show.line(key)}: {key}" for key in show.data
            if key.replace("-", "_") not in given}

    def prefix(self, option: str) -> str:
        """"show.toml:4: key: " for an option (`--model` or `model`) the file gave, else ""."""
        where = self.at.get(option.removeprefix("--").replace("-", "_"))
        return f"{where}: " if where else ""

    @contextmanager
    def blame(self, *options: str) -> Iterator[None]:
        """A UserError raised inside names where the first of `options` the file gave is written."""
        try:
            yield
        except UserError as error:
            prefix = next((self.prefix(o) for o in options if self.prefix(o)), "")
            if prefix and not str(error).startswith(self.path):  # (an error in the show file names its line)
                raise UserError(prefix + str(error)) from None
            raise


def plan_show(args: argparse.Namespace) -> ShowPlan:
    """The show the command line and its show file (`--config`) describe, checked whole without
    opening a device, a port or an output: a one-line UserError naming the file, line and key (or
    the option) of the first problem."""
    from ..control.attract import load_attract
    from ..control.events import LogReplay, read_log_and_end
    from ..control.hub import ControlHub
    from ..control.score import ScorePlayer, endless_cue, load_demo, load_score
    from ..control.state import ControlState
    from ..models.modelfile import load_model
    from ..output.humanoid import read_humanoid
    from ..output.outputs import make_profile

    given = {dest for dest, value in vars(args).items() if value is not None}
    show = apply_show_file(args) if args.config else None
    origins = _Origins(show, given)
    check_needs("run", args, where=origins.prefix)
    for option in RUN:
        if getattr(args, option.dest) is None and option.default is not None:
            setattr(args, option.dest, option.default)
    console = Console(quiet=args.quiet)
    for dest in READS:  # before any is read: a file that cannot be is named with the key that names it
        for path in (getattr(args, dest) or []) if RUN_BY_KEY[dest].kind == "paths" else [getattr(args, dest)]:
            try:
                if path is not None:
                    open(path, "rb").close()
            except OSError as e:
                raise UserError(f"{origins.prefix(dest)}{path}: cannot read: {e.strerror or e}") from None
    fps = option_value("run --fps", args.fps)
    seconds = None if args.seconds is None else option_value("run --seconds", args.seconds)
    morph = 0.0 if args.morph is None else option_value("run --morph", args.morph)
    health_every = 60.0 if args.health_every is None else option_value("run --health-every", args.health_every)
    with origins.blame("bvh_character", "characters", "vmc_characters"):
        characters, spacing, bvh_character, vmc_characters = crowd_options(args)
    for option in RUN:
        if option.kind == "address" and getattr(args, option.dest):
            host_port(f"run {option.flag}", getattr(args, option.dest))
        elif option.reader and getattr(args, option.dest):
            read(option.key, getattr(args, option.dest))
    with origins.blame("model"):
        model = load_model(args.model or default_model_path())
    state = ControlState(model.style_names, model.states)
    presets = read_presets(show, model_of(state)) if show else {}
    # (a presets file holds [presets] only: the show file given as its own presets is refused here)
    if args.presets and (Path(args.presets).exists() or not args.console):  # the console may save to a new file
        presets.update(read_presets_file(args.presets, model_of(state)))
    if args.keep_recordings and args.force:
        raise UserError(f"{origins.prefix('force') or origins.prefix('keep-recordings')}--force replaces recordings and "
                        "--keep-recordings (which a service runs a show with) keeps each under a new name: give one")
    if args.keep_recordings:
        args.bvh, args.record = kept_names(args.bvh, args.record)
    with origins.blame("bvh", "record"):
        check_recordings(args)
    with origins.blame("replay"):
        logged = logged_mappings(args.replay, state) if args.replay and not args.mapping else []  # as recorded
    with origins.blame("mapping", "hid"):
        mappings = logged + choose_mappings(args, state, console)
    live = bool(args.midi or args.midi_virtual or args.hid or args.osc_in or args.console)
    if args.sync == "midi" and not (args.midi or args.midi_virtual):
        raise UserError(f"{origins.prefix('sync')}--sync midi follows the clock of a MIDI input: give --midi or --midi-virtual")
    if args.sync and args.fast:
        raise UserError(f"{origins.prefix('sync')}--sync follows the music in real time: not with --fast")
    if args.replay and args.score:
        raise UserError(f"{origins.prefix('replay') or origins.prefix('score')}give --replay or --score, not both")
    with origins.blame("replay"):
        # a log's beat lock (its `tempo` events) plays back, unless a live tempo source locks the steps anew
        replay = None
        if args.replay:
            events, end = read_log_and_end(args.replay, warn=lambda m: console.warn("log cut", m))
            replay = LogReplay([e for e in events if not (args.sync and e.source.kind == "tempo")], loop=args.loop, end=end)
            if end is not None and seconds is None and not args.loop:
                seconds = end  # the recorded run's length: its last stretch without a control move plays too
        missing = unreadable_sources(replay.events, mappings) if replay else []
        if missing:
            raise UserError(f"{args.replay}: has {' and '.join(missing)} events but no mapping to read them: "
                            "give the --mapping it was recorded with")
    score_path = args.score or (None if live or args.replay else demo_score_path())
    targets = [] if args.no_osc else [parse_target(t) for t in (args.osc or DEFAULT_TARGETS)]
    for target in targets:
        if target.profile == "vmc" and target.port + vmc_characters - 1 > 65535:
            raise UserError(f"{origins.prefix('osc')}--osc {target}: {vmc_characters} characters need VMC ports "
                            f"{target.port} to {target.port + vmc_characters - 1}, past 65535")
    with origins.blame("humanoid"):  # the OSC profiles' joints, humanoid bones and root (output/outputs.py)
        # a bone map named is read whatever the targets: a mistake in it is said now, not when a VMC target is added
        humanoid = read_humanoid(args.humanoid, model.layout.skeleton) if args.humanoid else None
        profiles = {kind: make_profile(kind, model, humanoid, args.vmc_root, not args.no_relaxed_hands, characters)
                    for kind in {t.profile for t in targets}}
    hub = ControlHub(mappings, presets, None, morph, console,
                     per_device=logged_per_device(args.replay) if args.replay else True)  # as the log was played
    hub.start(state)
    for mapping in mappings:
        for target in preset_problems(mapping, hub.presets):
            raise UserError(f"{mapping.path}:{target_line(mapping, target)}: target {target!r}: no such preset "
                            "(the mapping, the show file and --presets define none by that name)")
    if score_path and not args.score:  # the built-in demo, in this model's styles, gaits and gestures
        try:
            replay = ScorePlayer(load_demo(model, state, hub.presets), state)
        except UserError as error:
            console.say(f"the demo does not fit this model ({error}): the walk stays at the average; "
                        "give --score or a controller to play it")
            score_path = None
    elif score_path:  # checked against the model and every preset the hub knows
        with origins.blame("score"):
            score = load_score(score_path, state, hub.presets, loop=True if args.loop else None)
            replay = ScorePlayer(score, state)
        for line, gait in missing_gaits(score, model.units):  # said, not refused (as when it is played): it walks
            console.warn(f"gait {gait}", f"{score_path}:{line}: gait {gait}: this model has no {gait} unit "
                         f"(it has {', '.join(model.units)}); it walks")
    endless = endless_cue(score, live) if args.fast and seconds is None and args.score and not score.loop else None
    if endless:  # it would render for ever, filling the disk with --bvh
        raise UserError(f"{origins.prefix('fast')}--fast needs an end: {score_path}:{endless[0]}: {endless[1]}; give --seconds")
    if args.fast and seconds is None and (replay is None or replay.loop or not replay.events):
        raise UserError(f"{origins.prefix('fast')}--fast needs an end: give --seconds, or a --replay log or a --score "
                        "(played once)")
    with origins.blame("attract"):
        attract = load_attract(show, state, hub.presets) if show else None
    if attract and not live:
        raise UserError(f"{args.config}:{show.line('attract')}: attract: needs a controller (midi, hid or osc-in) "
                        "whose input it waits for")
    return ShowPlan(args, show, fps, seconds, health_every, characters, spacing, bvh_character, vmc_characters,
                    model, state, mappings, hub, replay, score_path, targets, profiles, attract, live, console)


def choose_mappings(args: argparse.Namespace, state: ControlState, console: Console) -> list:
    """The mappings given, and for a MIDI port or HID device none of them reads, the shipped one that fits it."""
    mappings = [load_mapping(m, state, strict_styles=True) for m in (args.mapping or [])]
    wanted_midi = (args.midi or []) + (args.midi_virtual or [])  # each port gets the mapping fitting it (control/kinds.py)
    if wanted_midi and not any(m.midi for m in mappings):
        shipped = [load_mapping(p, state) for p in shipped_mappings()]
        for wanted in wanted_midi:
            chosen = [m for m in shipped if midi_fits(m, wanted) == 2] or [m for m in shipped if m.midi == "."]
            if chosen and chosen[0] not in mappings:  # two ports of one model: one mapping, a decoder each
                console.say(f"MIDI mapping: {chosen[0].name} ({chosen[0].path})")
                mappings.append(chosen[0])
    if args.hid and not any(m.hid or m.hid_usages for m in mappings):
        shipped = [load_mapping(p, state) for p in shipped_mappings()]
        chosen, why = choose_hid_mapping(shipped, *read("hid", args.hid))
        if chosen is None:
            raise UserError(f"--hid {args.hid}: {why}; give --mapping (instrument learn --hid writes one)")
        console.say(f"HID mapping: {chosen.name} ({chosen.path}), {why}")
        mappings.append(chosen)
    for mapping in mappings:
        for target in style_problems(mapping, state):
            console.warn(f"style {mapping.path} {target}", f"{mapping.path}: {target}: the model has no such style; that control does nothing")
    return mappings


def check_recordings(args: argparse.Namespace) -> None:
    """--bvh and --record may be written (the output rule: never one of the show's inputs, the
    score, a mapping, the show file...), are two different files, and --bvh is named .bvh."""
    if args.bvh and args.record and Path(args.bvh).resolve() == Path(args.record).resolve():
        raise UserError(f"--bvh and --record both name {args.bvh}: give two files")
    if args.bvh and Path(args.bvh).suffix.lower() != ".bvh":  # x.glb held BVH text
        raise UserError(f"{args.bvh}: a recording is BVH: give a .bvh name (`instrument convert` makes a .glb of it)")
    inputs = [args.config, args.presets]  # --force replaced a --score or a mapping with the log
    for dest in READS:
        inputs += (getattr(args, dest) or []) if RUN_BY_KEY[dest].kind == "paths" else [getattr(args, dest)]
    for path in (args.bvh, args.record):
        if path:
            check_output(path, args.force, inputs=tuple(inputs))


def kept_names(*paths: str | None) -> list[str | None]:
    """The recordings' names for a start that keeps every earlier recording (--keep-recordings):
    the names given when none of them exists, else NAME-2.EXT, NAME-3.EXT, ... numbered one past
    the highest number any of them holds, so a restarted show never writes over the take before
    the restart, the numbers keep the order of the starts (one deleted is not filled again), and
    a start's BVH and controller log share a number (the log replays to the BVH). A number is
    taken by a recording or by what a killed one left (NAME.part, which a recorder will not open
    again: counted free, a restart after a crash before the first frame failed on every try)."""
    given = [Path(p) for p in paths if p]

    highest = 0
    for path in given:
        if path.exists() or path.with_name(f"{path.name}.part").exists():
            highest = max(highest, 1)
        pattern = re.compile(rf"{re.escape(path.stem)}-(\d+){re.escape(path.suffix)}(\.part)?")
        if path.parent.is_dir():
            for other in path.parent.iterdir():
                if match := pattern.fullmatch(other.name):
                    highest = max(highest, int(match.group(1)))
    number = highest + 1

    def numbered(path: Path) -> Path:
        return path if number == 1 else path.with_name(f"{path.stem}-{number}{path.suffix}")

    return [None if p is None else str(numbered(Path(p))) for p in paths]


def crowd_options(args: argparse.Namespace) -> tuple[int, float, int, int]:
    """--characters, --spacing, --bvh-character (a character of the crowd) and --vmc-characters
    (how many of the crowd a VMC target sends, at most all), checked; a replayed log's crowd
    where --characters and --spacing are not given."""
    logged, where = logged_crowd(args.replay) if args.replay else ({}, "")  # a replay walks the crowd it recorded
    if args.characters is None and "characters" in logged:
        args.characters = option_value("run --characters", logged["characters"], where=f"{where} characters")
    if args.spacing is None and logged.get("spacing") is not None:
        args.spacing = option_value("run --spacing", logged["spacing"], where=f"{where} spacing")
    characters = 1 if args.characters is None else option_value("run --characters", args.characters)
    spacing = DEFAULT_SPACING if args.spacing is None else option_value("run --spacing", args.spacing)
    chosen = 0 if args.bvh_character is None else option_value("run --bvh-character", args.bvh_character)
    if chosen >= characters:
        raise UserError(f"--bvh-character: expected a character of the crowd, 0 to {characters - 1}, not {chosen}")
    vmc = DEFAULT_VMC_CHARACTERS if args.vmc_characters is None else option_value("run --vmc-characters", args.vmc_characters)
    return characters, spacing, chosen, min(vmc, characters)


def missing_gaits(score, units: list[str]) -> list[tuple[int, str]]:
    """(line, gait) of each gait a score's cues set that the model has no unit for (the first cue
    of each): `run --check` says so before the show, as the show does when it plays them."""
    from ..synthesis.parameters import GAITS
    from ..synthesis.stream import gait_index

    said: dict[str, int] = {}
    for cue in score.cues:
        if "gait" in cue.ramp:
            gait = GAITS[gait_index(cue.ramp["gait"])]
            if gait not in units and gait not in said:
                said[gait] = cue.line
    return [(line, gait) for gait, line in said.items()]
