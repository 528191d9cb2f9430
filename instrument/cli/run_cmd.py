"""`instrument run`: the live instrument."""

from __future__ import annotations

import argparse

from ..control.events import LogReplay, read_log
from ..errors import UserError
from ..models.modelfile import load_model
from ..output.osc import FLAT_PORT, VMC_PORT, parse_target
from ..output.outputs import OscOutput, RecorderOutput, make_profile
from ..runtime.console import Console
from ..runtime.performance import perform
from ..shipped import default_model_path, demo_log_path
from .synth_cmd import number

DEFAULT_TARGETS = (f"127.0.0.1:{VMC_PORT}/vmc", f"127.0.0.1:{FLAT_PORT}/flat")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="the live instrument: walk, listen to controls, send OSC (default: the demo performance)")
    p.add_argument("--model", help="model file (default: the shipped default model)")
    p.add_argument("--fps", default="30", help="output frame rate, 24 to 120 (default 30)")
    p.add_argument("--seconds", help="stop after this many seconds of performance (default: until Ctrl-C)")
    p.add_argument("--osc", action="append", metavar="HOST:PORT[/vmc|/flat]",
                   help=f"OSC target, repeatable (default: {' and '.join(DEFAULT_TARGETS)}); "
                        "a broadcast (x.x.x.255) or multicast (224-239.x.x.x) address sends to many")
    p.add_argument("--no-osc", action="store_true", help="send no OSC at all")
    p.add_argument("--bvh", metavar="OUT.bvh", help="record the performance as BVH while it plays")
    p.add_argument("--replay", metavar="LOG.jsonl", help="play a controller log (default with no controllers: the demo, looped)")
    p.add_argument("--no-loop", action="store_true", help="play the log once and stop")
    p.add_argument("--humanoid", metavar="BONES.toml", help="joint-to-humanoid-bone map for the VMC profile")
    p.add_argument("--fast", action="store_true", help="no realtime pacing: as fast as the CPU allows (offline rendering)")
    p.add_argument("--quiet", action="store_true", help="no status line")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    fps = number("--fps", args.fps)
    if not 24 <= fps <= 120:
        raise UserError(f"--fps must be between 24 and 120, not {args.fps}")
    seconds = None if args.seconds is None else number("--seconds", args.seconds)
    if seconds is not None and seconds <= 0:
        raise UserError(f"--seconds must be positive, not {args.seconds}")
    model = load_model(args.model or default_model_path())
    console = Console(quiet=args.quiet)
    replay_path = args.replay or demo_log_path()
    replay = LogReplay(read_log(replay_path), loop=not args.no_loop)
    targets = [] if args.no_osc else [parse_target(t) for t in (args.osc or DEFAULT_TARGETS)]
    if args.fast and seconds is None and (replay.loop or not replay.events):
        raise UserError("--fast needs an end: give --seconds, or --no-loop with a log")
    outputs = []
    try:
        if args.bvh:
            outputs.append(RecorderOutput(args.bvh, model, fps))
        profiles = {kind: make_profile(kind, model, args.humanoid) for kind in {t.profile for t in targets}}
        outputs += [OscOutput(t, profiles[t.profile], console) for t in targets]
    except UserError:
        for output in outputs:
            output.close()
        raise
    if not args.quiet:
        console.say(f"model {args.model or default_model_path()}; "
                    f"{fps:g} fps; controls from {replay_path}; OSC to {', '.join(map(str, targets)) or 'nowhere'}"
                    + (f"; recording {args.bvh}" if args.bvh else ""))
    summary = perform(model, outputs, console, fps, seconds, replay, fast=args.fast,
                      describe_sources=lambda: f"replay {'(loop)' if replay.loop else ''}")
    if not args.quiet:
        console.say(f"stopped after {summary.frames} frames; late {summary.late}, dropped {summary.dropped}"
                    + (f"; output errors {summary.output_errors}" if summary.output_errors else ""))
    return 0
