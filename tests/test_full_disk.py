"""A full disk never breaks the show or loses what was recorded.

Two ways to fill a disk: a real tmpfs of 64 KiB (mounted by the test; skipped, with the reason,
where mounting is not permitted), and a file size limit (RLIMIT_FSIZE, set in the child before
it runs), which needs no privilege and so always runs: the kernel writes what fits, returns a
short count, and refuses the next write (EFBIG), as a disk that fills mid-write does (ENOSPC).
"""

from __future__ import annotations

import errno
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from instrument.control.eventlog import EventLog
from instrument.control.events import ControlEvent
from instrument.control.hub import ControlHub
from instrument.control.events import read_log
from instrument.errors import UserError
from instrument.motion.bvh import read_bvh
from instrument.output.recorder import BvhRecorder
from instrument.terminal import Console
from waiting import wait_until

INSTRUMENT = [sys.executable, "-m", "instrument"]
RUN = INSTRUMENT + ["run", "--no-osc", "--normal-priority"]


@pytest.fixture
def tmpfs(tmp_path):
    """A real 64 KiB tmpfs, unmounted afterwards."""
    where = tmp_path / "small disk"
    where.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(where)], capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({mounted.stderr.strip() or 'mount refused'}); "
                    "the file size limit tests cover the same paths")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def fill(folder: Path) -> Path:
    """Fill the file system of `folder` to the last byte; the filler file."""
    filler = folder / "filler"
    with open(filler, "wb", buffering=0) as f:
        block = b"\0" * 4096
        while True:
            try:
                if f.write(block) == 0:
                    break
            except OSError as e:
                assert e.errno == errno.ENOSPC
                break
        while True:  # the last bytes of the last page
            try:
                if f.write(b"\0") == 0:
                    break
            except OSError:
                break
    return filler


def limited(size: int):
    """preexec_fn: files this process writes stop at `size` bytes (and the kernel says so with
    EFBIG, not with the signal that would kill the process)."""
    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, resource.RLIM_INFINITY))
    return limit


def bvh_header_bytes() -> int:
    from instrument.models.modelfile import default_model_path, load_model
    from instrument.motion.bvh import hierarchy_text

    return len(hierarchy_text(load_model(default_model_path()).layout.skeleton).encode()) + 40


def assert_valid_bvh(path: Path) -> int:
    """The header counts exactly the whole frame lines, and the reader agrees."""
    data = path.read_bytes()
    header = int(re.search(rb"\nFrames: (\d+)", data).group(1))
    lines = data.split(b"Frame Time:", 1)[1].split(b"\n")[1:]
    assert lines[-1] == b"", "the last frame line is cut"
    assert header == len(lines) - 1, f"header {header}, frame lines {len(lines) - 1}"
    assert read_bvh(path).frames == header
    return header


def stopped_lines(stderr: str, name: str) -> list[str]:
    return [line for line in stderr.splitlines() if name in line and "recording stopped" in line]


def record_until_full(bvh: Path, seconds: int = 20, preexec=None) -> subprocess.CompletedProcess:
    return subprocess.run(RUN + ["--bvh", str(bvh), "--fast", "--seconds", str(seconds)], capture_output=True, text=True,
                          timeout=600, preexec_fn=preexec)


def check_the_show_went_on(result: subprocess.CompletedProcess, bvh: Path, seconds: int = 20) -> None:
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    (line,) = stopped_lines(result.stderr, bvh.name)  # said once, when it happened
    frames = assert_valid_bvh(bvh)
    assert 1 <= frames < seconds * 30
    assert f"keeps the {frames} frames" in line
    assert f"stopped after {seconds * 30} frames" in result.stderr  # the show went on to its end
    assert not list(bvh.parent.glob("*.part"))


def test_a_recording_that_fills_a_real_tmpfs_keeps_a_valid_bvh_and_the_show_goes_on(tmpfs):
    bvh = tmpfs / "take.bvh"
    result = record_until_full(bvh)
    assert "No space left on device" in stopped_lines(result.stderr, bvh.name)[0]
    check_the_show_went_on(result, bvh)
    assert subprocess.run(INSTRUMENT + ["recover", str(bvh)], capture_output=True, text=True).stdout.endswith("left as it is\n")


