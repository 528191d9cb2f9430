"""BVH files: read any hierarchy and channel layout, write files that read back to the same numbers.

A BVH file is a skeleton (joints, offsets, channels per joint) followed by one line of channel
values per frame. `Motion` keeps exactly that: the skeleton and a (frames x channels) array, with
rotations in degrees as in the file. Interpretation (Euler orders, kinematics) lives elsewhere.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import UserError, located, quoted
from ..outputfile import written
from ..textfile import read_text

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
KNOWN_CHANNELS = {name.lower(): name for name in POSITION_CHANNELS + ROTATION_CHANNELS}


@dataclass(frozen=True)
class Joint:
    name: str
    parent: int  # index of the parent joint, -1 for the root
    offset: tuple[float, float, float]
    channels: tuple[str, ...]
    end_site: tuple[float, float, float] | None = None  # offset of an End Site child, if any

    @property
    def rotation_order(self) -> str:
        """Axes of the rotation channels in file order, e.g. 'ZXY' ('' for none)."""
        return "".join(c[0] for c in self.channels if c.endswith("rotation"))

    @property
    def position_axes(self) -> str:
        return "".join(c[0] for c in self.channels if c.endswith("position"))


@dataclass(frozen=True)
class Skeleton:
    joints: tuple[Joint, ...]

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def parents(self) -> np.ndarray:
        return np.array([j.parent for j in self.joints], dtype=np.int64)

    @property
    def offsets(self) -> np.ndarray:
        return np.array([j.offset for j in self.joints], dtype=np.float64)

    @property
    def channel_count(self) -> int:
        return sum(len(j.channels) for j in self.joints)

    def channel_start(self) -> np.ndarray:
        """Index of each joint's first channel in a frame line."""
        counts = [len(j.channels) for j in self.joints]
        return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def children(self, joint: int) -> list[int]:
        return [i for i, j in enumerate(self.joints) if j.parent == joint]

    def to_dict(self) -> dict:
        """Plain JSON-ready description, stored in model files."""
        return {
            "joints": [
                {
                    "name": j.name,
                    "parent": j.parent,
                    "offset": list(j.offset),
                    "channels": list(j.channels),
                    "end_site": None if j.end_site is None else list(j.end_site),
                }
                for j in self.joints
            ]
        }

    @classmethod
    def from_dict(cls, data: dict) -> "Skeleton":
        return cls(
            tuple(
                Joint(
                    name=str(j["name"]),
                    parent=int(j["parent"]),
                    offset=tuple(float(v) for v in j["offset"]),
                    channels=tuple(str(c) for c in j["channels"]),
                    end_site=None if j.get("end_site") is None else tuple(float(v) for v in j["end_site"]),
                )
                for j in data["joints"]
            )
        )

    def layout_key(self) -> tuple:
        """Its joints, parents and channels (not the offsets, which may differ slightly): what
        `same_layout` compares, hashable (training counts the skeletons its takes share)."""
        return tuple((j.name, j.parent, j.channels) for j in self.joints)

    def same_layout(self, other: "Skeleton") -> bool:
        """True when both have the same joints, parents and channels (offsets may differ slightly)."""
        return self.layout_key() == other.layout_key()


@dataclass
class Motion:
    skeleton: Skeleton
    channels: np.ndarray  # (frames, channel_count), rotations in degrees
    fps: float
    source: str = ""

    @property
    def frames(self) -> int:
        return int(self.channels.shape[0])

    @property
    def duration(self) -> float:
        return self.frames / self.fps


class _Lines:
    """Cursor over a file's whitespace-split lines, keeping 1-based line numbers for errors."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.lines = text.splitlines()
        self.pos = 0

    def error(self, message: str, line: int | None = None) -> UserError:
        return located(self.path, message, line if line is not None else min(self.pos, len(self.lines)) or None)

    def next_tokens(self) -> list[str]:
        """The next non-empty line's tokens; an error at end of file."""
        while self.pos < len(self.lines):
            self.pos += 1
            tokens = self.lines[self.pos - 1].split()
            if tokens:
                return tokens
        raise self.error("unexpected end of file in HIERARCHY (is MOTION missing?)", len(self.lines))


def _floats(lines: _Lines, tokens: list[str], count: int, what: str) -> tuple[float, ...]:
    if len(tokens) != count:
        raise lines.error(f"{what} needs {count} numbers, found {len(tokens)}")
    try:
        values = tuple(float(t) for t in tokens)
    except ValueError:
        raise lines.error(f"{what} has a value that is not a number: {quoted(' '.join(tokens))}") from None
    if not all(math.isfinite(v) for v in values):
        raise lines.error(f"{what} has a value that is not finite")
    return values


