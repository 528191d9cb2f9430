"""The flat profile's compiled encoder and the batched send: a crowd's datagrams are byte for byte
the messages the profile documents (built here one by one with the plain OSC encoder), and
what a real UDP socket receives from `UdpOut` (sendmmsg, or one send each) is the same and
parses with python-osc."""

from __future__ import annotations

import socket
import time
import threading

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage

from instrument.output import osc
from instrument.output.flat import FlatProfile, character_prefix
from instrument.output.osc import OscTarget, UdpOut, bundles, message
from instrument.terminal import Console
from instrument.synthesis.engine import Engine, default_controls
from instrument.synthesis.posing import CrowdPose, quaternions
from waiting import wait_until

CHARACTERS = 5
ECHO = {"style/elderly": 0.25, "speed": 1.1, "turn": -0.3}


@pytest.fixture(scope="module")
def crowd_frames(model):
    """Three frames of a crowd walking with its spread, so every character's pose differs."""
    engine = Engine(model, CHARACTERS, 30.0)
    controls = default_controls(model, {"elderly": 0.25}, liveliness=0.5)
    return [engine.frame(k / 30.0, controls, 0.5) for k in range(3)]


def reference(names: list[str], root: int, pose, echo: dict[str, float]) -> list[bytes]:
    """The frame as docs/osc.md lists it, each message encoded on its own."""
    messages = []
    for k in range(pose.rotations.shape[0]):
        head = character_prefix(k)
        local = quaternions(pose.rotations[k])
        messages += [message(f"{head}/bone/{n}/quat", *map(float, local[j])) for j, n in enumerate(names)]
        messages += [message(f"{head}/bone/{n}/pos", *map(float, pose.world_positions[k, j])) for j, n in enumerate(names)]
        messages.append(message(f"{head}/root/pos", *map(float, pose.world_positions[k, root])))
        messages.append(message(f"{head}/root/quat", *map(float, quaternions(pose.world_rotations[k, root]))))
        messages.append(message(f"{head}/root/local", *map(float, pose.translations[k, root])))
    messages += [message(f"/walk/{name}", float(value)) for name, value in echo.items()]
    messages.append(message("/walk/frame", int(pose.index), float(pose.time)))
    return bundles(messages)


def test_a_crowds_datagrams_are_the_messages_encoded_one_by_one(model, crowd_frames):
    names, root = model.layout.skeleton.names, model.layout.root
    profile = FlatProfile(names, root, CHARACTERS)
    for pose in crowd_frames:
        expected = reference(names, root, pose, ECHO)
        assert len(expected) > CHARACTERS  # a crowd's frame takes many bundles
        assert profile.datagrams(pose, ECHO) == expected
        assert [bytes(d) for d in profile.encode(pose, ECHO)] == expected  # the views the live loop sends


def test_one_character_is_encoded_as_before(model, crowd_frames):
    names, root = model.layout.skeleton.names, model.layout.root
    crowd = crowd_frames[-1]
    first = CrowdPose(crowd.index, crowd.time, crowd.rotations[:1], crowd.translations[:1], crowd.world_rotations[:1],
                      crowd.world_positions[:1])
    assert FlatProfile(names, root).datagrams(crowd.character(0), {}) == reference(names, root, first, {})


def test_the_compiled_quaternions_are_scipys_to_the_last_bit(crowd_frames):
    from scipy.spatial.transform import Rotation

    from instrument.output.flat import _pose_values

    turns = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    matrices = np.concatenate([Rotation.random(20000, random_state=3).as_matrix(), turns]
                              + [f.rotations.reshape(-1, 3, 3) for f in crowd_frames])
    count = len(matrices)  # each matrix as the root of a one-joint character: its quaternion comes 4 values in
    values = np.empty(count * 17)
    zeros = np.zeros((count, 1, 3))
    _pose_values(matrices[:, None], matrices[:, None], zeros, zeros, 0, values)
    got = values.reshape(count, 17)[:, :4]
    assert np.array_equal(got.view(np.uint64), quaternions(matrices).view(np.uint64))
    assert np.array_equal(values.reshape(count, 17)[:, 10:14], got)  # the root's world rotation: the same kernel


