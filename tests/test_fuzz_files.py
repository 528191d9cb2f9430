"""Property-based fuzzing of every file loader (Hypothesis): BVH, mappings, show files, presets
files, scores, controller logs with their header, Standard MIDI Files and CSV/TOML manifests.

Each test starts from real files (the shipped mappings, the demo score, a real motion capture
take, a log recorded with a shipped mapping, an SMF exported from it) and mutates them: lines
deleted, duplicated or swapped, numbers made huge, NaN, negative or strings, values nested
deeply, text made non-Latin-1, astral-plane or 140 kB long, bytes that are not UTF-8, files cut
short. The property is the project's rule for bad input: a loader either returns something valid
(every value inside what its target takes), or raises `UserError` whose text is one line
starting with the file's name; never any other exception. The example count is bounded and the
generation derandomized, so the suite is quick and a failure reproduces on any machine; each
input that once broke a loader is kept as an `@example`.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from conftest import REPO, walk_files
from instrument.cli import showplan
from instrument.cli.inspect_cmd import describe
from instrument.control.attract import load_attract
from instrument.control.checks import held_refusal, raw_problem, refusal, row_of, value_refusal
from instrument.control.events import ControlEvent, read_log
from instrument.control.loghead import header_line, logged_crowd, logged_mappings
from instrument.control.mapping import load_mapping
from instrument.control.presetfile import model_of, read_presets, read_presets_file
from instrument.control.score import load_score
from instrument.control.smf import export_smf, import_smf
from instrument.control.state import ControlState
from instrument.errors import UserError
from instrument.motion.bvh import read_bvh
from instrument.motion.upright import TO_Y_UP
from instrument.training.corpus import read_manifest

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]  # the shipped model's
STATES = 5
EXAMPLES = int(os.environ.get("INSTRUMENT_FUZZ_EXAMPLES", "300"))  # a deeper search: INSTRUMENT_FUZZ_EXAMPLES=5000
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
WORK = Path(tempfile.mkdtemp(prefix="fuzz-files-"))  # one folder, files overwritten example after example
DIGITS = sys.get_int_max_str_digits()

# --- the mutations -----------------------------------------------------------------------------

HUGE = "9" * (DIGITS + 700)  # an integer Python will not convert from text
LONG = "a" * 140_000  # past csv's 128 kB field limit
WORDS = ["Ωμέγα", "端口", "\U0001F600\U00010348", "Контроллер", "\u202e", "\x7f", "a\\\\b"]
NUMBERS = [HUGE, "-" + HUGE, "nan", "inf", "-inf", "-1", "-0.0", "0", "1e308", "-1e308", "1e-320", "17", "128", "16384",
           "0.5", "3", "1_000", "0x10", "1979-05-27", '"x"', "true", "[]", "{}", "[1, 2, 3]", "{ a = 1 }",
           "[" * 60 + "]" * 60, "[" * 3000 + "]" * 3000, "{ a = " * 2000 + "1" + " }" * 2000]
STRINGS = [f'"{w}"' for w in WORDS] + ['""', f'"{LONG}"', '"cc"', '"hid"', '"nrpn"', '"note"', '"style/elderly"',
                                       '"preset/calm"', '"store/calm"', '"reset"', '"cue"', '"phase/9"', '"X"', '"Hat/up"',
                                       '"ramp"', "5", "'lit\"eral'", '"""multi\nline"""']
LINES = ["presets = 5", "[presets]", "[presets.calm]", "[presets.bad name]", '"style/elderly" = 50', "speed = nan",
         "[[control]]", 'message = "cc"', 'target = "speed"', "[[cue]]", "cue = 5", "hold = 0", "at = -1",
         'repeat = "nowhere"', 'mark = "a"', "[attract]", "after = 0", "attract = 1", "[device]", "control = 5",
         "[feedback]", 'midi = "("', 'hid = "zzzz:0000"', f"x = {'[' * 3000}{']' * 3000}", f"big = {HUGE}",
         f'name = "{LONG}"', 'name = "\U0001F600端"', "[a.b.c.d.e.f]", "a.b.c = 1", "= 1", "[", "]]", '"unterminated',
         "\ufeffname = 1", "\x00", "osc = [5]", "fps = 1e308", "seconds = -1", f"seconds = {HUGE}", "replay = 5"]

structural = st.one_of(
    st.tuples(st.just("delete"), st.integers(0, 10_000)),
    st.tuples(st.just("duplicate"), st.integers(0, 10_000)),
    st.tuples(st.just("swap"), st.integers(0, 10_000), st.integers(0, 10_000)),
    st.tuples(st.just("number"), st.integers(0, 10_000), st.sampled_from(NUMBERS)),
    st.tuples(st.just("string"), st.integers(0, 10_000), st.sampled_from(STRINGS)),
    st.tuples(st.just("insert"), st.integers(0, 10_000), st.sampled_from(LINES)),
    st.tuples(st.just("text"), st.integers(0, 10_000), st.text(max_size=12)),
    st.tuples(st.just("cut"), st.integers(0, 10_000)),
)
# bytes that are mostly not UTF-8 end the reading at once: one operation in about twenty
not_utf8 = st.tuples(st.just("bytes"), st.integers(0, 10_000), st.binary(min_size=1, max_size=4))
op = st.integers(0, 19).flatmap(lambda k: not_utf8 if k == 0 else structural)
NUMBER = re.compile(r"(?<![\w.])-?[0-9][0-9_]*(\.[0-9]+)?([eE][-+]?[0-9]+)?")
STRING = re.compile(r'"[^"\\\n]*"')


def mutated(text: str, ops: list[tuple]) -> bytes:
    """`text` with the operations done in turn (an index picks a line, wrapping round)."""
    lines = text.split("\n")
    tail = b""
    for kind, at, *more in ops:
        k = at % max(len(lines), 1)
        if kind == "delete" and lines:
            del lines[k]
        elif kind == "duplicate" and lines:
            lines.insert(k, lines[k])
        elif kind == "swap" and lines:
            j = more[0] % len(lines)
            lines[k], lines[j] = lines[j], lines[k]
        elif kind in ("number", "string") and lines:
            pattern = NUMBER if kind == "number" else STRING
            lines[k] = pattern.sub(lambda _: more[0].replace("\\", "\\\\"), lines[k], count=1)
        elif kind == "insert":
            lines.insert(k, more[0])
        elif kind == "text" and lines:
            lines[k] = lines[k][: len(lines[k]) // 2] + more[0] + lines[k][len(lines[k]) // 2:]
        elif kind == "cut":
            joined = "\n".join(lines)
            lines = joined[: at % (len(joined) + 1)].split("\n")
        elif kind == "bytes":
            tail = more[0]
    data = "\n".join(lines).encode("utf-8", "surrogatepass")
    if tail:
        middle = len(data) // 2
        data = data[:middle] + tail + data[middle:]
    return data


def mutations(max_size: int = 4):
    return st.lists(op, min_size=1, max_size=max_size)


def state() -> ControlState:
    return ControlState(STYLES, STATES)


def one_line(error: UserError, path: Path | str, long_ok: str = "") -> None:
    """The project's one-line error: one line, the file named first, short enough to read (a
    value it quotes cut short: errors.quoted), unless its text has `long_ok` in it."""
    text = str(error)
    assert "\n" not in text and "\r" not in text, text[:300]
    assert text.startswith(str(path)), text[:300]
    assert len(text) < 1000 or (long_ok and long_ok in text), f"{len(text)} characters: {text[:300]}"


def written(name: str, data: bytes) -> Path:
    path = WORK / name
    path.write_bytes(data)
    return path


def valid_held(values: dict[str, float]) -> None:
    for target, value in values.items():
        assert held_refusal(target, value, STYLES, STATES) is None, (target, value)


# --- the shipped files and real data to start from --------------------------------------------

MAPPINGS = {p.name: p.read_text() for p in sorted((REPO / "mappings").glob("*.toml"))}
DEMO = (REPO / "examples" / "demo" / "demo.toml").read_text()
SCORE = """name = "every kind of cue"
loop = false

