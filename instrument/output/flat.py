"""The flat OSC profile: one address per value group, for TouchDesigner, Max, Pd, Blender add-ons.

Per frame, in bundles of at most 1,400 bytes, in this order:

    /walk/bone/<Joint>/quat  f f f f   local rotation of every joint (x, y, z, w), BVH joint names
    /walk/bone/<Joint>/pos   f f f     world position of every joint (model units)
    /walk/root/pos           f f f     world position of the root joint
    /walk/root/quat          f f f f   world rotation of the root joint (x, y, z, w)
    /walk/root/local         f f f     local translation of the root joint (its BVH position channels)
    /walk/style/<name>       f         echo of every style weight
    /walk/speed, /walk/turn, /walk/liveliness, /walk/spread   f   echo of the other controls
    /walk/frame              i f       frame index and performance time in seconds; sent last,
                                       so a receiver can apply the frame when it arrives

and, in a bundle of their own before the frame's, one message per foot that landed in the frame:

    /walk/footfall           s i f f   side ("left" or "right"), character, performance time in
                                       seconds, the foot's speed at impact in metres per second

Coordinates are the model's: right-handed, Y up, the units of the training data (centimetres
for the shipped model).

A crowd (`run --characters N`): character 0 is sent at the addresses above, exactly as a single
character; character K (1 to N-1) at the same bone and root addresses under
/walk/character/K/ (/walk/character/K/bone/<Joint>/quat, /walk/character/K/root/pos, ...),
after character 0's root and before the echo. The echo and /walk/frame are sent once, last.
"""

from __future__ import annotations

import struct

import numpy as np
from numba import njit

from ..synthesis.cores import over_cores, parts
from ..synthesis.footfalls import SIDES, Footfall
from ..synthesis.posing import Pose
from .background import Background
from .osc import Datagrams, bundles, float_prefix, message


def character_prefix(k: int) -> str:
    """Where character k's bone and root addresses start: /walk for character 0 (a crowd's
    first character is sent as a single one is), /walk/character/k for the others."""
    return "/walk" if k == 0 else f"/walk/character/{k}"


class FrameTemplate:
    """A frame's bundles with every value left as a slot: every message of the profile has a
    fixed size, so the bundles are cut the same way every frame, and a frame is the template
    with its float32 values (and the frame index) written in place by compiled code (`_write`:
    the characters' by their parts' `_encode`, the echo's by `fill`) into a buffer kept from
    frame to frame (`Datagrams`: the bundles as views of it, sent as they are)."""

    def __init__(self, prefixes: list[bytes], widths: list[int]):
        """For messages of `widths[k]` float32 values after `prefixes[k]`, then /walk/frame."""
        frame = message("/walk/frame", 0, 0.0)
        datagrams = bundles([p + bytes(4 * w) for p, w in zip(prefixes, widths)] + [frame])
        starts, bounds, base = [], [], 0
        for datagram in datagrams:  # where each message landed: "#bundle\0", time tag, then (size, message)...
            at = 16
            while at < len(datagram):
                size = int.from_bytes(datagram[at : at + 4], "big", signed=True)
                starts.append(base + at + 4)
                at += 4 + size
            bounds.append((base, base + len(datagram)))
            base += len(datagram)
        frame_values = starts[-1] + len(frame) - 8  # the int32 index, then the float32 time
        # each message's first float32 and how many follow it; the frame's time is a message of one
        self.float_starts = np.array([start + len(p) for start, p in zip(starts, prefixes)] + [frame_values + 4],
                                     dtype=np.int64)
        self.float_widths = np.array(list(widths) + [1], dtype=np.int64)
        self.index_slot = frame_values
        if self.float_starts.size and (self.float_starts % 4).any():  # cannot be: OSC aligns every argument
            raise ValueError("flat profile: a float slot off a 4-byte boundary")
        self.buffer = Datagrams(np.frombuffer(b"".join(datagrams), dtype=np.uint8).copy(), bounds)
        self.words = self.buffer.data.view(np.uint32)  # the buffer as the 4-byte words `_write` writes
        # the headers of its sendmmsg made now, at the first frame's encoding (before the live loop's
        # schedule starts), not at its first sending: for 1,000 characters 5 ms of Python, which held
        # the interpreter from the next frame's work on the thread that sends a crowd's frames
        self.buffer.headers()

    def fill(self, values: np.ndarray, index: int, first: int = 0) -> Datagrams:
        """The frame's datagrams with `values` (every float of the messages from message `first`
        on, in message order) written in, and the frame index: views of the kept buffer, good
        until the next fill."""
        data = self.buffer.data
        _write(self.words, self.float_starts[first:], self.float_widths[first:],
               np.ascontiguousarray(values, dtype=np.float64))
        data[self.index_slot : self.index_slot + 4] = np.array([index], dtype=">i4").view(np.uint8)
        return self.buffer


