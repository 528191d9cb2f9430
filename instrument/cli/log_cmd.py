"""`instrument log`: convert MIDI-only controller logs to and from Standard MIDI Files."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..control.events import read_log
from ..control.smf import export_smf, import_smf
from ..errors import UserError
from .arguments import checked


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("log", help="controller logs: export to / import from Standard MIDI Files")
    p.add_argument("action", choices=("export", "import"), help="export LOG.jsonl to a .mid, or import a .mid as LOG.jsonl")
    p.add_argument("source", metavar="FILE")
    p.add_argument("--out", required=True, metavar="FILE")
    p.add_argument("--fps", type=checked("log --fps"), default=30.0, help="import: the frame rate whose frames events land on (default 30)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists():
        raise UserError(f"{out}: already exists (nothing is overwritten)")
    if args.action == "export":
        count = export_smf(read_log(args.source), out)
    else:
        events = import_smf(args.source, args.fps)
        out.write_text("".join(e.to_json() + "\n" for e in events), encoding="utf-8")
        count = len(events)
    print(f"wrote {count} events to {out}", file=sys.stderr)
    return 0
