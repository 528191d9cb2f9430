"""`instrument learn`: MIDI or HID learn in the terminal, written out as a mapping file."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..control.devices import MidiInput
from ..control.hid import HidInput, detect_hid
from ..control.learn import detect
from ..control.options import read
from ..control.spec import TABLE
from ..errors import UserError
from ..outputfile import check_output, written
from ..terminal import Console
from ..shipped import default_model_path
from ..tomlfile import toml_string
from .arguments import checked

QUIET_AFTER = 0.8  # seconds without messages that end a capture
HID_JITTER = 0.02  # share of an axis's range a HID control must move by to count as moving


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("learn", help="MIDI or HID learn: pick a target, move a control, write a mapping file")
    p.add_argument("--out", required=True, metavar="MY.toml")
    p.add_argument("--force", action="store_true", help="overwrite the --out file if it exists (default: refuse)")
    p.add_argument("--model", help="model whose styles are offered (default: the shipped default model)")
    p.add_argument("--midi", metavar="PATTERN", help="MIDI input port (regular expression)")
    p.add_argument("--midi-virtual", metavar="NAME", help="create a virtual MIDI input port NAME instead")
    p.add_argument("--midi-api", choices=("alsa", "jack"))
    p.add_argument("--hid", metavar="VVVV:PPPP", help="HID device by vendor and product id (hexadecimal), e.g. 054c:09cc")
    p.add_argument("--timeout", type=checked("learn --timeout"), default=30.0, help="seconds to wait for a control to move (default 30)")
    p.set_defaults(run=run)


def capture(device: MidiInput | HidInput, timeout: float) -> list[tuple[str, float]]:
    """Raw events from the first message until the control rests for a moment."""
    device.read_raw()  # forget anything that came before the question
    raw: list[tuple[str, float]] = []
    deadline, last = time.monotonic() + timeout, None
    moved: dict[str, float] = {}  # HID: where each control last moved to (a resting stick jitters)
    while time.monotonic() < deadline:
        fresh = device.read_raw()
        if isinstance(device, HidInput):
            fresh = [(n, v) for n, v in fresh if n.startswith(("Button ", "Hat/")) or abs(v - moved.setdefault(n, v)) > HID_JITTER]
            moved.update(fresh)
        if fresh:
            raw += fresh
            last = time.monotonic()
        if last is not None and time.monotonic() - last > QUIET_AFTER:
            break
        time.sleep(0.005)
    return raw


def run(args: argparse.Namespace) -> int:
    out = check_output(args.out, args.force)
    if out.suffix.lower() != ".toml":
        raise UserError(f"--out {out}: give a .toml file (a mapping)")
    if not (args.midi or args.midi_virtual or args.hid):
        raise UserError("give --midi PATTERN (a port to listen to), --midi-virtual NAME or --hid VVVV:PPPP")
    hid_ids = read("hid", args.hid) if args.hid else None
    from ..control.state import ControlState  # (with the model's code: loaded when run, not for --help)
    from ..models.modelfile import load_model

    model = load_model(args.model or default_model_path())
    targets = ControlState(model.style_names, model.states).targets()
    targets = [t for t in targets if not t.startswith("part/")] + [f"preset/{n}" for n in ("1", "2", "3", "4")]
    # a target with named values (gait) on a fader (its zones, the row's range) or as one button a name
    targets += [f"{t}={name}" for t in targets if "/" not in t for name in TABLE[t].choices]
    device = HidInput(Console(), *hid_ids) if hid_ids else MidiInput(Console(), args.midi, args.midi_virtual, args.midi_api)
    port = args.midi_virtual or args.midi
    blocks: list[str] = []
    print("targets: " + ", ".join(f"{k + 1}) {t}" for k, t in enumerate(targets)), flush=True)
    try:
        while True:
            print("target (number or name; empty line to finish)? ", end="", flush=True)
            line = sys.stdin.readline()
            if not line or not line.strip():
                break
            choice = line.strip()
            target = targets[int(choice) - 1] if choice.isdigit() and 0 < int(choice) <= len(targets) else choice
            if target not in targets:
                print(f"not a target: {choice}", flush=True)
                continue
            print(f"move the control for {target} (an encoder: turn it up, then down)", flush=True)
            learned = (detect_hid if hid_ids else detect)(capture(device, args.timeout))
            if learned is None:
                print("nothing arrived; skipped", flush=True)
                continue
            if hid_ids:
                print(f"learned HID {learned.input} ({'button' if learned.button else 'axis'}) -> {target}", flush=True)
            else:
                print(f"learned {learned.message} channel {learned.channel} number {learned.number} ({learned.mode}) -> {target}", flush=True)
            target, _, name = target.partition("=")
            if name and not learned.button:
                print(f"{target}={name} is a button (a press sets {name}); that was not one: skipped", flush=True)
                continue
            # a learned fader's range: the row's (gait's 0 to 2, its zones); a named value: a button that sets it
            blocks.append(learned.toml(target, TABLE[target.split("/")[0]].fader, name or None))
    finally:
        device.close()
    if not blocks:
        print("nothing learned; no file written", file=sys.stderr)
        return 0
    device_line = f"hid = {toml_string(args.hid.lower())}" if hid_ids else f"midi = {toml_string(port)}"
    with written(out) as part:
        part.write_text(f"# Learned with instrument learn\nname = {toml_string(out.stem)}\n\n[device]\n{device_line}\n\n"
                        + "\n".join(blocks), encoding="utf-8")
    print(f"wrote {len(blocks)} controls to {out}", file=sys.stderr)
    return 0