@njit(cache=True, nogil=True)
def _write(words, starts, widths, values):  # pragma: no cover - compiled
    """Writes `values` (float64) as big-endian float32s into the messages' runs of float slots
    (each rounded to float32 as numpy's astype rounds it, then its bytes swapped); `words` is the
    frame's buffer as 4-byte words (OSC keeps every argument on a multiple of 4 bytes, and so
    does a bundle), `starts` in bytes."""
    single = np.empty(1, dtype=np.float32)
    bits = single.view(np.uint32)
    at = 0
    for m in range(starts.shape[0]):
        start = starts[m] // 4
        for i in range(widths[m]):
            single[0] = values[at + i]
            u = bits[0]
            words[start + i] = (u >> 24) | ((u >> 8) & 0xFF00) | ((u << 8) & 0xFF0000) | ((u << 24) & 0xFF000000)
        at += widths[m]


@njit(cache=True, nogil=True)
def _encode(rotations, world_rotations, world_positions, translations, root, values, words, starts, widths):  # pragma: no cover
    """Some characters' values (`_pose_values`) written into their messages (`_write`): one call
    a part of the crowd, so both run on the part's core."""
    _pose_values(rotations, world_rotations, world_positions, translations, root, values)
    _write(words, starts, widths, values)


@njit(cache=True, nogil=True)
def _quaternion(a, q):  # pragma: no cover - compiled
    """Rotation matrix `a` (3, 3) as a unit quaternion (x, y, z, w), w >= 0, into `q`: scipy's
    `Rotation.from_matrix(assume_valid=True)` (Markley's method) step by step, so the same
    numbers to the last bit as `posing.quaternions` (tests/test_flat_encoding.py)."""
    trace = a[0, 0] + a[1, 1] + a[2, 2]
    choice, best = 0, a[0, 0]
    if a[1, 1] > best:
        choice, best = 1, a[1, 1]
    if a[2, 2] > best:
        choice, best = 2, a[2, 2]
    if trace > best:
        choice = 3
    if choice != 3:
        i = choice
        j = (i + 1) % 3
        k = (j + 1) % 3
        q[i] = 1 - trace + 2 * a[i, i]
        q[j] = a[j, i] + a[i, j]
        q[k] = a[k, i] + a[i, k]
        q[3] = a[k, j] - a[j, k]
    else:
        q[0] = a[2, 1] - a[1, 2]
        q[1] = a[0, 2] - a[2, 0]
        q[2] = a[1, 0] - a[0, 1]
        q[3] = 1 + trace
    norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for c in range(4):
        q[c] /= norm
    if q[3] < 0:
        for c in range(4):
            q[c] = -q[c]


@njit(cache=True, nogil=True)
def _pose_values(rotations, world_rotations, world_positions, translations, root, out):  # pragma: no cover - compiled
    """Every character's values in the order they are sent (see the module's text): a quaternion
    per joint, a position per joint, the root's position, world quaternion and translation."""
    joints = rotations.shape[1]
    at = 0
    for n in range(rotations.shape[0]):
        for j in range(joints):
            _quaternion(rotations[n, j], out[at : at + 4])
            at += 4
        for j in range(joints):
            for c in range(3):
                out[at + c] = world_positions[n, j, c]
            at += 3
        for c in range(3):
            out[at + c] = world_positions[n, root, c]
        _quaternion(world_rotations[n, root], out[at + 3 : at + 7])
        for c in range(3):
            out[at + 7 + c] = translations[n, root, c]
        at += 10


