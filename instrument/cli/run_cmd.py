"""`instrument run`: the live instrument."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..control.devices import MidiClockReader, MidiInput, OscInput
from ..control.events import LogReplay, read_log
from ..control.hid import HidInput
from ..control.hid import choose_mapping as choose_hid_mapping
from ..control.hid_feedback import HidFeedback
from ..control.kinds import midi_fits
from ..control.loghead import header_line, logged_crowd, logged_mappings, logged_per_device, unreadable_sources
from ..control.mapping import load_mapping, parse_hid_id, preset_problems, style_problems, target_line
from ..control.presetfile import model_of, read_presets, read_presets_file
from ..errors import UserError
from ..output.osc import FLAT_PORT, VMC_PORT, parse_target
from ..outputfile import check_output
from ..terminal import Console
from ..runtime.health import Health
from ..runtime.notify import SystemdNotifier
from ..runtime.priority import realtime_scheduling
from ..runtime.stopping import StopFlag
from ..shipped import default_model_path, demo_score_path, shipped_mappings
from ..synthesis.parameters import DEFAULT_SPACING, DEFAULT_VMC_CHARACTERS
from ..tomlfile import TomlFile
from ..control.options import OPTIONS, host_port
from ..control.options import value as option_value
from .arguments import check_needs

if TYPE_CHECKING:
    from ..control.state import ControlState

DEFAULT_TARGETS = (f"127.0.0.1:{VMC_PORT}/vmc", f"127.0.0.1:{FLAT_PORT}/flat")
DEFAULTS = {"fps": "30", "no_osc": False, "no_feedback": False, "loop": False, "fast": False, "quiet": False,
            "normal_priority": False, "force": False, "vmc_root": "hips", "no_relaxed_hands": False}
LISTS = ("osc", "mapping", "midi", "midi_virtual")
SHOW_FILE_CHECKS = {"osc": parse_target, "hid": parse_hid_id}  # checked as the file is read, so errors name its line
ADDRESSES = ("osc_in", "status_port", "console")  # [HOST:]PORT options (control/options.host_port)
PATHS = ("model", "bvh", "replay", "score", "record", "humanoid", "presets", "mapping")  # relative to the show file


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="the live instrument: walk, listen to controls, send OSC (default: the demo performance)")
    p.add_argument("--config", metavar="SHOW.toml", help="a show file holding any of these options (flags given here win)")
    p.add_argument("--model", help="model file (default: the shipped default model)")
    p.add_argument("--fps", help="output frame rate, 24 to 120 (default 30)")
    p.add_argument("--seconds", help="stop after this many seconds of performance (default: until Ctrl-C)")
    p.add_argument("--osc", action="append", metavar="HOST:PORT[/vmc|/flat]",
                   help=f"OSC target, repeatable (default: {' and '.join(DEFAULT_TARGETS)}); "
                        "/vmc-unbundled or /flat-unbundled: one message per datagram, for receivers that reject bundles; "
                        "a broadcast (x.x.x.255) or multicast (224-239.x.x.x) address sends to many")
    p.add_argument("--no-osc", action="store_true", default=None, help="send no OSC at all")
    p.add_argument("--bvh", metavar="OUT.bvh", help="record the performance as BVH while it plays")
    p.add_argument("--characters", metavar="N", help="a crowd of N walkers (default 1; docs/crowds.md)")
    p.add_argument("--spacing", metavar="METRES",
                   help=f"a crowd's distance between neighbours on the floor (default {DEFAULT_SPACING:g})")
    p.add_argument("--bvh-character", metavar="K", help="of a crowd, the character --bvh records (default 0)")
    p.add_argument("--vmc-characters", metavar="M", help=f"of a crowd, how many characters (0 to M-1) a VMC target sends, "
                   f"character K on its port + K (default {DEFAULT_VMC_CHARACTERS}; the flat profile carries them all)")
    p.add_argument("--midi", action="append", metavar="PATTERN",
                   help="MIDI input: the first port whose name matches (regular expression); repeatable, one controller each")
    p.add_argument("--midi-virtual", action="append", metavar="NAME",
                   help="create a virtual MIDI input port NAME that other programs connect to; repeatable")
    p.add_argument("--midi-api", choices=("alsa", "jack"), help="MIDI system (default: rtmidi's choice, ALSA on Linux)")
    p.add_argument("--sync", choices=("midi", "link"),
                   help="step on the beat: follow MIDI clock on the MIDI inputs, or join an Ableton Link session "
                        "(docs/tempo.md)")
    p.add_argument("--midi-out", metavar="NAME",
                   help="a virtual MIDI output port NAME sending each footfall as a note (left 36, right 38, channel 10)")
    p.add_argument("--no-feedback", action="store_true", default=None,
                   help="send nothing back to the MIDI controller (default: LEDs and motor faders follow the state)")
    p.add_argument("--hid", metavar="VVVV:PPPP", help="HID game controller by vendor and product id, e.g. 054c:09cc")
    p.add_argument("--mapping", action="append", metavar="FILE.toml",
                   help="mapping file, repeatable (default: the shipped mapping that matches the device)")
    p.add_argument("--osc-in", metavar="[HOST:]PORT", help="accept control from OSC surfaces (bound to 127.0.0.1 unless HOST is given)")
    p.add_argument("--console", metavar="[HOST:]PORT",
                   help="serve the browser console (style mixer + live character) on PORT, bound to 127.0.0.1 unless "
                        "HOST is given; with a HOST the printed URL carries a token the page needs (docs/console.md)")
    p.add_argument("--console-token", metavar="TOKEN", help="the console's token (default: a new random one when HOST is given)")
    p.add_argument("--presets", metavar="FILE.toml", help="[presets.NAME] tables of target = value, recalled by preset/NAME")
    p.add_argument("--morph", help="seconds to morph into a recalled preset (default: the mapping's)")
    p.add_argument("--record", metavar="LOG.jsonl", help="record every raw control event with its time")
    p.add_argument("--replay", metavar="LOG.jsonl", help="play a controller log once (default with no controllers: the demo, looped)")
    p.add_argument("--score", metavar="SCORE.toml", help="play a score of timed cues (docs/scores.md); live controls ride on top")
    p.add_argument("--loop", action="store_true", default=None, help="play the --replay log or the --score over and over")
    p.add_argument("--humanoid", metavar="BONES.toml", help="joint-to-humanoid-bone map for the VMC profile")
    p.add_argument("--vmc-root", metavar="hips|path", help="VMC: the hips carry the walk under a fixed root (default, as "
                   "VirtualMotionCapture sends), or /VMC/Ext/Root/Pos carries the path and heading")
    p.add_argument("--no-relaxed-hands", action="store_true", default=None,
                   help="VMC: send no finger bones (default: a relaxed hand pose)")
    p.add_argument("--fast", action="store_true", default=None, help="no realtime pacing: as fast as the CPU allows (offline rendering)")
    p.add_argument("--normal-priority", action="store_true", default=None,
                   help="do not ask for realtime scheduling (default: asked for, so frames stay on time on a busy machine)")
    p.add_argument("--quiet", action="store_true", default=None, help="no status line (the health line stays)")
    p.add_argument("--force", action="store_true", default=None, help="let --bvh and --record replace existing files (default: refuse)")
    p.add_argument("--health-every", metavar="SECONDS",
                   help="a health line (frames, late, outputs, devices, memory) this often, 0 for none (default 60)")
    p.add_argument("--status-port", metavar="[HOST:]PORT",
                   help="answer /walk/status (OSC) and 'status' (JSON) requests on this UDP port (bound to 127.0.0.1 unless HOST is given)")
    p.set_defaults(run=run)


def apply_show_file(args: argparse.Namespace) -> TomlFile:
    """Fill options not given on the command line from the show file, each checked as the command
    line's are (control/options.py), an error naming the file, the key's line and the key; the file
    read, for its [presets] (checked once the model is known: `read_presets`) and [attract]."""
    show = TomlFile(args.config)
    path = show.path
    options = {a for a in vars(args) if a not in ("config", "run", "command")}
    for key, value in show.data.items():
        if key in ("presets", "attract"):  # read once the model is known (control/presetfile.py, control/attract.py)
            if not isinstance(value, dict):  # its shape is known before: `service` refuses what `run` will
                tables = "[presets.NAME] tables" if key == "presets" else "an [attract] table"
                raise UserError(f"{path}:{show.line(key)}: {key}: expected {tables}")
            continue
        dest = key.replace("-", "_")
        where = f"{path}:{show.line(key)}: {key}"
        if dest not in options:
            raise UserError(f"{where}: unknown option (the show file takes the flags of `instrument run`)")
        if dest in LISTS:
            value = value if isinstance(value, list) else [value]
            if not all(isinstance(v, str) for v in value):
                raise UserError(f"{where}: expected a string or a list of strings")
        elif isinstance(DEFAULTS.get(dest), bool):
            if not isinstance(value, bool):
                raise UserError(f"{where}: expected true or false")
        elif not isinstance(value, (str, int, float)) or isinstance(value, bool):
            raise UserError(f"{where}: expected a string or a number")
        else:
            value = str(value)
        option = f"run --{dest.replace('_', '-')}"
        if dest in ADDRESSES:
            host_port(option, value, where=where)
        elif option in OPTIONS:  # the same table as the command line, the error naming file, line and key
            option_value(option, value, where=where)
        for k, text in enumerate(value if isinstance(value, list) else [value]) if dest in SHOW_FILE_CHECKS else ():
            try:
                SHOW_FILE_CHECKS[dest](text)
            except UserError as e:
                line = show.line(key, k) if isinstance(value, list) else show.line(key)
                raise UserError(f"{path}:{line}: {key}: {str(e).removeprefix('--osc ')}") from None
        if getattr(args, dest) is None:
            setattr(args, dest, value)
        if dest in PATHS:
            base = Path(path).parent
            current = getattr(args, dest)
            if current is value:  # came from the file: paths are relative to it
                setattr(args, dest, [str(base / v) for v in value] if isinstance(value, list) else str(base / value))
    return show


def choose_mappings(args: argparse.Namespace, state: ControlState, console: Console) -> list:
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
        chosen, why = choose_hid_mapping(shipped, *parse_hid_id(args.hid))
        if chosen is None:
            raise UserError(f"--hid {args.hid}: {why}; give --mapping (instrument learn --hid writes one)")
        console.say(f"HID mapping: {chosen.name} ({chosen.path}), {why}")
        mappings.append(chosen)
    for mapping in mappings:
        for target in style_problems(mapping, state):
            console.warn(f"style {mapping.path} {target}", f"{mapping.path}: {target}: the model has no such style; that control does nothing")
    return mappings


def check_recordings(args: argparse.Namespace) -> None:
    """--bvh and --record may be written (the output rule), and are two different files."""
    if args.bvh and args.record and Path(args.bvh).resolve() == Path(args.record).resolve():
        raise UserError(f"--bvh and --record both name {args.bvh}: give two files")
    for path in (args.bvh, args.record):
        if path:
            check_output(path, args.force, inputs=(args.replay,))


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


def run(args: argparse.Namespace) -> int:
    with StopFlag() as stop:  # Ctrl-C and SIGTERM from here on, start-up included, only ask to stop
        return _run(args, stop)


def _run(args: argparse.Namespace, stop: StopFlag) -> int:
    # the walk's code (numpy, scipy, numba): loaded here, under the stop flag, not for --help
    from ..control.attract import Attract, load_attract
    from ..control.feedback import MidiFeedback
    from ..control.hub import ControlHub
    from ..control.score import ScorePlayer, load_score
    from ..control.state import ControlState
    from ..models.modelfile import load_model
    from ..output.outputs import OscOutput, RecorderOutput, make_profile
    from ..output.vmc import ROOT_CONVENTIONS
    from ..output.footfall_midi import FootfallMidi
    from ..runtime.link import LinkTempo
    from ..runtime.performance import Show, close_all, perform
    from ..runtime.tempo import BeatLock, TempoFollower

    show = apply_show_file(args) if args.config else None
    check_needs("run", args)
    for key, value in DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    fps = option_value("run --fps", args.fps)
    seconds = None if args.seconds is None else option_value("run --seconds", args.seconds)
    morph = 0.0 if args.morph is None else option_value("run --morph", args.morph)
    health_every = 60.0 if args.health_every is None else option_value("run --health-every", args.health_every)
    characters, spacing, bvh_character, vmc_characters = crowd_options(args)
    for dest in ADDRESSES:
        if getattr(args, dest):
            host_port(f"run --{dest.replace('_', '-')}", getattr(args, dest))
    if args.vmc_root not in ROOT_CONVENTIONS:
        raise UserError(f"--vmc-root must be {' or '.join(ROOT_CONVENTIONS)}, not {args.vmc_root!r}")
    model = load_model(args.model or default_model_path())
    console = Console(quiet=args.quiet)
    state = ControlState(model.style_names, model.states)
    presets = read_presets(show, model_of(state)) if show else {}
    if args.presets and (Path(args.presets).exists() or not args.console):  # the console may save to a new file
        presets.update(read_presets_file(args.presets, model_of(state)))
    check_recordings(args)
    logged = logged_mappings(args.replay, state) if args.replay and not args.mapping else []  # as recorded
    mappings = logged + choose_mappings(args, state, console)
    live = bool(args.midi or args.midi_virtual or args.hid or args.osc_in or args.console)
    if args.sync == "midi" and not (args.midi or args.midi_virtual):
        raise UserError("--sync midi follows the clock of a MIDI input: give --midi or --midi-virtual")
    if args.sync and args.fast:
        raise UserError("--sync follows the music in real time: not with --fast")
    if args.replay and args.score:
        raise UserError("give --replay or --score, not both")
    replay = (LogReplay(read_log(args.replay, warn=lambda m: console.warn("log cut", m)), loop=args.loop)
              if args.replay else None)
    missing = unreadable_sources(replay.events, mappings) if replay else []
    if missing:
        raise UserError(f"{args.replay}: has {' and '.join(missing)} events but no mapping to read them: "
                        "give the --mapping it was recorded with")
    score_path = args.score or (None if live or args.replay else demo_score_path())
    targets = [] if args.no_osc else [parse_target(t) for t in (args.osc or DEFAULT_TARGETS)]
    for target in targets:
        if target.profile == "vmc" and target.port + vmc_characters - 1 > 65535:
            raise UserError(f"--osc {target}: {vmc_characters} characters need VMC ports {target.port} to "
                            f"{target.port + vmc_characters - 1}, past 65535")
    outputs, devices, hub, created, health, tempo = [], [], None, [], None, None
    try:
        tempo = TempoFollower() if args.sync == "midi" else LinkTempo() if args.sync == "link" else None
        hub = ControlHub(mappings, presets, None, morph, console,
                         per_device=logged_per_device(args.replay) if args.replay else True)  # as the log was played
        hub.start(state)
        for mapping in mappings:
            for target in preset_problems(mapping, hub.presets):
                raise UserError(f"{mapping.path}:{target_line(mapping, target)}: target {target!r}: no such preset (the mapping, the show file and --presets "
                                "define none by that name)")
        if score_path and not args.score:  # the built-in demo, written for the shipped model's styles
            try:
                replay = ScorePlayer(load_score(score_path, state, hub.presets, loop=True), state)
            except UserError as error:
                console.say(f"the demo does not fit this model ({error}): the walk stays at the average; "
                            "give --score or a controller to play it")
                score_path = None
        elif score_path:  # checked against the model and every preset the hub knows
            replay = ScorePlayer(load_score(score_path, state, hub.presets, loop=True if args.loop else None), state)
        if args.fast and seconds is None and (replay is None or replay.loop or not replay.events):
            raise UserError("--fast needs an end: give --seconds, or a --replay log or a --score (played once)")
        attract = load_attract(show, state, hub.presets) if show else None
        if attract and not live:
            raise UserError(f"{args.config}: attract: needs a controller (midi, hid or osc-in) whose input it waits for")
        for pattern, virtual in [(p, None) for p in args.midi or []] + [(None, v) for v in args.midi_virtual or []]:
            clock = MidiClockReader(tempo.message) if args.sync == "midi" else None
            devices.append(MidiInput(console, pattern, virtual, args.midi_api, clock))
            mapper = hub.mapper(devices[-1].source)  # the device's own, which its feedback follows
            if mapper is not None and not args.no_feedback:
                outputs.append(MidiFeedback(mapper, state, console, pattern, virtual, args.midi_api))
        if args.hid:
            vendor, product = parse_hid_id(args.hid)
            devices.append(HidInput(console, vendor, product))
            mapper = hub.mapper(devices[-1].source)
            if mapper is not None and mapper.mapping.feedback is not None and not args.no_feedback:
                outputs.append(HidFeedback(devices[-1], mapper.mapping.feedback, console))
        if args.osc_in:
            devices.append(OscInput(console, args.osc_in if ":" in args.osc_in else f"127.0.0.1:{args.osc_in}"))
        if args.console:
            from ..console.link import ConsoleLink

            def sources() -> str:
                return ", ".join([d.describe() for d in devices] + ([f"log {args.replay}"] if args.replay else [])
                                 + ([f"score {score_path}"] if score_path else []))

            link = ConsoleLink(args.console, model, state, hub.presets, console, fps, args.console_token, args.presets,
                               sources)
            devices.append(link.input)
            for line in link.announcement():
                console.say(line)
        profiles = {kind: make_profile(kind, model, args.humanoid, args.vmc_root, not args.no_relaxed_hands, characters)
                    for kind in {t.profile for t in targets}}
        for t in targets:  # a crowd's flat target carries every character; VMC: character k on port + k
            crowd = range(vmc_characters) if t.profile == "vmc" else [0]
            outputs += [OscOutput(replace(t, port=t.port + k), profiles[t.profile], console, k) for k in crowd]
        if args.midi_out:
            outputs.append(FootfallMidi(args.midi_out, args.midi_api))
        if args.console:
            outputs.append(link.output)  # after the OSC targets: their datagrams leave first at the deadline
        # files last: a start-up that fails leaves nothing behind, so the corrected command runs
        if args.bvh:
            outputs.append(RecorderOutput(args.bvh, model, fps, replace=args.force, character=bvh_character))
            created.append(args.bvh)
        if args.record:
            hub.start_recording(args.record, header_line(mappings, characters, spacing, hub.per_device), replace=args.force)
            created.append(args.record)
        health = Health(console, outputs, devices, SystemdNotifier(), health_every, args.status_port)  # watches every output
    except UserError:
        close_all(outputs + devices + [t for t in (hub, health) if t is not None] + ([tempo] if hasattr(tempo, "close") else []),
                  console)
        for path in created:
            Path(path).unlink(missing_ok=True)
        raise
    if not args.quiet:
        sources = [d.describe() for d in devices] + ([f"log {args.replay}"] if args.replay else [])
        sources += [f"score {score_path}"] if score_path else []
        sources += [f"attract after {attract.after / 60:g} min of no input"] if attract else []
        crowd = f"{characters} characters {spacing:g} m apart; " if characters > 1 else ""
        if any(t.profile == "vmc" for t in targets) and vmc_characters < characters:
            crowd += f"VMC sends characters 0 to {vmc_characters - 1} (--vmc-characters), the flat profile all; "
        console.say(f"model {args.model or default_model_path()}; {fps:g} fps; {crowd}controls: {', '.join(sources) or 'none'}; "
                    f"OSC to {', '.join(map(str, targets)) or 'nowhere'}" + (f"; recording {args.bvh}" if args.bvh else "")
                    + (f" (character {bvh_character})" if args.bvh and characters > 1 else ""))
    if not args.fast and not args.normal_priority:
        refused = realtime_scheduling()
        if refused and not args.quiet:
            console.say(f"realtime scheduling {refused}: running at normal priority (frames may be late on a busy machine)")
    live_sources = [d.poll for d in devices]
    if attract:
        live_sources = [Attract(attract, live_sources, state, console).poll]
    try:
        if stop:  # asked to stop during start-up: close everything (a BVH with no frame is removed)
            close_all(reversed(outputs), console)  # files first, as at the end of a show
            console.say(f"stopped by {stop.by} before the first frame")
            return 0
        beat_lock = None if tempo is None else BeatLock(tempo)
        show = Show(model, outputs, fps, seconds, args.fast, characters, spacing, state=state, replay=replay,
                    sources=live_sources, apply=hub.apply, beat_lock=beat_lock,
                    describe_sources=lambda: ", ".join([d.describe() for d in devices]
                                                       + ([beat_lock.describe()] if beat_lock else []))
                    or ("score" if score_path else "replay"))
        summary = perform(show, console, stop, on_frame=health.frame)
    finally:
        health.notifier.stopping()
        close_all([hub] + devices + [health, health.notifier] + ([tempo] if hasattr(tempo, "close") else []), console)  # the recording first, as the outputs' files
        console.flush()
    refused = dict(hub.refused)
    for device in devices:
        for kind, count in getattr(device, "refused", {}).items():
            refused[kind] = refused.get(kind, 0) + count
    if not args.quiet:
        console.say(f"stopped after {summary.frames} frames; late {summary.late}, dropped {summary.dropped}"
                    + (f"; output errors {summary.output_errors}" if summary.output_errors else "")
                    + (f"; input errors {summary.input_errors}" if summary.input_errors else "")
                    + (f"; refused {refused}" if refused else ""))
        console.flush()
    return 0
