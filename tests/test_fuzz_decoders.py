"""Property-based fuzzing (Hypothesis) of what arrives live: the browser console's messages
(console/messages.py) and OSC packets (control/oscparse.py, and devices' OscInput over a real
UDP socket on 127.0.0.1).

A live show survives anything a page or a control surface sends: a page's message is either
turned into an event whose value its target takes, or refused with a one-line reason; an OSC
packet yields messages, each read as (address, number or None, tag) or refused as Malformed.
Never any other exception, so nothing a sender does can stop the frame loop.
"""

from __future__ import annotations

import json
import math
import os
import socket
import struct
import sys
import time

from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from instrument.console.messages import MAX_MESSAGE, Refused, parse
from instrument.control import oscparse
from instrument.control.checks import refusal
from instrument.control.devices import OscInput
from instrument.control.state import ControlState
from instrument.terminal import Console

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]  # the shipped model's
STATES = 5
TARGETS = frozenset(ControlState(STYLES, STATES).targets())
EXAMPLES = int(os.environ.get("INSTRUMENT_FUZZ_EXAMPLES", "300"))  # a deeper search: INSTRUMENT_FUZZ_EXAMPLES=5000
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])
DIGITS = sys.get_int_max_str_digits()

# --- the console's messages --------------------------------------------------------------------

names = st.one_of(st.sampled_from(sorted(TARGETS) + ["preset/calm", "store/calm", "style/nobody", "reset", "cue", "phase/0",
                                                      "phase/99999", "part/elderly/arms", "", "Ωμέγα", "\U0001F600", "a" * 100]),
                  st.text(max_size=20))
numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
                    st.sampled_from([0, 1, 0.5, -1, 10**4000, 2**64]))
json_values = st.recursive(st.one_of(st.none(), st.booleans(), numbers, names),
                           lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(names, inner, max_size=4)),
                           max_leaves=10)
messages = st.one_of(
    st.builds(lambda t, v: {"set": t, "value": v}, names, st.one_of(numbers, json_values)),
    st.builds(lambda k, n: {k: n}, st.sampled_from(["preset", "store", "save", "set"]), json_values),
    st.dictionaries(st.sampled_from(["set", "value", "preset", "store", "save", "x"]), json_values, max_size=3),
    json_values,
)


def as_text(item: object) -> str:
    try:
        return json.dumps(item, ensure_ascii=False, allow_nan=True)
    except ValueError:
        return str(item)


@FUZZ
@given(text=st.one_of(messages.map(as_text), st.text(max_size=200),
                      messages.map(as_text).flatmap(lambda t: st.integers(0, len(t)).map(lambda k: t[:k]))))
@example(text='{"set": "speed", "value": ' + "9" * (DIGITS + 1) + "}")  # more digits than Python converts (over 4096 bytes)
@example(text='{"set": "speed", "value": ' + "9" * 4000 + "}")  # fits in a message, not in a float
@example(text="[" * 2000 + "]" * 2000)
@example(text='{"set": "speed", "value": 1e999}')
@example(text='{"set": "\\n", "value": 0.0}')  # a newline in a target's name
def test_a_page_message_is_an_event_of_a_good_value_or_refused_in_one_line(text):
    try:
        kind, target, value = parse(text, TARGETS)
    except Refused as error:
        assert str(error) and "\n" not in str(error) and len(str(error)) < 400, str(error)[:400]
        return
    assert len(text) <= MAX_MESSAGE
    assert kind in ("event", "save")
    if kind == "event":
        assert refusal(target, value, STYLES, STATES) is None, (target, value)


# --- OSC -----------------------------------------------------------------------------------------

def osc_string(text: bytes) -> bytes:
    return text + b"\0" * (4 - len(text) % 4)


def osc_message(address: bytes, tags: bytes, args: bytes) -> bytes:
    return osc_string(address) + osc_string(b"," + tags) + args


def osc_bundle(elements: list[bytes]) -> bytes:
    return b"#bundle\0" + b"\0" * 8 + b"".join(struct.pack(">i", len(e)) + e for e in elements)