# What a file that is not BVH is, from how it starts (content first: a name can lie) and else
# from its name: the formats a capture is commonly exported in, and files often given by mistake.
_SIGNATURES = (
    ("glTF", "a binary glTF (.glb) file"),
    ("Kaydara FBX Binary", "an FBX file"),
    ("; FBX", "an FBX file"),
    ("PK\x03\x04", "a zip archive (a .zip or .npz)"),
    (":FILE", "an Acclaim ASF/AMC file"),
    (":FULLY-SPECIFIED", "an Acclaim AMC file"),
)
_SUFFIXES = {
    ".glb": "a binary glTF file", ".gltf": "a glTF file", ".vrm": "a VRM (glTF) file", ".fbx": "an FBX file",
    ".c3d": "a C3D marker file", ".trc": "a TRC marker file", ".dae": "a COLLADA file", ".obj": "a Wavefront OBJ mesh",
    ".usd": "a USD file", ".usda": "a USD file", ".usdc": "a USD file", ".usdz": "a USD file", ".abc": "an Alembic file",
    ".amc": "an Acclaim AMC file", ".asf": "an Acclaim ASF file", ".npz": "a NumPy archive", ".npy": "a NumPy array",
    ".json": "a JSON file", ".csv": "a CSV file", ".toml": "a TOML file", ".blend": "a Blender file",
    ".ma": "a Maya file", ".mb": "a Maya file", ".zip": "a zip archive",
}

# the formats a motion capture is exported in besides BVH (a folder of them holds takes in the wrong format)
OTHER_CAPTURE_SUFFIXES = frozenset(_SUFFIXES) - {".obj", ".npy", ".json", ".csv", ".toml", ".zip"}  # (not motion)


def other_format(path: str, head: str) -> str | None:
    """What the file at `path`, starting with `head`, is when it is plainly some other format
    ("a binary glTF (.glb) file"), or None: a user who gives an export of the wrong format
    learns what it is and what to give, not that a BVH starts with HIERARCHY."""
    start = head.lstrip("\ufeff \t\r\n")
    for signature, what in _SIGNATURES:
        if start.startswith(signature):
            return what
    if start.startswith("<") and "COLLADA" in start[:2000]:
        return "a COLLADA (.dae) file"
    by_name = _SUFFIXES.get(Path(path).suffix.lower())
    if by_name is not None:
        return by_name
    if start.startswith("{"):
        return "a JSON file"
    if start.startswith("<"):
        return "an XML or HTML file"
    return None


def _parse_hierarchy(lines: _Lines) -> Skeleton:
    if not any(line.strip() for line in lines.lines):  # (not "FILE:0: unexpected end of file")
        raise lines.error("the file is empty: a BVH file starts with HIERARCHY")
    tokens = lines.next_tokens()
    if tokens[0].upper() != "HIERARCHY":
        other = other_format(lines.path, "\n".join(lines.lines[:20]))
        if other is not None:
            raise UserError(f"{lines.path}: {other}, not a BVH (give a .bvh capture; "
                            "a BVH file is text that starts with HIERARCHY)")
        raise lines.error("a BVH file starts with HIERARCHY")
    tokens = lines.next_tokens()
    if tokens[0].upper() != "ROOT":
        raise lines.error(f"expected ROOT, found {quoted(tokens[0])}")
    joints: list[dict] = []
    stack: list[int] = []  # open joints; -2 marks an open End Site
    end_owner = -1  # the joint whose End Site is open
    pending: tuple[str, int] | None = (" ".join(tokens[1:]) or "root", -1)
    while True:
        if pending is not None:
            name, parent = pending
            pending = None
            if lines.next_tokens() != ["{"]:
                raise lines.error(f"expected '{{' after joint {quoted(name)}")
            joints.append({"name": name, "parent": parent, "offset": None, "channels": (), "end_site": None})
            stack.append(len(joints) - 1)
            continue
        tokens = lines.next_tokens()
        key = tokens[0].upper()
        current = stack[-1] if stack else None
        if key == "OFFSET":
            offset = _floats(lines, tokens[1:], 3, "OFFSET")
            if current == -2:
                joints[end_owner]["end_site"] = offset
            else:
                joints[current]["offset"] = offset
        elif key == "CHANNELS":
            if current == -2:
                raise lines.error("an End Site has no CHANNELS")
            try:
                count = int(tokens[1])
            except (IndexError, ValueError):
                raise lines.error("CHANNELS needs a count") from None
            names = tokens[2:]
            if len(names) != count:
                raise lines.error(f"CHANNELS says {count} channels but lists {len(names)}")
            unknown = [n for n in names if n.lower() not in KNOWN_CHANNELS]
            if unknown:
                raise lines.error(f"unknown channel {quoted(unknown[0])}")
            channels = tuple(KNOWN_CHANNELS[n.lower()] for n in names)
            if len(set(channels)) != len(channels):
                raise lines.error("a channel is listed twice")
            if len([c for c in channels if c.endswith("rotation")]) not in (0, 3):
                raise lines.error("a joint needs all three rotation channels or none")
            joints[current]["channels"] = channels
        elif key == "JOINT":
            if current == -2:
                raise lines.error("an End Site cannot hold a JOINT")
            pending = (" ".join(tokens[1:]), current)
        elif key == "END":
            end_owner = current
            if lines.next_tokens() != ["{"]:
                raise lines.error("expected '{' after End Site")
            stack.append(-2)
        elif key == "}":
            stack.pop()
            if not stack:
                break
        elif key == "MOTION":
            raise lines.error("MOTION before the hierarchy was closed (a '}' is missing)")
        else:
            raise lines.error(f"unexpected {quoted(tokens[0])} in HIERARCHY")
    for j in joints:
        if j["offset"] is None:
            raise lines.error(f"joint {quoted(j['name'])} has no OFFSET")
    names = [j["name"] for j in joints]
    if len(set(names)) != len(names):
        raise lines.error("two joints have the same name")
    return Skeleton(tuple(Joint(**j) for j in joints))