[presets.calm]
"style/elderly" = 0.5
speed = 0.8

[[cue]]
mark = "top"
ramp = { "style/elderly" = 1.0, "part/active/arms" = 0.5, "phase/2" = 0.5 }
over = 2
curve = "ease"

[[cue]]
after = 1
preset = "calm"
over = 1

[[cue]]
hold = 2

[[cue]]
wait = "cue"

[[cue]]
repeat = "top"
times = 2
"""
PRESETS = """# what the console saves
[presets.calm]
"style/elderly" = 0.5
speed = 0.8

[presets.proud]
"style/masculine" = 1.5
"part/active/arms" = 0.5
turn = -0.5
"""
SHOW = """# a show file (docs/installations.md)
seconds = 1
fps = 30
osc = ["127.0.0.1:39539/vmc", "127.0.0.1:9000/flat"]
osc-in = "9001"
status-port = "9100"
health-every = 60
characters = 2

[presets.calm]
"style/elderly" = 0.5
speed = 0.8

[presets.proud]
"style/masculine" = 1.5
"style/active" = 0.5

[attract]
after = 5
presets = ["calm", "proud"]
morph = 8
hold = 30
"""


def real_bvh() -> str:
    """A real take (bandai-walk) cut to 8 frames, or the shipped test walk's first frames."""
    files = walk_files()
    if not files:
        pytest.skip("real walks not found")
    lines = files[0].read_text().splitlines()
    motion = lines.index("MOTION")
    return "\n".join(lines[: motion + 1] + ["Frames:\t8"] + lines[motion + 2: motion + 11]) + "\n"


