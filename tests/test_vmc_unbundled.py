"""Unbundled VMC (`--osc HOST:PORT/vmc-unbundled`), for receivers that read single OSC messages.

One `instrument run` sends VMC to two real UDP receivers on 127.0.0.1: one bundled as usual,
one unbundled. The unbundled one reads every datagram as a plain OSC message with python-osc's
message parser (a bundle would fail it, and none may arrive), and must hear the same messages in
the same order as the bundled one carries inside its bundles, frame after frame, each frame laid
out as the VMC specification's receivers expect: the root, every bone, the available message and
the time last.
"""

import subprocess
import sys
import time

import pytest
from oscrecv import Receiver
from pythonosc.osc_message import OscMessage

from instrument.errors import UserError
from instrument.output.osc import OscTarget, bundles, message, parse_target, unbundled

HUMAN_BONES = 21 + 30  # the mapped humanoid bones and the relaxed hands' finger bones


def frames_of(messages: list[tuple[str, list]]) -> dict[float, list[tuple[str, list]]]:
    """Messages grouped into frames, keyed by the frame's /VMC/Ext/T time (the frame's last message)."""
    out, current = {}, []
    for address, args in messages:
        current.append((address, args))
        if address == "/VMC/Ext/T":
            out[args[0]] = current
            current = []
    return out


def test_unbundled_targets_parse_and_print_back():
    target = parse_target("127.0.0.1:39539/vmc-unbundled")
    assert target == OscTarget("127.0.0.1", 39539, "vmc", bundled=False)
    assert str(target) == "127.0.0.1:39539/vmc-unbundled"
    assert parse_target("127.0.0.1:9000/flat-unbundled").bundled is False
    assert parse_target("127.0.0.1:39539/vmc").bundled is True
    with pytest.raises(UserError, match="unknown profile 'midi'"):
        parse_target("127.0.0.1:9000/midi-unbundled")


def test_unbundled_opens_bundles_in_order():
    messages = [message("/a", 1.0), message("/b", "x", 2), message("/c")]
    packed = bundles(messages * 40, limit=200)  # several bundles
    assert len(packed) > 1 and all(p.startswith(b"#bundle\0") for p in packed)
    assert unbundled(packed) == messages * 40
    assert unbundled([messages[0]]) == [messages[0]]  # a plain message stays as it is


def test_a_single_message_receiver_gets_every_vmc_message_unbundled():
    bundled, single = Receiver(), Receiver()
    try:
        run = subprocess.run([sys.executable, "-m", "instrument", "run", "--seconds", "2", "--quiet",
                              "--osc", f"127.0.0.1:{bundled.port}/vmc", "--osc", f"127.0.0.1:{single.port}/vmc-unbundled"],
                             capture_output=True, text=True, timeout=180)
        assert run.returncode == 0, run.stderr
        deadline = time.monotonic() + 30  # the last datagrams may still be on their way
        while time.monotonic() < deadline and len(frames_of(single.messages())) < len(frames_of(bundled.messages())):
            time.sleep(0.05)
    finally:
        bundled.close()
        single.close()
    assert single.datagrams and not any(d.startswith(b"#bundle") for d in single.datagrams)
    parsed = [OscMessage(d) for d in single.datagrams]  # each datagram alone is one whole message
    singles = frames_of([(m.address, list(m.params)) for m in parsed])
    packed = frames_of(bundled.messages())
    assert len(singles) >= 30 and set(singles) == set(packed)
    for time_stamp, frame in singles.items():
        assert frame == packed[time_stamp]
        addresses = [address for address, _ in frame]
        assert addresses[0] == "/VMC/Ext/Root/Pos" and frame[0][1][0] == "root" and len(frame[0][1]) == 8
        assert addresses[1 : 1 + HUMAN_BONES] == ["/VMC/Ext/Bone/Pos"] * HUMAN_BONES
        assert all(isinstance(args[0], str) and len(args) == 8 for _, args in frame[1 : 1 + HUMAN_BONES])
        assert frame[-2:] == [("/VMC/Ext/OK", [1]), ("/VMC/Ext/T", [time_stamp])]