class FlatProfile:
    def __init__(self, joint_names: list[str], root: int, characters: int = 1):
        self.names = joint_names
        self.root = root
        self.characters = characters
        self.whole_crowd = characters > 1  # datagrams() takes every character's pose (a CrowdPose)
        joints = len(joint_names)
        # per character, in the order sent: a quaternion per joint, a position per joint, the root's position,
        # world rotation and local translation
        self.prefixes, self.widths = [], []
        for head in (character_prefix(k) for k in range(characters)):
            self.prefixes += [float_prefix(f"{head}/bone/{n}/quat", 4) for n in joint_names]
            self.prefixes += [float_prefix(f"{head}/bone/{n}/pos", 3) for n in joint_names]
            self.prefixes += [float_prefix(f"{head}/root/{kind}", width)
                              for kind, width in (("pos", 3), ("quat", 4), ("local", 3))]
            self.widths += [4] * joints + [3] * joints + [3, 4, 3]
        self._template: tuple[tuple[str, ...], FrameTemplate] | None = None  # for the echo's names
        self._values = np.empty(0)
        # a crowd shared over the cores is sent from a thread of its own (outputs.OscOutput); one thread
        # for every target of this profile, since their frames are written into its one buffer: a target's
        # frame is not written before the last sending from the buffer has ended, whichever target's it was
        self.sending = Background("send flat") if len(parts(characters)) > 1 else None

    def datagrams(self, pose: Pose, echo: dict[str, float]) -> list[bytes]:
        """One frame's bundles: of one character (a Pose), or of a crowd (a CrowdPose: the same
        arrays with a leading character axis)."""
        return self.encode(pose, echo).copies()

    def encode(self, pose: Pose, echo: dict[str, float]) -> Datagrams:
        """`datagrams`, written into the profile's kept buffer (good until the next call): what
        the live loop sends, in one system call where the kernel has `sendmmsg`."""
        arrays = (pose.rotations, pose.world_rotations, pose.world_positions, pose.translations)
        if pose.rotations.ndim == 3:  # one character: a crowd of one
            arrays = tuple(a[None] for a in arrays)
        names = tuple(echo)
        if self._template is None or self._template[0] != names:
            echo_prefixes = [float_prefix(f"/walk/{name}", 1) for name in names]
            self._template = names, FrameTemplate(self.prefixes + echo_prefixes, self.widths + [1] * len(names))
            self._values = np.empty(sum(self.widths) + len(names) + 1)  # every float of a frame, in message order
        values, poses = self._values, len(self._values) - len(names) - 1
        if arrays[0].shape[0] * (7 * len(self.names) + 10) != poses:  # the kernel does not check its bounds
            raise ValueError(f"flat profile of {len(self.prefixes) // (2 * len(self.names) + 3)} characters given "
                             f"{arrays[0].shape[0]}")
        arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in arrays]
        template = self._template[1]
        words, starts, widths = template.words, template.float_starts, template.float_widths
        count, per = len(arrays[0]), 2 * len(self.names) + 3  # characters, and messages per character
        cut = parts(count)
        if len(cut) == 1:  # one core's worth (one character): no parts to cut
            _encode(*arrays, self.root, values[:poses], words, starts[: count * per], widths[: count * per])
        else:
            each = poses // count  # values per character
            over_cores(_encode, [(*(a[start:stop] for a in arrays), self.root, values[start * each : stop * each], words,
                                  starts[start * per : stop * per], widths[start * per : stop * per]) for start, stop in cut])
        values[poses:-1] = np.fromiter(echo.values(), float, len(names))
        values[-1] = float(pose.time)
        return template.fill(values[poses:], int(pose.index), first=len(arrays[0]) * per)


# /walk/footfall's start for each side (address, type tags, the side): `message`'s bytes, made once
_FOOTFALL_PREFIXES = [message("/walk/footfall", side, 0, 0.0, 0.0)[:-12] for side in SIDES]
_FOOTFALL_NUMBERS = struct.Struct(">iff")  # the character, the time, the speed


def footfall_datagrams(footfalls: list[Footfall], characters: range) -> list[bytes]:
    """The /walk/footfall messages of a frame's footfalls of `characters`, bundled (none: []).
    Each is its side's prefix and three numbers packed at once: a crowd of 1,000 lands some 60
    feet a frame, and `message` works out the type tags of each again."""
    prefixes, pack = _FOOTFALL_PREFIXES, _FOOTFALL_NUMBERS.pack
    messages = [prefixes[f.side] + pack(f.character, f.time, f.speed) for f in footfalls if f.character in characters]
    return bundles(messages) if messages else []