def midi_log() -> str:
    """A log as `run --record` writes it with the shipped nanoKONTROL2 mapping."""
    mapping = load_mapping(REPO / "mappings" / "korg-nanokontrol2.toml")
    events = [ControlEvent(k / 30, "midi:nanoKONTROL2 MIDI 1", f"cc/1/{k % 8}", float(k * 7 % 128)) for k in range(12)]
    events.append(ControlEvent(0.5, "midi:nanoKONTROL2 MIDI 1", "pitchbend/2/0", 16383.0))
    return "\n".join([header_line([mapping], characters=3, spacing=1.5)] + [e.to_json() for e in events]) + "\n"


def signed_log(mapping_text: str) -> str:
    """A log whose header carries `mapping_text` with its true sha256 (so the mapping inside is read, not refused as edited)."""
    entry = {"name": "fuzzed", "file": "fuzzed.toml", "sha256": hashlib.sha256(mapping_text.encode("utf-8", "surrogatepass")).hexdigest(),
             "toml": mapping_text}
    header = json.dumps({"instrument_log": 1, "mappings": [entry], "decoders": "per-device"}, ensure_ascii=False)
    return header + "\n" + midi_log().split("\n", 1)[1]


# --- the loaders -------------------------------------------------------------------------------

@FUZZ
@given(base=st.sampled_from(sorted(MAPPINGS)), ops=mutations())
@example(base="korg-nanokontrol2.toml", ops=[("insert", 0, f"x = {'[' * 3000}{']' * 3000}")])
@example(base="korg-nanokontrol2.toml", ops=[("insert", 0, f"big = {HUGE}")])
@example(base="korg-nanokontrol2.toml", ops=[("insert", 0, "presets = 5")])
@example(base="3dconnexion-spacemouse.toml", ops=[("string", 194, '"""multi\nline"""')])  # a newline in a target
@example(base="akai-midimix.toml", ops=[("string", 19, f'"{LONG}"')])  # a 140 kB message name
def test_a_mapping_is_valid_or_one_line(base, ops):
    path = written("mapping.toml", mutated(MAPPINGS[base], ops))
    for strict in (False, True):
        try:
            mapping = load_mapping(path, state(), strict_styles=strict)
        except UserError as error:
            one_line(error, path)
            continue
        valid_mapping(mapping, strict)


