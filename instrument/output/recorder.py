"""Recording the performance as BVH while it plays, safe against Ctrl-C, crashes and kills.

The header is written first with a fixed-width frame count; every frame is one line appended
in a single write, after which the count in the header is rewritten in place. The file on disk
is therefore a valid BVH after every frame. A process killed between the two writes leaves one
frame more than the header counts; `instrument recover FILE` repairs that. A recording never
overwrites an existing file unless asked to (run --force): nothing recorded is lost to a repeated command.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..motion.bvh import Skeleton, frame_lines, hierarchy_text

COUNT_WIDTH = 10


class BvhRecorder:
    def __init__(self, path: str | Path, skeleton: Skeleton, fps: float, replace: bool = False):
        self.path = Path(path)
        header = hierarchy_text(skeleton) + "MOTION\nFrames: "
        self.count_offset = len(header.encode("utf-8"))
        header += f"{0:0{COUNT_WIDTH}d}\nFrame Time: {1.0 / fps:.7f}\n"
        try:
            self.fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if replace else os.O_EXCL), 0o644)
            os.write(self.fd, header.encode("utf-8"))
        except FileExistsError:
            raise UserError(f"{self.path}: already exists; record to a new file, or give --force") from None
        except OSError as e:
            raise UserError(f"{self.path}: cannot record: {e.strerror or e}") from None
        self.frames = 0

    def write(self, channels: np.ndarray) -> None:
        os.write(self.fd, frame_lines(channels[None]).encode("ascii"))
        self.frames += 1
        os.pwrite(self.fd, f"{self.frames:0{COUNT_WIDTH}d}".encode("ascii"), self.count_offset)

    def close(self) -> None:
        """Close the file; a recording stopped before its first frame is removed (no file is
        better than a BVH with no motion, which no reader takes)."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
            if self.frames == 0:
                self.path.unlink(missing_ok=True)


def recover(path: str | Path) -> tuple[int, int]:
    """Make the header's frame count match the complete frame lines; (count before, after)."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e.strerror or e}") from None
    match = re.search(r"MOTION\s*\nFrames:\s*(\d+)\s*\nFrame Time:[^\n]*\n", text)
    if not match:
        raise UserError(f"{path}: no MOTION header: not a recording")
    body = text[match.end():]
    lines = body.split("\n")
    complete = lines[:-1] if not body.endswith("\n") else lines[:-1]  # a last line without newline is partial
    width = len(text[match.end():].split("\n", 1)[0].split()) if complete else 0
    good = [l for l in complete if len(l.split()) == width]
    if int(match.group(1)) == len(good) == len(complete) and body.endswith("\n"):
        return len(good), len(good)  # healthy: left exactly as it is
    fixed = text[: match.start(1)] + f"{len(good):0{COUNT_WIDTH}d}" + text[match.end(1): match.end()] + "".join(l + "\n" for l in good)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(fixed, encoding="utf-8")
    tmp.replace(path)
    return int(match.group(1)), len(good)