def parse_bvh(text: str, path: str = "<text>") -> Motion:
    lines = _Lines(path, text)
    skeleton = _parse_hierarchy(lines)
    tokens = lines.next_tokens() if lines.pos < len(lines.lines) else []
    if not tokens or tokens[0].upper() != "MOTION":
        raise lines.error("MOTION section is missing", len(lines.lines))
    tokens = lines.next_tokens()
    if tokens[0].lower() != "frames:" or len(tokens) != 2 or not tokens[1].isdigit() or len(tokens[1]) > 12:
        raise lines.error("expected 'Frames: N'")
    frame_count = int(tokens[1])
    tokens = lines.next_tokens()
    if [t.lower() for t in tokens[:2]] != ["frame", "time:"] or len(tokens) != 3:
        raise lines.error("expected 'Frame Time: SECONDS'")
    try:
        frame_time = float(tokens[2])
    except ValueError:
        raise lines.error("Frame Time is not a number") from None
    if not MIN_FRAME_TIME <= frame_time <= MAX_FRAME_TIME:  # also refuses nan and inf
        raise lines.error(f"Frame Time must be {MIN_FRAME_TIME:g} to {MAX_FRAME_TIME:g} s (1000 to 1 frames per second), "
                          f"not {tokens[2]}")
    header_line = lines.pos  # 1-based number of the Frame Time line
    # blank lines among the frames are skipped, as in the hierarchy (Blender's reader does the same)
    numbered = [(header_line + 1 + k, row) for k, row in enumerate(lines.lines[lines.pos :]) if row.strip()]
    line_numbers = [n for n, _ in numbered]
    rows = [row for _, row in numbered]
    width = skeleton.channel_count
    if len(rows) < frame_count:
        last = line_numbers[-1] if line_numbers else header_line
        raise located(path, f"truncated: header says {frame_count} frames, file has {len(rows)}", last)
    if len(rows) > frame_count:
        raise located(path, f"header says {frame_count} frames but more lines follow", line_numbers[frame_count])
    if frame_count == 0:
        raise located(path, "the file has no frames", header_line - 1)
    joined = " ".join(rows)
    try:
        values = np.array(joined.split(), dtype=np.float64)
    except ValueError:
        values = None
    if values is None or values.size != frame_count * width or not np.isfinite(values).all():
        _raise_frame_error(path, numbered, width)
    fps = _fps_from_frame_time(frame_time)
    values = values.reshape(frame_count, width)
    _check_jumps(path, skeleton, values, line_numbers, fps)
    return Motion(skeleton, values, fps, source=path)


MIN_FRAME_TIME, MAX_FRAME_TIME = 0.001, 1.0  # seconds: motion capture runs at 1 to 1000 frames per second


def _fps_from_frame_time(frame_time: float) -> float:
    """Files store 1/fps rounded (0.0333333); snap to the whole rate the author meant."""
    fps = 1.0 / frame_time
    whole = round(fps)
    return float(whole) if whole > 0 and abs(fps - whole) < 1e-4 * fps else fps


JUMP_EXTENTS_PER_SECOND = 20.0  # a position channel faster than this many body extents a second is a glitch


def body_extent(skeleton: Skeleton) -> float:
    """The longest chain of bones from the root to an end (OFFSETs and End Sites summed as
    lengths, whatever the pose): about a body's height, in the file's units."""
    reach = np.zeros(len(skeleton.joints))
    ends = [0.0]
    for k, joint in enumerate(skeleton.joints):  # parents come first in a BVH
        if joint.parent >= 0:
            reach[k] = reach[joint.parent] + float(np.linalg.norm(joint.offset))
        if joint.end_site is not None:
            ends.append(reach[k] + float(np.linalg.norm(joint.end_site)))
    return float(max(reach.max(initial=0.0), *ends))