def valid_mapping(mapping, strict: bool) -> None:
    """Every control of an accepted mapping sends only values its target takes; its presets hold good values."""
    for control in mapping.controls:
        assert 1 <= control.channel <= 16 and 0 <= control.number <= 16383
        row = row_of(control.target, STYLES if strict else _AnyStyles(), STATES)
        assert row is not None, control.target
        assert all(value_refusal(row, control.target, end) is None for end in control.range), control
        assert math.isfinite(control.step) and 0 <= control.deadzone < 1
    for values in mapping.presets.values():
        for target, value in values.items():
            assert math.isfinite(value) and (not strict or held_refusal(target, value, STYLES, STATES) is None)
    assert 0 <= mapping.morph <= 600


class _AnyStyles:
    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name != ""


@FUZZ
@given(ops=mutations())
@example(ops=[("insert", 1, "presets = 5")])
@example(ops=[("number", 3, HUGE)])
@example(ops=[("number", 3, "[" * 3000 + "]" * 3000)])
def test_a_presets_file_is_valid_or_one_line(ops):
    path = written("presets.toml", mutated(PRESETS, ops))
    try:
        presets = read_presets_file(str(path), model_of(state()))
    except UserError as error:
        one_line(error, path)
        return
    for values in presets.values():
        valid_held(values)


@FUZZ
@given(base=st.sampled_from([DEMO, SCORE]), ops=mutations())
@example(base=SCORE, ops=[("number", 12, "1e308")])
@example(base=SCORE, ops=[("number", 12, HUGE)])
def test_a_score_is_valid_or_one_line(base, ops):
    path = written("score.toml", mutated(base, ops))
    try:
        score = load_score(path, state())
    except UserError as error:
        one_line(error, path)
        return
    assert score.cues
    for cue in score.cues:
        assert cue.at is None or (math.isfinite(cue.at) and cue.at >= 0)
        assert all(math.isfinite(x) and x >= 0 for x in (cue.after, cue.over, cue.hold))
        assert cue.repeat is None or 0 <= cue.repeat < len(score.cues)
        assert cue.times is None or cue.times >= 1
        for target, value in cue.ramp.items():
            assert refusal(target, value, STYLES, STATES) is None, (target, value)


@FUZZ
@given(ops=mutations())
@example(ops=[("insert", 9, "presets = 5")])
@example(ops=[("number", 2, HUGE)])
@example(ops=[("insert", 4, "attract = 1")])
def test_a_show_file_is_valid_or_one_line(ops):
    path = written("show.toml", mutated(SHOW, ops))
    args = _run_args(path)
    try:
        show = showplan.apply_show_file(args)
        presets = read_presets(show, model_of(state()))
        attract = load_attract(show, state(), presets)
    except UserError as error:
        one_line(error, path, long_ok=": osc: ")  # output/osc.py's parse_target quotes a target whole (not this area's)
        return
    for values in presets.values():
        valid_held(values)
    assert attract is None or (math.isfinite(attract.after) and attract.after > 0)


def _run_args(path: Path) -> argparse.Namespace:
    """`instrument run --config PATH` as parsed, no other option given."""
    from instrument.cli.main import build_parser

    return build_parser("run").parse_args(["run", "--config", str(path)])


@FUZZ
@given(ops=mutations())
@example(ops=[("number", 1, HUGE)])
@example(ops=[("number", 3, "1e308")])
@example(ops=[("number", 2, "17")])
def test_a_log_is_valid_or_one_line(ops):
    path = written("log.jsonl", mutated(midi_log(), ops))
    check_log(path)


@FUZZ
@given(base=st.sampled_from(sorted(MAPPINGS)), ops=mutations())
@example(base="korg-nanokontrol2.toml", ops=[("insert", 0, f"x = {'[' * 3000}{']' * 3000}")])
def test_a_log_whose_header_carries_a_broken_mapping_is_valid_or_one_line(base, ops):
    text = mutated(MAPPINGS[base], ops).decode("utf-8", "replace")
    path = written("signed.jsonl", signed_log(text).encode("utf-8"))
    check_log(path)


