"""`instrument run`: the live instrument."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from ..control.devices import MidiClockReader, MidiInput, OscInput
from ..control.hid import HidInput
from ..control.hid_feedback import HidFeedback
from ..control.loghead import header_line
from ..errors import UserError
from ..runtime.health import Health
from ..runtime.notify import SystemdNotifier
from ..runtime.priority import realtime_scheduling
from ..runtime.stopping import StopFlag
from ..shipped import default_model_path
from ..control.options import RUN, read
from ..output.osc import FLAT_PORT, VMC_PORT
from .showplan import plan_show


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="the live instrument: walk, listen to controls, send OSC (default: the demo performance)")
    for option in RUN:  # the one table of run's options, which the show file reader reads too (control/options.py)
        options = option.argparse_options()
        if option.flag == "--osc":
            options["help"] = options["help"].format(vmc=VMC_PORT, flat=FLAT_PORT)
        p.add_argument(option.flag, **options)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    with StopFlag() as stop:  # Ctrl-C and SIGTERM from here on only ask to stop, once anything is open
        return _run(args, stop)


def _run(args: argparse.Namespace, stop: StopFlag) -> int:
    # the walk's code (numpy, scipy, numba): loaded here, under the stop flag, not for --help
    from ..control.attract import Attract
    from ..control.feedback import MidiFeedback
    from ..output.outputs import OscOutput, RecorderOutput
    from ..output.footfall_midi import FootfallMidi
    from ..runtime.link import LinkTempo
    from ..runtime.performance import Show, close_all, compile_kernels, perform
    from ..runtime.tempo import BeatLock, TempoFollower

    with stop.ending_at_once("instrument run"):  # nothing is open yet: Ctrl-C ends the process at once
        plan = plan_show(args)  # everything checked before anything opens
        if args.check:
            print(f"{args.config or 'the options'}: the show is fine (checked whole; nothing was opened or written)")
            return 0
        # a first run compiles here for half a minute, not in the first frame with the devices open
        compile_kernels(plan.model, plan.characters, plan.fps, plan.profiles.values())
    console = plan.console
    fps, seconds, state, model, mappings, replay = plan.fps, plan.seconds, plan.state, plan.model, plan.mappings, plan.replay
    characters, spacing, bvh_character, vmc_characters = plan.characters, plan.spacing, plan.bvh_character, plan.vmc_characters
    score_path, targets, attract, hub = plan.score_path, plan.targets, plan.attract, plan.hub
    outputs, devices, created, health, tempo = [], [], [], None, None
    try:
        tempo = TempoFollower() if args.sync == "midi" else LinkTempo() if args.sync == "link" else None
        for pattern, virtual in [(p, None) for p in args.midi or []] + [(None, v) for v in args.midi_virtual or []]:
            clock = MidiClockReader(tempo.message) if args.sync == "midi" else None
            devices.append(MidiInput(console, pattern, virtual, args.midi_api, clock))
            mapper = hub.mapper(devices[-1].source)  # the device's own, which its feedback follows
            if mapper is not None and not args.no_feedback:
                outputs.append(MidiFeedback(mapper, state, console, pattern, virtual, args.midi_api))
        if args.hid:
            vendor, product = read("hid", args.hid)
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
                               sources, plan.has())
            devices.append(link.input)
            for line in link.announcement():
                console.say(line)
        for t in targets:  # a crowd's flat target carries every character; VMC: character k on port + k
            crowd = range(vmc_characters) if t.profile == "vmc" else [0]
            outputs += [OscOutput(replace(t, port=t.port + k), plan.profiles[t.profile], console, k) for k in crowd]
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
        health = Health(console, outputs, devices, SystemdNotifier(), plan.health_every, args.status_port)  # watches every output
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
                    + (f" (character {bvh_character})" if args.bvh and characters > 1 else "")
                    + (f"; controls logged to {args.record}" if args.record else ""))  # (--keep-recordings: both numbered)
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
        summary = perform(show, console, stop, on_frame=health.frame, compiled=True)  # compile_kernels above
        hub.stopped_at(summary.frames / fps)  # frames are consecutive (a dropped slot moves the clock, not the index)
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
                    + (f"; poses held (not a number) {summary.held}" if summary.held else "")
                    + (f"; refused {refused}" if refused else ""))
        console.flush()
    return 0
