"""`instrument service`: a systemd unit that runs a show file for weeks, unattended.

The unit starts `instrument run --config SHOW` as a notify service: systemd waits for the first
frame (READY=1), the frame loop pets the watchdog, and a loop that freezes or a process that
dies is restarted. It may use realtime scheduling at the priority `run` asks for.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import UserError
from ..runtime.priority import PRIORITY
from ..tomlfile import read_toml
from .arguments import checked


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("service", help="write a systemd unit that runs a show file unattended (restart, watchdog)")
    p.add_argument("--config", required=True, metavar="SHOW.toml", help="the show file the service runs")
    p.add_argument("--out", required=True, metavar="NAME.service", help="where to write the unit")
    p.add_argument("--user", action="store_true", help="a user unit (systemctl --user) instead of a system unit")
    p.add_argument("--run-as", metavar="USER", help="system unit: the account it runs as (default root)")
    p.add_argument("--watchdog", type=checked("service --watchdog"), default=10.0, metavar="SECONDS",
                   help="restart when the frame loop has not answered for this long (default 10)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.set_defaults(run=run)


def unit_text(show: Path, watchdog: float, user_unit: bool, run_as: str | None, python: str = sys.executable) -> str:
    show = show.resolve()
    lines = [
        f"# Written by `instrument service --config {show}`. Install: see docs/installations.md.",
        "[Unit]",
        f"Description=instrument: the walk of {show.name}",
        *(["After=sound.target"] if user_unit else ["Wants=network-online.target", "After=network-online.target sound.target"]),
        "StartLimitIntervalSec=600",
        "StartLimitBurst=20",
        "",
        "[Service]",
        "Type=notify",
        "NotifyAccess=main",
        f"ExecStart={python} -m instrument run --config {show} --quiet",
        f"WorkingDirectory={show.parent}",
        "Environment=PYTHONUNBUFFERED=1",
        f"WatchdogSec={watchdog:g}",
        "Restart=on-failure",
        "RestartSec=2",
        "TimeoutStartSec=120",
        "TimeoutStopSec=15",
        f"LimitRTPRIO={PRIORITY}",
    ]
    if run_as and not user_unit:
        lines += [f"User={run_as}", "SupplementaryGroups=audio"]
    lines += ["", "[Install]", f"WantedBy={'default.target' if user_unit else 'multi-user.target'}", ""]
    return "\n".join(lines).strip() + "\n"


def run(args: argparse.Namespace) -> int:
    show = Path(args.config)
    read_toml(show)  # a missing or broken show file is named now, not at the first start
    watchdog = args.watchdog
    if args.run_as and args.user:
        raise UserError("--run-as is for a system unit; a user unit runs as its user")
    out = Path(args.out)
    if out.suffix != ".service":
        raise UserError(f"--out {out}: a systemd unit's name ends in .service")
    text = unit_text(show, watchdog, args.user, args.run_as)
    try:
        with open(out, "w" if args.force else "x", encoding="utf-8") as f:
            f.write(text)
    except FileExistsError:
        raise UserError(f"{out}: already exists (give --force to replace it)") from None
    except OSError as e:
        raise UserError(f"{out}: cannot write: {e.strerror or e}") from None
    where = "~/.config/systemd/user/" if args.user else "/etc/systemd/system/"
    control = "systemctl --user" if args.user else "systemctl"
    print(f"wrote {out}; install: cp {out} {where} && {control} daemon-reload && {control} enable --now {out.name}")
    return 0
