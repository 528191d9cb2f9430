"""`instrument log`: convert MIDI-only controller logs to and from Standard MIDI Files."""

from __future__ import annotations

import argparse
import sys

from ..outputfile import check_output, written
from .arguments import checked


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("log", help="controller logs: export to / import from Standard MIDI Files")
    p.add_argument("action", choices=("export", "import"), help="export LOG.jsonl to a .mid, or import a .mid as LOG.jsonl")
    p.add_argument("source", metavar="FILE")
    p.add_argument("--out", required=True, metavar="FILE")
    p.add_argument("--force", action="store_true", help="overwrite the --out file if it exists (default: refuse)")
    p.add_argument("--fps", type=checked("log --fps"), default=30.0, help="import: the frame rate whose frames events land on (default 30)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..control.events import read_log
    from ..control.smf import export_smf, import_smf  # (mido: loaded when run, not for --help)

    out = check_output(args.out, args.force, inputs=(args.source,))
    if args.action == "export":
        events = read_log(args.source)
        with written(out) as part:
            count = export_smf(events, part, args.source)
    else:
        events = import_smf(args.source, args.fps)
        with written(out) as part:
            part.write_text("".join(e.to_json() + "\n" for e in events), encoding="utf-8")
        count = len(events)
    print(f"wrote {count} events to {out}", file=sys.stderr)
    return 0