def check_log(path: Path) -> None:
    """A log read as `run --replay` reads it: events, the mappings of its header, its crowd;
    then exported to an SMF that reads back."""
    try:
        events = read_log(path, warn=lambda _: None)
        mappings = logged_mappings(path, state())
        crowd, _ = logged_crowd(path)
    except UserError as error:
        one_line(error, path)
        return
    assert all(math.isfinite(e.time) and e.time >= 0 and math.isfinite(e.value) for e in events)
    for mapping in mappings:
        valid_mapping(mapping, strict=False)
    assert isinstance(crowd, dict)
    # what `log export` writes from it is a MIDI file that reads back, or a one-line refusal
    out = WORK / "log.mid"
    try:
        count = export_smf(events, out, path)
    except UserError as error:
        one_line(error, path)
        return
    assert count == len(events) == len(import_smf(out))


@FUZZ
@given(ops=st.lists(st.tuples(st.integers(0, 10_000), st.binary(max_size=6), st.integers(0, 6)), min_size=1, max_size=4))
@example(ops=[(12, b"\x00\x00", 2)])  # 0 ticks per beat
@example(ops=[(12, b"\xe7\x28", 2)])  # SMPTE time (25 fps, 40 ticks a frame)
@example(ops=[(4675, b"", 4)])  # (mido: IndexError)
def test_a_midi_file_is_valid_or_one_line(ops):
    """An exported SMF with bytes replaced, inserted or cut: read, or refused in one line."""
    base = WORK / "base.mid"
    events = [ControlEvent(k / 30, "midi:Контроллер", f"cc/{1 + k % 16}/{k % 128}", float(k % 128)) for k in range(20)]
    export_smf(events, base)
    data = bytearray(base.read_bytes())
    for at, payload, drop in ops:
        k = at % (len(data) + 1)
        data[k: k + drop] = payload
    path = written("fuzzed.mid", bytes(data))
    try:
        imported = import_smf(path)
    except UserError as error:
        one_line(error, path)
        return
    for event in imported:
        assert math.isfinite(event.time) and event.time >= 0
        assert raw_problem(event.source, event.control, event.value) is None, event


@FUZZ
@given(ops=mutations())
@example(ops=[("number", 140, "nan")])
@example(ops=[("number", 140, HUGE)])
def test_a_bvh_file_is_valid_or_one_line(ops):
    path = written("take.bvh", mutated(real_bvh(), ops))
    try:
        motion = read_bvh(path)
    except UserError as error:
        one_line(error, path)
        return
    assert motion.channels.ndim == 2 and len(motion.channels) > 0
    assert motion.channels.shape[1] == sum(len(j.channels) for j in motion.skeleton.joints)
    assert bool((abs(motion.channels) < math.inf).all()) and 0 < motion.fps <= 1000
    try:  # what `inspect` and training do next with a file that reads: turn it Y up, find its feet and steps
        info = describe(path)
    except UserError as error:
        one_line(error, path)
        return
    assert info["up"] in TO_Y_UP and info["frames"] == motion.frames


@FUZZ
@given(kind=st.sampled_from(["csv", "toml"]), ops=mutations())
@example(kind="csv", ops=[("string", 1, f'"{LONG}"')])
@example(kind="toml", ops=[("string", 2, '""')])  # an empty style was taken (CI's Hypothesis found it)
@example(kind="toml", ops=[("string", 1, '""')])
def test_a_manifest_is_valid_or_one_line(kind, ops):
    base = ('file,style\n"a.bvh",elderly\nb.bvh,youthful\n' if kind == "csv" else
            '[[take]]\nfile = "a.bvh"\nstyle = "elderly"\n\n[[take]]\nfile = "b.bvh"\nstyle = "youthful"\n')
    path = written(f"manifest.{kind}", mutated(base, ops))
    for take in ("a.bvh", "b.bvh"):  # the takes it names are there: a renamed one is not
        (WORK / take).touch()
    try:
        pairs = read_manifest(path)
    except UserError as error:
        one_line(error, path)
        return
    assert all(isinstance(t.path, Path) and isinstance(t.style, str) and t.style and t.unit for t in pairs)
    assert all(t.path.is_file() for t in pairs)  # a file not there was refused at its line


# --- the commands, as a user runs them ---------------------------------------------------------