def test_a_recording_cut_short_by_the_file_size_limit_keeps_a_valid_bvh(tmp_path):
    """The limit falls inside a frame line: the kernel writes half of it (a short write) first."""
    bvh = tmp_path / "take.bvh"
    result = record_until_full(bvh, preexec=limited(bvh_header_bytes() + 20 * 1300 + 650))
    check_the_show_went_on(result, bvh)


def test_a_disk_full_at_start_is_one_line_and_leaves_no_file(tmpfs, tmp_path):
    fill(tmpfs)
    before = sorted(os.listdir(tmpfs))
    result = subprocess.run(RUN + ["--bvh", str(tmpfs / "take.bvh"), "--seconds", "1"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "take.bvh" in result.stderr and "No space left on device" in result.stderr
    result = subprocess.run(RUN + ["--record", str(tmpfs / "take.jsonl"), "--seconds", "1"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "take.jsonl" in result.stderr and "No space left on device" in result.stderr
    assert sorted(os.listdir(tmpfs)) == before  # no empty file left behind


def test_a_file_size_limit_at_start_is_one_line_and_leaves_no_file(tmp_path):
    for option, name in (("--bvh", "take.bvh"), ("--record", "take.jsonl")):
        result = subprocess.run(RUN + [option, str(tmp_path / name), "--seconds", "1"], capture_output=True, text=True,
                                timeout=300, preexec_fn=limited(10))
        assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert name in result.stderr and "File too large" in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_controller_log_says_at_once_when_a_full_disk_stops_it(tmpfs, tmp_path):
    """Through the hub, as `run --record` does: the one line comes while the show goes on, the
    log ends on a whole line and replays every event it kept."""
    said = tmp_path / "console.txt"
    with open(said, "w") as stream:
        console = Console(stream=stream)
        hub = ControlHub([], record=tmpfs / "take.jsonl", console=console)
        state = _state()
        count = 0
        while hub.log.error is None:
            hub.apply(state, ControlEvent(count / 30, "osc:127.0.0.1", "speed", 1.0 + (count % 10) / 100))
            count += 1
            if count % 100 == 0:  # a batch at a time, as a performer's moves come: most fit on the disk
                wait_until(lambda: not hub.log.pending or hub.log.error, "the writer thread's turn")
            assert count < 10_000_000
        wait_until(lambda: console.flush() and "recording stopped" in said.read_text(), "the warning")
        hub.close()
        console.flush()
    lines = [line for line in said.read_text().splitlines() if "recording stopped" in line]
    assert len(lines) == 1 and "take.jsonl" in lines[0] and "No space left on device" in lines[0]
    kept = read_log(tmpfs / "take.jsonl", warn=lambda m: pytest.fail(f"the log was cut mid-line: {m}"))
    assert 0 < len(kept) < count
    assert (tmpfs / "take.jsonl").read_bytes().endswith(b"\n")


def _state():
    from instrument.control.state import ControlState

    return ControlState(["elderly", "youthful"], 5)


LOG_UNTIL_LIMIT = """
import sys, time
from instrument.control.eventlog import EventLog
from instrument.control.events import ControlEvent
log = EventLog(sys.argv[1], '{"instrument_log": {}}', warn=lambda line: print("WARN", line, flush=True))
k = 0
while log.error is None:
    log.write(ControlEvent(k / 30, "osc:127.0.0.1", "speed", 1.25))
    k += 1
    while k % 50 == 0 and log.pending and log.error is None:  # a batch at a time
        time.sleep(0.01)
print("STILL RUNNING", flush=True)
log.close()
print("CLOSED", k, flush=True)
"""


def test_the_controller_log_under_a_file_size_limit_stops_on_a_whole_line(tmp_path):
    path = tmp_path / "take.jsonl"
    result = subprocess.run([sys.executable, "-c", LOG_UNTIL_LIMIT, str(path)], capture_output=True, text=True, timeout=300,
                            preexec_fn=limited(20_000 + 37))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("WARN") and "take.jsonl" in lines[0] and "File too large" in lines[0]
    assert lines[1] == "STILL RUNNING" and len(lines) == 3  # said before the end, and once
    assert path.read_bytes().endswith(b"\n")
    kept = read_log(path, warn=lambda m: pytest.fail(f"the log was cut mid-line: {m}"))
    assert 0 < len(kept) < int(lines[2].split()[1])


def recording(path: Path, frames: int, skeleton_bvh: str) -> None:
    """A recording as the recorder leaves it: frames of the skeleton's rest."""
    header, motion = skeleton_bvh.split("MOTION\n")
    row = motion.splitlines()[2]
    path.write_text(header + f"MOTION\nFrames: {frames:010d}\nFrame Time: 0.0333333\n" + (row + "\n") * frames)


@pytest.fixture(scope="module")
def rest_bvh(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("rest") / "rest.bvh"
    subprocess.run(INSTRUMENT + ["skeleton", "--out", str(out)], check=True, capture_output=True, timeout=300)
    return out.read_text()


def test_recover_on_a_full_tmpfs_mends_a_killed_take_in_place(tmpfs, rest_bvh):
    """The usual kill (a frame written, its count not, half a frame after it) needs no free space."""
    take = tmpfs / "take.bvh"
    recording(take, 12, rest_bvh)
    data = take.read_bytes()
    take.write_bytes(data.replace(b"Frames: 0000000012", b"Frames: 0000000011") + data.splitlines()[-1][:300])
    fill(tmpfs)
    result = subprocess.run(INSTRUMENT + ["recover", str(take)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert assert_valid_bvh(take) == 12


def test_recover_on_a_full_tmpfs_fails_in_one_line_and_leaves_the_take(tmpfs, rest_bvh):
    take = tmpfs / "take.bvh"
    recording(take, 12, rest_bvh)
    lines = take.read_bytes().split(b"\n")
    lines[-5] = lines[-5][:200]  # a damaged line among the frames: only a rewrite mends it
    take.write_bytes(b"\n".join(lines))
    before = take.read_bytes()
    fill(tmpfs)
    result = subprocess.run(INSTRUMENT + ["recover", str(take)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "take.bvh" in result.stderr and "No space left on device" in result.stderr and "left as it was" in result.stderr
    assert take.read_bytes() == before
    assert sorted(os.listdir(tmpfs)) == ["filler", "take.bvh"]
    (tmpfs / "filler").unlink()  # room again: the same command mends it
    assert subprocess.run(INSTRUMENT + ["recover", str(take)], capture_output=True, text=True, timeout=120).returncode == 0
    assert assert_valid_bvh(take) == 11


def test_recover_under_a_file_size_limit_fails_in_one_line_and_leaves_the_take(tmp_path, rest_bvh):
    take = tmp_path / "take.bvh"
    recording(take, 12, rest_bvh)
    lines = take.read_bytes().split(b"\n")
    lines[-5] = lines[-5][:200]
    take.write_bytes(b"\n".join(lines))
    before = take.read_bytes()
    result = subprocess.run(INSTRUMENT + ["recover", str(take)], capture_output=True, text=True, timeout=120,
                            preexec_fn=limited(len(before) - 4000))
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "File too large" in result.stderr and "left as it was" in result.stderr
    assert take.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["take.bvh"]


@pytest.mark.parametrize("moment", ["before the first frame", "at the first frame"])
def test_a_kill_9_in_the_first_frames_leaves_what_recover_mends(tmp_path, moment):
    """SIGKILL as soon as the recording's file appears: recover then either removes a take with
    no frame (and the same command runs again) or mends it into a valid BVH."""
    bvh, part = tmp_path / "take.bvh", tmp_path / "take.bvh.part"
    process = subprocess.Popen(RUN + ["--bvh", str(bvh), "--quiet"], stderr=subprocess.PIPE, text=True)
    try:
        if moment == "before the first frame":
            wait_until(lambda: part.exists() or bvh.exists(), "the recording's file")
        else:
            wait_until(bvh.exists, "the first frame")
        process.kill()
    finally:
        process.wait(60)
        process.stderr.close()
    assert process.returncode == -signal.SIGKILL
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left in (["take.bvh"], ["take.bvh.part"], ["take.bvh", "take.bvh.part"])  # never a 0-frame take.bvh
    result = subprocess.run(INSTRUMENT + ["recover", str(bvh)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    if "nothing was recorded" in result.stdout:
        assert left == ["take.bvh.part"] and list(tmp_path.iterdir()) == []
    else:
        assert assert_valid_bvh(bvh) >= 1 and sorted(p.name for p in tmp_path.iterdir()) == ["take.bvh"]
    if moment == "at the first frame":
        assert bvh.exists()


def test_a_take_left_before_its_first_frame_is_named_not_overwritten(tmp_path, model):
    part = tmp_path / "take.bvh.part"
    part.write_text("left by a killed run")
    with pytest.raises(UserError, match=r"take\.bvh\.part: left by a recording that was killed; `instrument recover"):
        BvhRecorder(tmp_path / "take.bvh", model.layout.skeleton, 30.0)
    assert part.read_text() == "left by a killed run"


def test_a_log_on_a_disk_full_at_start_leaves_no_file(tmpfs):
    fill(tmpfs)
    with pytest.raises(UserError, match="No space left on device"):
        EventLog(tmpfs / "take.jsonl", '{"instrument_log": {}}')
    assert not (tmpfs / "take.jsonl").exists()


def test_writing_to_a_full_device_raises_instead_of_losing_bytes():
    from instrument.outputfile import write_all

    fd = os.open("/dev/full", os.O_WRONLY)
    try:
        with pytest.raises(OSError) as caught:
            write_all(fd, b"x" * 10)
        assert caught.value.errno == errno.ENOSPC
    finally:
        os.close(fd)




@pytest.mark.parametrize("command, out", [
    (["synth", "--seconds", "1", "--out"], "walk.bvh"),
    (["synth", "--seconds", "1", "--out"], "walk.glb"),
    (["skeleton", "--out"], "rest.bvh"),
    (["train", str(Path(__file__).resolve().parents[1] / "examples" / "data"), "--quiet", "--out"], "model.npz"),
])
def test_an_output_cut_short_by_the_file_size_limit_is_one_line_and_leaves_no_part(tmp_path, command, out):
    """The rule of every output (docs/cli.md): the .part is removed on failure. BVH and model
    files left their .part behind (only glTF went through the shared writer)."""
    warm = tmp_path / "warm"  # the same command once without the limit: numba's cache holds its kernels
    warm.mkdir()
    assert subprocess.run(INSTRUMENT + command + [str(warm / out)], capture_output=True, timeout=600).returncode == 0
    shutil.rmtree(warm)
    (tmp_path / out).write_bytes(b"precious")
    result = subprocess.run(INSTRUMENT + command + [str(tmp_path / out), "--force"], capture_output=True, text=True,
                            timeout=600, preexec_fn=limited(2000))
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert f"{out}: cannot write: File too large" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [out] and (tmp_path / out).read_bytes() == b"precious"


def test_a_first_run_that_cannot_cache_its_kernels_is_one_line(tmp_path):
    """numba saves a first run's compiled kernels to its cache; a full disk or a file size limit
    there was a traceback from inside numba. Now one line naming the cache."""
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    result = subprocess.run(INSTRUMENT + ["synth", "--seconds", "1", "--out", str(tmp_path / "walk.bvh")], capture_output=True,
                            text=True, timeout=600, preexec_fn=limited(2000), env=env)
    assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
    errors = [line for line in result.stderr.splitlines() if "error" in line]
    assert errors == [f"instrument synth: error: the kernels' cache {cache}: cannot write: File too large"], result.stderr
    assert not (tmp_path / "walk.bvh").exists()
