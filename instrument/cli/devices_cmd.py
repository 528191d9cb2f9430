"""`instrument devices`: the MIDI ports and HID devices here, each with the shipped mapping that fits."""

from __future__ import annotations

import argparse

from ..control.devices import midi_backend, midi_system
from ..control.hid import choose_mapping as choose_hid_mapping
from ..control.hid import describe_controls, device_descriptor, hidapi
from ..control.kinds import midi_fits
from ..control.mapping import load_mapping
from ..errors import UserError
from ..shipped import shipped_mappings

PLAYABLE = {(1, 4), (1, 5), (1, 8)}  # Generic Desktop joystick, gamepad, multi-axis controller


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("devices", help="list MIDI ports and HID devices, with the shipped mapping for each")
    p.add_argument("--midi-api", choices=("alsa", "jack"), help="MIDI system (default: rtmidi's choice)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    mappings = [load_mapping(p) for p in shipped_mappings()]
    print("MIDI inputs:")
    try:
        with midi_system(args.midi_api):
            names = midi_backend(args.midi_api).get_input_names()
    except UserError as error:
        names = []
        print(f"  ({error})")
    for name in names:
        fit = next((m for m in mappings if midi_fits(m, name) == 2), None)  # as `run` gives the port its mapping
        print(f"  {name}  ->  {fit.path if fit else 'no shipped mapping (generic: mappings/generic-8-faders.toml)'}")
    if not names:
        print("  none")
    print("HID devices:")
    try:
        hid = hidapi()
        found = hid.enumerate()
    except Exception as error:
        found = []
        print(f"  (HID not available: {error})")
    shown = set()
    for info in found:
        ids = (info.get("vendor_id", 0), info.get("product_id", 0))
        if ids in shown:  # one line per device, not per interface
            continue
        playable = (info.get("usage_page"), info.get("usage")) in PLAYABLE
        if not playable and not any(m.hid and ids in m.hid for m in mappings):
            continue  # keyboards, mice, UPSes...: nothing a performer plays
        try:
            descriptor = device_descriptor(hid, *ids)
            controls = describe_controls(descriptor.controls) if descriptor else "(unplugged just now)"
        except UserError as error:  # a descriptor that cannot be parsed: said, with the byte
            controls = f"(cannot read them: {error})"
        shown.add(ids)
        fit, why = choose_hid_mapping(mappings, *ids, hid=hid)
        print(f"  {ids[0]:04x}:{ids[1]:04x} {info.get('product_string') or ''}  ->  "
              f"{f'{fit.path} ({why})' if fit else 'no shipped mapping (instrument learn --hid writes one)'}")
        print(f"    controls: {controls}")
    if not shown:
        print("  none")
    return 0