CLI = settings(max_examples=max(EXAMPLES // 50, 4), deadline=None, derandomize=True, database=None,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
CLI_SHOW = "seconds = 1\nfps = 30\nbvh = \"cli-show.bvh\"\n\n[presets.calm]\n\"style/elderly\" = 0.5\nspeed = 0.8\n"


def command(*words: str) -> subprocess.CompletedProcess:
    """`instrument WORDS` as a user runs it (this checkout's code: PYTHONPATH)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "instrument", *words], capture_output=True, text=True, env=env,
                          timeout=600, cwd=WORK)


def done_or_one_line(result: subprocess.CompletedProcess, path: Path) -> bool:
    """Exit 0, or exit 1 with one stderr line naming the file; never a traceback. Whether it was done."""
    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    if result.returncode == 0:
        return True
    assert result.returncode == 1, (result.returncode, result.stderr[-2000:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path.name) in lines[0], result.stderr[-2000:]
    return False


@CLI
@given(ops=mutations())
@example(ops=[("insert", 1, "presets = 5")])
@example(ops=[("insert", 1, f"x = {'[' * 3000}{']' * 3000}")])
@example(ops=[("number", 0, HUGE)])
def test_run_with_a_show_file_plays_or_refuses_in_one_line(ops):
    path = written("cli-show.toml", mutated(CLI_SHOW, ops))
    recording = WORK / "cli-show.bvh"
    recording.unlink(missing_ok=True)
    done = done_or_one_line(command("run", "--config", str(path), "--fast", "--seconds", "0.2", "--no-osc"), path)
    if recording.exists():  # what was written is whole: a BVH whose header counts its frames
        assert done, "a refused show left a recording"
        assert len(read_bvh(recording).channels) > 0


@CLI
@given(ops=mutations())
@example(ops=[("string", 1, '"midi:Контроллер 端口 \U0001F600"')])  # not Latin-1: the SMF's track name is UTF-8
@example(ops=[("string", 2, '"cc/17/1"')])  # channel 17
@example(ops=[("number", 2, "1e308")])  # t = 1e308
@example(ops=[("number", 2, HUGE)])  # over 4300 digits
def test_log_export_writes_a_midi_file_that_reads_back_or_refuses_in_one_line(ops):
    path = written("cli-log.jsonl", mutated(midi_log(), ops))
    out = WORK / "cli-log.mid"
    out.unlink(missing_ok=True)
    if done_or_one_line(command("log", "export", str(path), "--out", str(out)), path):
        exported = read_log(path)
        back = import_smf(out)
        assert len(back) == len(exported)
        assert sorted({e.source for e in back}) == sorted({e.source for e in exported})  # names as written
    else:
        assert not out.exists(), "a refused export left a file"


@CLI
@given(ops=mutations())
@example(ops=[("number", 2, "1e308")])  # t = 1e308: refused, not an endless --fast replay
@example(ops=[("string", 2, '"cc/17/1"')])  # channel 17: warned about, the show goes on
def test_run_replaying_a_log_plays_or_refuses_in_one_line(ops):
    path = written("cli-replay.jsonl", mutated(midi_log(), ops))
    done_or_one_line(command("run", "--replay", str(path), "--fast", "--no-osc"), path)


@CLI
@given(ops=st.lists(st.tuples(st.integers(0, 10_000), st.binary(max_size=6), st.integers(0, 6)), min_size=1, max_size=4))
@example(ops=[(12, b"\x00\x00", 2)])  # 0 ticks per beat
@example(ops=[(12, b"\xe7\x28", 2)])  # SMPTE time (25 fps, 40 ticks a frame)
def test_log_import_writes_a_log_that_reads_back_or_refuses_in_one_line(ops):
    base = WORK / "cli-base.mid"
    export_smf([ControlEvent(k / 30, "midi:Контроллер", f"cc/1/{k}", float(k)) for k in range(8)], base)
    data = bytearray(base.read_bytes())
    for at, payload, drop in ops:
        k = at % (len(data) + 1)
        data[k: k + drop] = payload
    path = written("cli-fuzzed.mid", bytes(data))
    out = WORK / "cli-imported.jsonl"
    out.unlink(missing_ok=True)
    if done_or_one_line(command("log", "import", str(path), "--out", str(out)), path):
        assert all(raw_problem(e.source, e.control, e.value) is None for e in read_log(out))
    else:
        assert not out.exists(), "a refused import left a file"


# --- the cases of issue 24 (item 11), each once by name ----------------------------------------

def refused(call, pattern: str) -> None:
    with pytest.raises(UserError) as caught:
        call()
    assert "\n" not in str(caught.value) and re.fullmatch(pattern, str(caught.value)), str(caught.value)[:300]


@pytest.mark.parametrize("value", ["[" * 3000 + "]" * 3000, "{ a = " * 3000 + "1" + " }" * 3000])
def test_deeply_nested_toml_is_one_line(value):
    path = written("deep.toml", f'name = "deep"\nx = {value}\n'.encode())
    refused(lambda: load_mapping(path), re.escape(f"{path}: arrays or tables nested too deeply"))


def test_a_toml_integer_of_over_4300_digits_is_one_line_naming_its_line():
    path = written("huge.toml", f'[presets.calm]\nspeed = 1\nturn = {HUGE}\n'.encode())
    refused(lambda: read_presets_file(str(path), model_of(state())), re.escape(f"{path}:3: a number of more than {DIGITS} digits"))


@pytest.mark.parametrize("text", ["[presets]\ncalm = 5\n", "presets = 5\n"])
def test_presets_that_are_not_tables_are_one_line(text):
    path = written("presets5.toml", text.encode())
    refused(lambda: read_presets_file(str(path), model_of(state())), re.escape(str(path)) + r":\d: .*")


@pytest.mark.parametrize("field,value", [("value", HUGE), ("t", HUGE), ("t", "1e308")])
def test_a_log_line_of_a_huge_number_is_one_line_naming_it(field, value):
    event = {"t": "0.5", "source": '"midi:x"', "control": '"cc/1/1"', "value": "3"}
    event[field] = value
    line = "{" + ", ".join(f'"{k}": {v}' for k, v in event.items()) + "}"
    path = written("huge.jsonl", ('{"t": 0, "source": "midi:x", "control": "cc/1/1", "value": 1}\n' + line + "\n").encode())
    refused(lambda: read_log(path), re.escape(f"{path}:2: ") + ("not JSON: a number of more than .*" if value == HUGE else ".*'t'.*"))


def test_a_log_header_of_a_huge_number_is_one_line():
    path = written("huge-header.jsonl", ('{"instrument_log": ' + HUGE + ', "mappings": []}\n').encode())
    refused(lambda: read_log(path), re.escape(f"{path}:1: not JSON: ") + ".*")
    assert logged_mappings(path) == []  # (not a header: read_log names the line)


@pytest.mark.parametrize("control,value,problem", [("cc/17/1", 1, "not a MIDI control id"), ("cc/1/200", 1, "not a MIDI control id"),
                                                   ("cc/1/1", 300, "MIDI value out of range"), ("zz", 1, "not a MIDI control id")])
def test_log_export_refuses_what_a_midi_file_cannot_hold(control, value, problem):
    out = WORK / "refused.mid"
    out.unlink(missing_ok=True)
    refused(lambda: export_smf([ControlEvent(0.0, "midi:x", control, float(value))], out, "my.jsonl"),
            re.escape(f"my.jsonl: event {control!r} of 'midi:x' at t = 0 s: {problem}"))
    assert not out.exists()


def test_log_export_keeps_a_non_latin_1_device_name():
    out = WORK / "names.mid"
    names = ["midi:Контроллер", "midi:端口 \U0001F600", "midi:Café"]
    export_smf([ControlEvent(k / 10, name, "cc/1/1", 64.0) for k, name in enumerate(names)], out)
    assert sorted(e.source for e in import_smf(out)) == sorted(names)


def test_a_csv_manifest_field_of_140_kb_is_one_line():
    path = written("long.csv", f"file,style\n{LONG}.bvh,elderly\n".encode())
    refused(lambda: read_manifest(path), re.escape(f"{path}:2: not a CSV manifest: field larger than field limit ") + r".*")
