"""Recording the performance as BVH while it plays, safe against Ctrl-C, crashes, kills and a full disk.

The header is written first, to NAME.part, with a fixed-width frame count; every frame is one
line appended, after which the count in the header is rewritten in place. The first frame moves
NAME.part onto NAME. So the file on disk is a valid BVH after every frame, and a run stopped
before its first frame leaves no NAME (a kill -9 then leaves a NAME.part with no motion, which
`instrument recover NAME` removes). A process killed between the two writes of a frame leaves one
frame more than the header counts; `instrument recover NAME` repairs that.

A write the disk refuses (full, a size limit, an I/O error) stops the recording: the part of the
frame that got written is cut off again, so the file keeps every frame before it as a valid BVH,
and `write` raises RecordingStopped once (the live loop says it in one line and goes on) and
does nothing from then on. A recording never overwrites an existing file unless asked to
(run --force): nothing recorded is lost to a repeated command.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..motion.bvh import Skeleton, frame_lines, hierarchy_text
from ..outputfile import write_all

COUNT_WIDTH = 10
HEADER = re.compile(rb"MOTION[ \t\r]*\nFrames:[ \t]*(\d+)[ \t\r]*\nFrame Time:[^\n]*\n")


class RecordingStopped(Exception):
    """The disk refused a frame: the recording ended, the file keeps what came before."""


def part_of(path: Path) -> Path:
    """Where a recording lives until its first frame."""
    return path.with_name(path.name + ".part")


class BvhRecorder:
    def __init__(self, path: str | Path, skeleton: Skeleton, fps: float, replace: bool = False):
        self.path = Path(path)
        self.part = part_of(self.path)
        self.replace = replace
        if self.path.exists() and not replace:
            raise UserError(f"{self.path}: already exists; record to a new file, or give --force")
        header = hierarchy_text(skeleton) + "MOTION\nFrames: "
        self.count_offset = len(header.encode("utf-8"))
        header += f"{0:0{COUNT_WIDTH}d}\nFrame Time: {1.0 / fps:.7f}\n"
        try:
            self.fd: int | None = os.open(self.part, os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if replace else os.O_EXCL), 0o644)
        except FileExistsError:
            raise UserError(f"{self.part}: left by a recording that was killed; `instrument recover {self.path}` "
                            "keeps what it holds (or removes it if it holds nothing)") from None
        except OSError as e:
            raise UserError(f"{self.path}: cannot record: {e.strerror or e}") from None
        try:
            write_all(self.fd, header.encode("utf-8"))
        except OSError as e:  # a disk full from the start: no empty file is left behind
            os.close(self.fd)
            self.part.unlink(missing_ok=True)
            raise UserError(f"{self.path}: cannot record: {e.strerror or e}") from None
        self.size = len(header.encode("utf-8"))  # bytes of the header and the whole frames
        self.frames = 0
        self.stopped: str | None = None  # why the recording ended early, once it has

    @property
    def file(self) -> Path:
        """The file the take is in now."""
        return self.path if self.frames else self.part

    def write(self, channels: np.ndarray) -> None:
        """Append one frame (the live loop's send). Raises RecordingStopped once when the disk
        refuses it; after that, and after close, it does nothing."""
        if self.fd is None or self.stopped is not None:
            return
        line = frame_lines(channels[None]).encode("ascii")
        try:
            write_all(self.fd, line)
            os.pwrite(self.fd, f"{self.frames + 1:0{COUNT_WIDTH}d}".encode("ascii"), self.count_offset)
        except OSError as e:
            self._stop(e)
        self.size += len(line)
        self.frames += 1
        if self.frames == 1:
            self._publish()

    def _stop(self, error: OSError) -> None:
        """Cut the frame the disk refused, so the file is the valid BVH it was before it."""
        try:
            os.ftruncate(self.fd, self.size)  # shrinking needs no space; the count still says self.frames
        except OSError:
            pass  # left one partial line: `instrument recover` cuts it
        kept = f"keeps the {self.frames} frames before it" if self.frames else "holds no frame and is removed"
        self.stopped = f"{self.file}: {error.strerror or error}: recording stopped; the file {kept} (the show goes on)"
        if not self.frames:
            self.close()
        raise RecordingStopped(self.stopped)

    def _publish(self) -> None:
        """The first frame is on disk: NAME.part becomes NAME (the open file goes on being written)."""
        try:
            if self.replace:
                os.replace(self.part, self.path)
                return
            try:
                os.link(self.part, self.path)  # never over a file that appeared meanwhile
            except FileExistsError:
                self.path = self.part  # the take goes on in NAME.part
                raise
            except OSError:  # a file system without hard links
                if self.path.exists():
                    self.path = self.part
                    raise FileExistsError(f"{self.path} appeared while recording") from None
                os.rename(self.part, self.path)
                return
            os.unlink(self.part)
        except OSError as e:
            raise RecordingStopped(f"{self.part}: could not become {self.path.name} ({e.strerror or e}); "
                                   f"the recording goes on in {self.part}") from None

    def close(self) -> None:
        """Close the file; a recording stopped before its first frame is removed (no file is
        better than a BVH with no motion, which no reader takes)."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
            if self.frames == 0:
                self.part.unlink(missing_ok=True)


def recover(path: str | Path) -> tuple[int, int, Path, int, list[int]]:
    """Make the header's frame count match the complete frame lines of the recording at `path` (or
    its NAME.part, where a run killed before its first frame left it): (count before, frames
    kept, the file that holds them, lines cut: a cut last line or lines that are not frames, and
    the numbers of those of them that had frames after them: the frames after such a line now
    come a frame earlier, which the user is told). A NAME.part with no frame is removed (0 frames
    kept).

    The usual case (a kill between a frame and its count: a count one short, maybe a cut last
    line) is fixed in place, which needs no free space. Anything else is written to a new file
    renamed over the old; a disk that refuses it leaves the recording exactly as it was."""
    path = Path(path)
    part = part_of(path)
    if not path.exists() and part.exists():
        path = part
    elif part.exists() and path.samefile(part):  # killed between the first frame's two names
        part.unlink()
    try:
        data = path.read_bytes()
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e.strerror or e}") from None
    match = HEADER.search(data)
    if not match:
        raise UserError(f"{path}: no MOTION header: not a recording")
    before = int(match.group(1))
    body = data[match.end():]
    complete = body.split(b"\n")[:-1]  # what follows the last newline is a cut line, or nothing
    width = len(complete[0].split()) if complete else 0
    whole = [k for k, line in enumerate(complete) if width and len(line.split()) == width]
    good = [complete[k] for k in whole]
    cut = len(complete) - len(good) + (1 if body.split(b"\n")[-1].strip() else 0)
    first = data[: match.end()].count(b"\n") + 1  # the first frame's line
    kept = set(whole)
    inside = [first + k for k in range(whole[-1]) if k not in kept] if whole else []
    if not good:
        if path.name.endswith(".part"):
            path.unlink()
            return before, 0, path, cut, []
        raise UserError(f"{path}: holds no complete frame: nothing to recover")
    if before == len(good) == len(complete) and data.endswith(b"\n"):
        return before, before, path, 0, []  # healthy: left exactly as it is
    count = f"{len(good):0{COUNT_WIDTH}d}".encode("ascii")
    if len(good) == len(complete) and len(match.group(1)) == COUNT_WIDTH:
        _fix_in_place(path, match.start(1), count, match.end() + sum(len(line) + 1 for line in good))
    else:
        _rewrite(path, data[: match.start(1)] + count + data[match.end(1): match.end()] + b"".join(l + b"\n" for l in good))
    return before, len(good), _settle(path), cut, inside


def _fix_in_place(path: Path, count_at: int, count: bytes, size: int) -> None:
    """Cut the partial last line and rewrite the count (same width): no new space needed."""
    try:
        fd = os.open(path, os.O_WRONLY)
        try:
            os.ftruncate(fd, size)
            os.pwrite(fd, count, count_at)
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as e:
        raise UserError(f"{path}: cannot repair: {e.strerror or e}") from None


def _rewrite(path: Path, fixed: bytes) -> None:
    """The repaired text to a new file renamed over `path`; on failure `path` is untouched."""
    tmp = path.with_name(path.name + ".recovering")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            write_all(fd, fixed)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise UserError(f"{path}: cannot write the repaired copy: {e.strerror or e}; the recording is left as it was") from None


def _settle(path: Path) -> Path:
    """A repaired NAME.part becomes NAME, unless NAME exists (then it stays where it is)."""
    if not path.name.endswith(".part"):
        return path
    final = path.with_name(path.name[: -len(".part")])
    try:
        os.link(path, final)
        os.unlink(path)
        return final
    except OSError:
        return path