def test_the_compiled_writer_rounds_and_orders_floats_as_numpy_does():
    from instrument.output.flat import _write

    rng = np.random.default_rng(5)
    values = np.concatenate([rng.normal(size=5000) * 10.0 ** rng.integers(-40, 38, 5000),  # float32's whole range
                             [0.0, -0.0, np.inf, -np.inf, 1e-46, -3e-39, 3.4e38, 1 + 2.0**-24, 1 + 3 * 2.0**-24]])
    widths = np.array([4] * (len(values) // 4) + [len(values) % 4], dtype=np.int64)  # messages of 4 floats, a shorter last
    starts = 4 * np.arange(len(widths)) * 6 + 8  # each run 8 bytes after the last one's start slot, so runs are apart
    words = np.zeros(len(widths) * 6 + 4, dtype=np.uint32)
    _write(words, starts, widths, values)
    slots = np.concatenate([np.arange(w) + a // 4 for a, w in zip(starts, widths)])
    assert words[slots].tobytes() == values.astype(">f4").tobytes()
    assert not np.delete(words, slots).any()  # nothing written between the runs


def test_a_pose_of_another_crowd_size_is_refused(model, crowd_frames):
    with pytest.raises(ValueError, match="characters"):
        FlatProfile(model.layout.skeleton.names, model.layout.root, CHARACTERS - 1).encode(crowd_frames[0], ECHO)


def receive(sock: socket.socket, count: int) -> list[bytes]:
    got: list[bytes] = []
    sock.settimeout(30.0)
    while len(got) < count:
        got.append(sock.recv(65536))
    return got


@pytest.mark.parametrize("batched", [True, False])
def test_the_datagrams_arrive_as_encoded_and_parse(model, crowd_frames, batched):
    names, root = model.layout.skeleton.names, model.layout.root
    profile = FlatProfile(names, root, CHARACTERS)
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    out = UdpOut(OscTarget("127.0.0.1", receiver.getsockname()[1], "flat"), Console(quiet=True))
    out.batched = batched
    try:
        for pose in crowd_frames:
            expected = reference(names, root, pose, ECHO)
            out.send(profile.encode(pose, ECHO))
            assert receive(receiver, len(expected)) == expected
        assert out.sent == sum(len(reference(names, root, p, ECHO)) for p in crowd_frames)
        last = crowd_frames[-1]
        values = {m.address: m.params for data in expected for m in OscBundle(data)}
        k = CHARACTERS - 1
        np.testing.assert_allclose(values[f"/walk/character/{k}/bone/{names[root]}/pos"], last.world_positions[k, root],
                                   rtol=1e-6)
        assert values["/walk/frame"][0] == last.index
    finally:
        out.close()
        receiver.close()


@pytest.mark.skipif(osc.SENDMMSG is None, reason="no sendmmsg in this libc")
def test_a_refused_target_is_reported_by_the_batched_send_and_the_show_goes_on(model, crowd_frames):
    names, root = model.layout.skeleton.names, model.layout.root
    profile = FlatProfile(names, root, CHARACTERS)
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()  # nobody listens there: the kernel answers with "connection refused"
    warnings: list[str] = []
    console = Console(quiet=True)
    console.warn = lambda key, text: warnings.append(text)
    out = UdpOut(OscTarget("127.0.0.1", port, "flat"), console)
    try:
        wait_until(lambda: out.send(profile.encode(crowd_frames[0], ECHO)) or out.failed, "the refusal to be reported")
        assert any("refused" in w.lower() for w in warnings), warnings
    finally:
        out.close()


def tiled(pose: CrowdPose, count: int) -> CrowdPose:
    """A crowd of `count` characters made of `pose`'s, repeated (a large crowd without its engine)."""
    def grown(a):
        return np.ascontiguousarray(np.resize(a, (count, *a.shape[1:])))

    return CrowdPose(pose.index, pose.time, grown(pose.rotations), grown(pose.translations), grown(pose.world_rotations),
                     grown(pose.world_positions))


def test_a_crowd_shared_over_cores_sends_from_its_own_thread_every_frame_in_order(model, crowd_frames, monkeypatch):
    from instrument.output.outputs import OscOutput
    from instrument.synthesis import cores
    from instrument.synthesis.footfalls import Footfall
    from instrument.synthesis.posing import Frame

    monkeypatch.setattr(cores, "_cores", lambda: 2)  # a crowd this size is then shared over two cores
    count = 2 * cores.LEAST_PER_PART
    names, root = model.layout.skeleton.names, model.layout.root
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    output = OscOutput(OscTarget("127.0.0.1", receiver.getsockname()[1], "flat"), FlatProfile(names, root, count),
                       Console(quiet=True))
    assert output.background is not None
    senders: list[str] = []
    send = output.out.send
    output.out.send = lambda datagrams: senders.append(threading.current_thread().name) or send(datagrams)
    expected: list[bytes] = []
    try:
        for pose in crowd_frames:
            crowd = tiled(pose, count)
            landed = [Footfall(count - 1, 1, pose.time, 1.25)]
            output.send(output.prepare(Frame(pose.index, pose.time, crowd, {}, ECHO, landed)))
            expected += [message("/walk/footfall", "right", count - 1, pose.time, 1.25)]  # in a bundle of its own, first
            expected += [m for data in reference(names, root, crowd, ECHO) for m in osc.unbundled([data])]
        output.close()  # waits for the last frame's sending
        got = [m for data in receive(receiver, output.out.sent) for m in osc.unbundled([data])]
    finally:
        receiver.close()
    assert got == expected
    assert senders and threading.current_thread().name not in senders
    parsed = [OscMessage(m) for m in got]  # python-osc's own parser reads every message
    assert [m.address for m in parsed].count("/walk/footfall") == len(crowd_frames)
    assert parsed[-1].address == "/walk/frame" and parsed[-1].params[0] == crowd_frames[-1].index


def test_two_targets_of_one_crowd_profile_each_get_every_frame_as_encoded(model, crowd_frames, monkeypatch):
    """`run` makes one profile per kind, so two flat targets write their frames into one buffer:
    a target's frame must not be written while the other's sending is still reading the last one.
    The second target's kernel is made slow (each sending 20 ms late), so a frame written too soon
    would reach it in place of the one before."""
    from instrument.output.outputs import OscOutput
    from instrument.synthesis import cores
    from instrument.synthesis.posing import Frame

    monkeypatch.setattr(cores, "_cores", lambda: 2)
    count = 2 * cores.LEAST_PER_PART
    names, root = model.layout.skeleton.names, model.layout.root
    profile = FlatProfile(names, root, count)
    receivers, outputs = [], []
    try:
        for _ in range(2):
            receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            receiver.bind(("127.0.0.1", 0))
            receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
            receivers.append(receiver)
            outputs.append(OscOutput(OscTarget("127.0.0.1", receiver.getsockname()[1], "flat"), profile, Console(quiet=True)))
        send = outputs[1].out.send
        outputs[1].out.send = lambda datagrams: time.sleep(0.02) or send(datagrams)
        expected: list[bytes] = []
        for pose in crowd_frames[:8]:
            crowd = tiled(pose, count)
            for output in outputs:
                output.send(output.prepare(Frame(pose.index, pose.time, crowd, {}, ECHO, [])))
            expected += [m for data in reference(names, root, crowd, ECHO) for m in osc.unbundled([data])]
        for output in outputs:
            output.close()
        for output, receiver in zip(outputs, receivers):
            got = [m for data in receive(receiver, output.out.sent) for m in osc.unbundled([data])]
            assert got == expected
    finally:
        for receiver in receivers:
            receiver.close()


def test_a_failed_sending_on_the_thread_is_raised_at_the_next_frame_which_is_sent_still(model, crowd_frames, monkeypatch):
    """An error of a sending on the thread is the target's, raised by its next `send` (the loop
    counts it against the target there) after that frame is handed over: no frame is lost to it."""
    from instrument.output.outputs import OscOutput
    from instrument.synthesis import cores
    from instrument.synthesis.posing import Frame

    monkeypatch.setattr(cores, "_cores", lambda: 2)
    count = 2 * cores.LEAST_PER_PART
    output = OscOutput(OscTarget("127.0.0.1", 9, "flat"), FlatProfile(model.layout.skeleton.names, model.layout.root, count),
                       Console(quiet=True))
    sent: list[int] = []

    def send(datagrams):
        index = OscMessage(osc.unbundled([bytes(list(datagrams)[-1])])[-1]).params[0]  # the frame's /walk/frame
        if not sent and index == crowd_frames[0].index and not getattr(send, "failed", False):
            send.failed = True
            raise RuntimeError("a broken sending")
        sent.append(index)

    output.out.send = send
    frames = [Frame(pose.index, pose.time, tiled(pose, count), {}, ECHO, []) for pose in crowd_frames[:3]]
    output.send(output.prepare(frames[0]))
    with pytest.raises(RuntimeError, match="a broken sending"):
        output.send(output.prepare(frames[1]))
    output.send(output.prepare(frames[2]))
    output.close()
    assert sent == [frames[1].index, frames[2].index]


def test_an_error_of_a_background_sending_is_raised_by_the_next_wait():
    from instrument.output.background import Background

    background = Background("test")
    done: list[int] = []

    def fails():
        raise OSError("no route")

    background.hand(fails)
    with pytest.raises(OSError, match="no route"):
        background.wait()
    background.hand(lambda: done.append(1))  # the thread goes on with the next
    background.close()
    assert done == [1]