def _check_jumps(path: str, skeleton: Skeleton, values: np.ndarray, line_numbers: list[int], fps: float) -> None:
    """Refuse a position channel that leaps between two frames faster than JUMP_EXTENTS_PER_SECOND
    body extents a second (about 34 m/s for a body 1.7 m long; a sprinter makes 12): a capture
    glitch, a marker swap or takes joined end to end. Parsed as finite numbers, one such frame of
    the hips 10 km up trained a style whose walk floated 39 m above the floor and stood still,
    without a word; its line is named here instead."""
    extent = body_extent(skeleton)
    columns = [start + k for start, joint in zip(skeleton.channel_start(), skeleton.joints)
               for k, channel in enumerate(joint.channels) if channel.endswith("position")]
    if extent <= 0 or not columns or len(values) < 2:
        return
    with np.errstate(over="ignore", invalid="ignore"):  # 1e308 against -1e308 is a leap too
        leaps = np.abs(np.diff(values[:, columns], axis=0)) * fps
    over = ~(leaps <= JUMP_EXTENTS_PER_SECOND * extent)
    if over.any():
        frame, column = np.argwhere(over)[0]
        channel = int(columns[column])
        joint = int(np.searchsorted(skeleton.channel_start(), channel, side="right") - 1)
        name = skeleton.joints[joint].channels[channel - skeleton.channel_start()[joint]]
        jump = abs(float(values[frame + 1, channel]) - float(values[frame, channel]))
        raise located(path, f"{skeleton.joints[joint].name} {name} leaps {jump:.6g} in one frame (the body is "
                            f"about {extent:.3g} long): a capture glitch? fix or cut the frame", line_numbers[frame + 1])


def _raise_frame_error(path: str, numbered: list[tuple[int, str]], width: int) -> None:
    """Find the first bad frame line (slow path, only on error); `numbered` holds (line number, text)."""
    for line, row in numbered:
        tokens = row.split()
        if len(tokens) != width:
            raise located(path, f"frame has {len(tokens)} values, the hierarchy has {width} channels", line)
        for t in tokens:
            try:
                v = float(t)
            except ValueError:
                raise located(path, f"not a number: {quoted(t)}", line) from None
            if not math.isfinite(v):
                raise located(path, f"not a finite number: {quoted(t)}", line)
    raise located(path, "frame data could not be read")


def read_bvh(path: str | Path) -> Motion:
    path = Path(path)
    return parse_bvh(read_text(path, latin1_fallback=True), str(path))


def _fmt(values) -> str:
    return " ".join(f"{v:.6f}" for v in values)


def hierarchy_text(skeleton: Skeleton) -> str:
    """The HIERARCHY section, tab-indented."""
    out = io.StringIO()
    out.write("HIERARCHY\n")

    def write(index: int, depth: int) -> None:
        joint = skeleton.joints[index]
        pad = "\t" * depth
        out.write(f"{pad}{'ROOT' if joint.parent < 0 else 'JOINT'} {joint.name}\n{pad}{{\n")
        out.write(f"{pad}\tOFFSET {_fmt(joint.offset)}\n")
        if joint.channels:
            out.write(f"{pad}\tCHANNELS {len(joint.channels)} {' '.join(joint.channels)}\n")
        for child in skeleton.children(index):
            write(child, depth + 1)
        if joint.end_site is not None:
            out.write(f"{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET {_fmt(joint.end_site)}\n{pad}\t}}\n")
        out.write(f"{pad}}}\n")

    write(0, 0)
    return out.getvalue()


def frame_lines(channels: np.ndarray) -> str:
    """Frame lines for a (frames x channels) block, newline-terminated."""
    if len(channels) == 0:
        return ""
    row = " ".join(["%.6f"] * channels.shape[1])
    body = "\n".join(row % tuple(r) for r in np.where(channels == 0, 0.0, channels))  # no '-0.000000'
    return body + "\n"


def bvh_text(motion: Motion) -> str:
    return (
        hierarchy_text(motion.skeleton)
        + f"MOTION\nFrames: {motion.frames}\nFrame Time: {1.0 / motion.fps:.7f}\n"
        + frame_lines(motion.channels)
    )


def write_bvh(path: str | Path, motion: Motion) -> None:
    """Write atomically: a crash mid-write never leaves a half file in place of a good one, and a
    failed write (a full disk) leaves no PATH.part behind."""
    text = bvh_text(motion)
    with written(path) as part:
        part.write_text(text, encoding="utf-8")