ARGS = {b"i": struct.pack(">i", 64), b"f": struct.pack(">f", 0.5), b"d": struct.pack(">d", 0.25), b"h": struct.pack(">q", 3),
        b"s": osc_string(b"calm"), b"T": b"", b"N": b"", b"b": struct.pack(">i", 2) + b"ab\0\0",
        b"f!": struct.pack(">f", math.nan), b"d!": struct.pack(">d", math.inf)}
osc_messages = st.builds(
    lambda address, kind: osc_message(address, kind.rstrip(b"!"), ARGS[kind]),
    st.one_of(st.sampled_from([b"/walk/speed", b"/walk/style/elderly", b"/walk/preset/calm", b"/other", b"/walk/" + b"x" * 300,
                               "/walk/Ωμέγα".encode()]), st.binary(max_size=12)),
    st.sampled_from(sorted(ARGS)))
osc_packets = st.recursive(osc_messages, lambda inner: st.lists(inner, max_size=4).map(osc_bundle), max_leaves=12)


def mutated_bytes(data: bytes, ops: list[tuple[int, bytes, int]]) -> bytes:
    """`data` with, at each place, `drop` bytes replaced by `payload` (so bytes change, appear and go)."""
    out = bytearray(data)
    for at, payload, drop in ops:
        k = at % (len(out) + 1)
        out[k: k + drop] = payload
    return bytes(out)


packets = st.one_of(
    osc_packets,
    st.builds(mutated_bytes, osc_packets, st.lists(st.tuples(st.integers(0, 10_000), st.binary(max_size=4), st.integers(0, 4)),
                                                   min_size=1, max_size=3)),
    st.binary(max_size=64),
    st.builds(lambda k: b"#bundle\0" + b"\0" * 8 + struct.pack(">i", 24) + (b"#bundle\0" + b"\0" * 8 + struct.pack(">i", 0)) * k,
              st.integers(0, 40)),
)


def read_all(packet: bytes) -> list[tuple[str, float | None, str]]:
    """Every message of a packet read as OscInput reads it; Malformed where it stops."""
    out = []
    try:
        for message in oscparse.messages(packet):
            assert isinstance(message, bytes)
            try:
                out.append(oscparse.first_number(message))
            except oscparse.Malformed:
                pass
    except oscparse.Malformed:
        pass
    return out


@FUZZ
@given(packet=packets)
@example(packet=osc_bundle([osc_bundle([osc_bundle([osc_bundle([osc_bundle([osc_bundle([osc_bundle([osc_bundle([osc_bundle([])])])])])])])])]))
@example(packet=b"/walk/speed\0,f\0\0\0\0")  # the argument cut off
@example(packet=b"#bundle\0" + b"\0" * 8 + struct.pack(">i", -4))
def test_an_osc_packet_is_read_or_malformed(packet):
    for address, value, tag in read_all(packet):
        assert isinstance(address, str) and address.startswith("/")
        assert value is None or isinstance(value, float)
        assert isinstance(tag, str)


@settings(max_examples=12, deadline=None, derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(burst=st.lists(packets, min_size=1, max_size=8))
def test_osc_input_over_udp_survives_any_packets_and_reads_the_next_good_one(burst):
    """Fuzzed packets sent to a real OscInput socket, then a good message: the input takes the
    good one, and everything it handed out is a /walk/ control with a number (checked later by
    the hub: control/checks.py)."""
    console = Console(quiet=True)
    osc = OscInput(console, "127.0.0.1:0")
    good = osc_message(b"/walk/spread", b"f", struct.pack(">f", 0.5))
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for packet in burst:
                if packet and len(packet) < 65000:
                    sender.sendto(packet, osc.sock.getsockname())
            sender.sendto(good, osc.sock.getsockname())
            events = []
            deadline = time.monotonic() + 30
            while not any(e.control == "spread" and e.value == 0.5 for e in events) and time.monotonic() < deadline:
                events += osc.poll(0.0)
                time.sleep(0.005)
    finally:
        osc.sock.close()
    assert any(e.control == "spread" and e.value == 0.5 for e in events)
    assert all(isinstance(e.control, str) and isinstance(e.value, float) for e in events)
