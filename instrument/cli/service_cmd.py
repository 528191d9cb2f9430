"""`instrument service`: a systemd unit that runs a show file for weeks, unattended.

The unit starts `instrument run --config SHOW` as a notify service: systemd waits for the first
frame (READY=1), the frame loop pets the watchdog, and a loop that freezes or a process that
dies is restarted. It may use realtime scheduling at the priority `run` asks for. It runs with
--keep-recordings: a start after a crash records beside the night's take (NAME-2.bvh), never
over it nor refusing to start because it exists.

A system unit runs as a user of its own (DynamicUser=, or --run-as an account), in a sandbox
that leaves the instrument what it needs and nothing more: the network (OSC in and out), the
sound and MIDI devices and hidraw nodes, realtime scheduling, memory numba can compile into,
read access to the show, and write access to the folders its recordings go to. docs/installations.md
says which directive each of those needs keeps off. Before the unit is written the show file is
checked whole by the function `run` checks it with (cli/showplan.py), so a unit is never written
for a show that `run` would refuse; every path is quoted and escaped for systemd, and a path systemd cannot
hold (a control character, such as a newline) is refused in one line.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from ..errors import UserError
from ..runtime.priority import PRIORITY
from .arguments import checked

USER_NAME = re.compile(r"[a-z_][a-z0-9_-]{0,30}")  # what systemd takes in User= (its "strict" rule)
# the sandbox a user unit can have without privileges (mount namespaces would need PrivateUsers=, which hides the devices)
USER_SANDBOX = (
    "NoNewPrivileges=yes",
    "RestrictAddressFamilies=AF_INET AF_INET6 AF_UNIX AF_NETLINK",  # PrivateNetwork= stays off: OSC in and out
    "RestrictNamespaces=yes",
    "RestrictSUIDSGID=yes",
    "LockPersonality=yes",
    "SystemCallArchitectures=native",
    "SystemCallFilter=@system-service",
    "SystemCallErrorNumber=EPERM",
)
# the sandbox of a system unit; docs/installations.md says why each need leaves a directive off
SANDBOX = USER_SANDBOX + (
    "CapabilityBoundingSet=",
    "AmbientCapabilities=",
    "ProtectSystem=strict",
    "ProtectHome=read-only",  # a show under /home is read; its recordings' folders are made writable below
    "PrivateTmp=yes",
    "PrivateMounts=yes",
    "DevicePolicy=closed",  # PrivateDevices= stays off: the sound/MIDI devices and hidraw nodes are opened
    "DeviceAllow=char-alsa rw",
    "DeviceAllow=char-hidraw rw",
    "ProtectKernelTunables=yes",
    "ProtectKernelModules=yes",
    "ProtectKernelLogs=yes",
    "ProtectControlGroups=yes",
    "ProtectClock=yes",
    "ProtectHostname=yes",
    "ProtectProc=invisible",
    "UMask=0027",
    # MemoryDenyWriteExecute= stays off: numba compiles the kernels into memory it then runs
    # RestrictRealtime= stays off: the frame loop asks for SCHED_FIFO (LimitRTPRIO= below)
    # PrivateUsers= stays off: it would hide the audio group the sound devices belong to
    # RemoveIPC= is not set: DynamicUser= implies it, and for a --run-as account running the JACK
    # server it would remove the server's shared memory when the service stops
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("service", help="write a systemd unit that runs a show file unattended (restart, watchdog)")
    p.add_argument("--config", required=True, metavar="SHOW.toml", help="the show file the service runs")
    p.add_argument("--out", required=True, metavar="NAME.service", help="where to write the unit")
    p.add_argument("--user", action="store_true", help="a user unit (systemctl --user) instead of a system unit")
    p.add_argument("--run-as", metavar="USER", help="system unit: the account it runs as (default: a user of its own "
                   "that systemd makes, DynamicUser=; give the account that owns the recordings' folder or the JACK server)")
    p.add_argument("--watchdog", type=checked("service --watchdog"), default=10.0, metavar="SECONDS",
                   help="restart when the frame loop has not answered for this long (default 10)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.set_defaults(run=run)


def unit_word(text: str, kind: str = "argument") -> str:
    """`text` as one quoted word systemd reads back exactly: `%` (a specifier) doubled; `\\` and
    `"` escaped inside the quotes; in an "argument" of the command line `$` (a variable) doubled
    too (systemd substitutes none in the "executable" nor in a "path" setting)."""
    bad = next((c for c in text if ord(c) < 32 or ord(c) == 127), None)
    if bad is not None:
        raise UserError(f"{text!r}: a path with a control character ({bad!r}) cannot go in a systemd unit; rename it")
    if kind == "executable" and any(c in text for c in "\"'\\"):
        raise UserError(f"{text}: systemd refuses an executable whose path holds a quote or a backslash; "
                        "install the instrument where the path has none")
    text = text.replace("\\", "\\\\").replace('"', '\\"').replace("%", "%%")
    return f'"{text.replace("$", "$$") if kind == "argument" else text}"'


def run_words(show: Path) -> list[str]:
    """The `instrument` command the unit runs the show with (its checks parse the same words)."""
    return ["run", "--config", str(show), "--quiet", "--keep-recordings"]


def unit_text(show: Path, watchdog: float, user_unit: bool, run_as: str | None, python: str = sys.executable,
              writes: tuple[Path, ...] = ()) -> str:
    """The unit for `show` (resolved); `writes`: the folders its recordings go to."""
    show = show.resolve()
    command = " ".join([unit_word(python, "executable")]
                       + [unit_word(w) for w in ("-m", "instrument", *run_words(show))])
    lines = [
        "# Written by `instrument service`. Install: see docs/installations.md.",
        "[Unit]",
        f"Description=instrument: the walk of {show.name.replace('%', '%%')}",
        *(["After=sound.target"] if user_unit else ["Wants=network-online.target", "After=network-online.target sound.target"]),
        "StartLimitIntervalSec=600",
        "StartLimitBurst=20",
        "",
        "[Service]",
        "Type=notify",
        "NotifyAccess=main",
        f"ExecStart={command}",
        "Environment=PYTHONUNBUFFERED=1",
        f"WatchdogSec={watchdog:g}",
        "Restart=on-failure",
        # stopped by SIGTERM (systemctl stop) or SIGINT before anything opened (a first start's compile),
        # run ends at once with 128 + the signal: a stop asked for, not a failure to restart or report
        "SuccessExitStatus=130 143",
        "RestartSec=2",
        "TimeoutStartSec=300",  # a first start compiles the kernels (about half a minute) before the first frame
        "TimeoutStopSec=15",
        f"LimitRTPRIO={PRIORITY}",
    ]
    if user_unit:
        lines += list(USER_SANDBOX)
    else:
        lines += [f"User={run_as}" if run_as else "DynamicUser=yes", "SupplementaryGroups=audio",
                  "CacheDirectory=instrument", "StateDirectory=instrument", *SANDBOX]
        # "-": a folder missing at start does not stop the unit (run then says which, in one line)
        lines += [f"ReadWritePaths={unit_word('-' + str(folder), 'path')}" for folder in sorted(set(writes))]
    lines += ["", "[Install]", f"WantedBy={'default.target' if user_unit else 'multi-user.target'}", ""]
    return "\n".join(lines).strip() + "\n"


def show_outputs(show: Path) -> tuple[Path, ...]:
    """Check the show file exactly as `run` does before it opens anything (cli/showplan.py: a show
    `run` refuses is refused here, in the same line), and return the folders its recordings go to."""
    from .run_cmd import add_parser as add_run_parser
    from .showplan import plan_show

    parser = argparse.ArgumentParser(prog="instrument")
    add_run_parser(parser.add_subparsers(dest="command"))
    return plan_show(parser.parse_args(run_words(show))).writes()


def run(args: argparse.Namespace) -> int:
    show = Path(args.config)
    writes = show_outputs(show)
    if args.run_as and args.user:
        raise UserError("--run-as is for a system unit; a user unit runs as its user")
    if args.run_as is not None and not USER_NAME.fullmatch(args.run_as):
        raise UserError(f"--run-as {args.run_as!r}: not a user name systemd takes (lower-case letters, digits, _ and -)")
    out = Path(args.out)
    if out.suffix != ".service":
        raise UserError(f"--out {out}: a systemd unit's name ends in .service")
    text = unit_text(show, args.watchdog, args.user, args.run_as, writes=writes)
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
