import json
import subprocess
import sys
from pathlib import Path

from samples import cmu_style_walk


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True, timeout=120)


def test_help_lists_the_subcommands():
    result = run("--help")
    assert result.returncode == 0
    assert "inspect" in result.stdout


def test_inspect_json_on_a_folder(tmp_path):
    text, _ = cmu_style_walk(fps=120)
    (tmp_path / "walk.bvh").write_text(text)
    (tmp_path / "notes.txt").write_text("not motion")
    result = run("inspect", "--json", str(tmp_path))
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert len(document) == 1
    info = document[0]
    assert {"file", "frames", "fps", "joints", "steps"} <= set(info)
    assert info["frames"] == 528 and info["fps"] == 120.0
    assert len(info["joints"]) == 31
    assert {s["label"] for s in info["steps"]} == {"left", "right"}
    assert all(60 <= s["frames"] <= 72 for s in info["steps"])


def test_inspect_text_names_steps_and_warnings(tmp_path):
    text, _ = cmu_style_walk(fps=30)
    path = tmp_path / "walk.bvh"
    path.write_text(text)
    result = run("inspect", str(path))
    assert result.returncode == 0
    assert "joints   31" in result.stdout
    assert "steps    " in result.stdout and "LeftToeBase / RightToeBase" in result.stdout


def test_inspect_keeps_going_past_a_bad_file_and_exits_1(tmp_path):
    text, _ = cmu_style_walk(fps=30)
    (tmp_path / "a_good.bvh").write_text(text)
    (tmp_path / "b_bad.bvh").write_text(text.replace("MOTION", "MOTON"))
    result = run("inspect", "--json", str(tmp_path))
    assert result.returncode == 1
    document = json.loads(result.stdout)
    assert "steps" in document[0] and "error" in document[1]
    assert "b_bad.bvh:" in result.stderr and "Traceback" not in result.stderr


def test_missing_path_and_empty_folder_are_one_line_errors(tmp_path):
    for args in (["inspect", str(tmp_path / "nope.bvh")], ["inspect", str(tmp_path)]):
        result = run(*args)
        assert result.returncode == 1
        assert len(result.stderr.strip().splitlines()) == 1
        assert str(tmp_path) in result.stderr


def test_version_and_help_load_no_subcommand():
    """Start-up stays fast: `--version` and `--help` import none of numpy, scipy, numba (timed in `instrument bench --startup`)."""
    probe = ("import sys\nfrom instrument.cli.main import main\n"
             "try:\n    main([sys.argv[1]])\nexcept SystemExit:\n    pass\n"
             "print(sorted(m for m in ('numpy', 'scipy', 'numba', 'mido') if m in sys.modules))")
    for flag in ("--version", "--help"):
        result = subprocess.run([sys.executable, "-c", probe, flag], capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
        assert result.stdout.strip().splitlines()[-1] == "[]"


HEAVY_PROBE = ("import sys\nfrom instrument.cli.main import main\n"
               "try:\n    code = main(sys.argv[1:])\nexcept SystemExit as e:\n    code = e.code\n"
               "print(code, sorted(m for m in ('scipy', 'numba', 'matplotlib') if m in sys.modules))")


def heavy_modules_loaded(*args: str) -> str:
    """Run `instrument ARGS` in a fresh Python; the exit status and which of scipy, numba and
    matplotlib it loaded (what makes a command slow to start)."""
    result = subprocess.run([sys.executable, "-c", HEAVY_PROBE, *args], capture_output=True, text=True, timeout=120)
    assert "Traceback" not in result.stderr, result.stderr
    return result.stdout.strip().splitlines()[-1]


def test_every_command_help_loads_no_scipy_numba_or_matplotlib():
    """Each command loads its heavy code when it runs, not to parse its options (timed in `instrument bench --startup`)."""
    from instrument.cli.main import COMMANDS

    assert {c: heavy_modules_loaded(c, "--help") for c in COMMANDS} == {c: "0 []" for c in COMMANDS}


def test_recover_and_log_run_without_scipy_or_numba(tmp_path):
    walk = tmp_path / "walk.bvh"
    walk.write_text(cmu_style_walk(fps=30)[0])
    log = tmp_path / "take.jsonl"
    log.write_text('{"t": 0.5, "source": "midi:x", "control": "cc/1/7", "value": 64}\n')
    assert heavy_modules_loaded("recover", str(walk)) == "0 []"
    assert heavy_modules_loaded("log", "export", str(log), "--out", str(tmp_path / "take.mid")) == "0 []"
    assert heavy_modules_loaded("log", "import", str(tmp_path / "take.mid"), "--out", str(tmp_path / "back.jsonl")) == "0 []"
    assert (tmp_path / "back.jsonl").read_text().count("cc/1/7") == 1


def test_the_help_summary_of_each_command_is_its_own():
    from instrument.cli.main import COMMANDS, EVERY, build_parser

    every = build_parser(EVERY)
    sub = next(a for a in every._actions if a.dest == "command")
    assert {a.dest: a.help for a in sub._choices_actions} == {name: summary for name, (_, summary) in COMMANDS.items()}


def test_bench_startup_times_every_command_against_bare_python():
    from instrument.cli.main import COMMANDS

    result = run("bench", "--startup", "--repeat", "1", "--json")
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    assert set(figures) == {"instrument --version", "instrument --help"} | {f"instrument {c} --help" for c in COMMANDS}
    assert all(f["seconds"] > 0 and f["bare_seconds"] > 0 and f["ratio"] == f["seconds"] / f["bare_seconds"] for f in figures.values())


def test_a_crash_in_a_c_library_names_the_python_line_it_came_from(tmp_path):
    """A segfault inside libjack or hidapi during a show should say where, not only "Segmentation
    fault": every command turns on faulthandler (stderr), as the run command's crash in CI showed.
    Here a command whose code crashes in C (ctypes reading address 0) stands in for the library."""
    crash = ("import ctypes, sys\n"
             "from instrument.cli import main as entry\n"
             "def crashing_command(args):\n"
             "    return ctypes.string_at(0)\n"
             "class Parsed: command = 'run'; run = staticmethod(crashing_command)\n"
             "entry.build_parser = lambda load: type('P', (), {'parse_args': lambda self, argv: Parsed()})()\n"
             "sys.exit(entry.main(['run']))\n")
    result = subprocess.run([sys.executable, "-c", crash], capture_output=True, text=True, timeout=120)
    assert result.returncode == -11  # SIGSEGV, as before: only the report is new
    assert "Fatal Python error: Segmentation fault" in result.stderr
    assert "crashing_command" in result.stderr  # the Python function the crash happened in


def test_a_process_left_holding_a_dead_jack_client_ends_without_the_teardown():
    """After a JACK restart the dead server's clients are left to libjack (jackwatch.abandon); the
    process then ends as soon as its command is done, its output flushed, without the interpreter's
    teardown (where a show that survived a restart once crashed on exit). Not so otherwise."""
    script = ("import atexit, sys\n"
              "from instrument.control import jackwatch\n"
              "if sys.argv[1] == 'abandoned':\n"
              "    jackwatch.ABANDONED.set()\n"
              "atexit.register(lambda: print('teardown'))\n"
              "sys.argv = ['instrument', 'info']\n"
              "from instrument.cli.main import main\n"
              "code = main()\n"
              "print('returned', code)\n")
    for case in ("abandoned", "steady"):
        result = subprocess.run([sys.executable, "-c", script, case], capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
        assert "states" in result.stdout  # the command's output, flushed either way
        ended_at_once = "returned" not in result.stdout and "teardown" not in result.stdout
        assert ended_at_once == (case == "abandoned"), (case, result.stdout[-200:])


def test_past_a_jack_restart_or_at_the_process_end_no_port_is_taken_apart():
    """A show that survived a JACK restart crashed (CI, once) closing its MIDI input as it ended:
    libjack still held the dead server's client; and `run` segfaulted in rtmidi's close_port on its
    JACK virtual input at a clean end, the server alive (about once in four full test runs). Once a
    port was left to a dead server, any port's close leaves it (kept alive for the process's end);
    when the process ends with its command, an input's; an output is closed then (its close sends
    what it queued: a last note-off), as is every port of a process that goes on (a test's own)."""
    script = ("import sys\n"
              "from instrument.control import jackwatch\n"
              "class Port:\n"
              "    pass\n"
              "closed, port = [], Port()\n"
              "if sys.argv[1] == 'abandoned':\n"
              "    jackwatch.ABANDONED.set()\n"
              "if sys.argv[1] == 'ending':\n"
              "    jackwatch.ENDS_WITH_PROCESS.set()\n"
              "before = sys.getrefcount(port)\n"
              "jackwatch.release(port, lambda: closed.append(1), leave_at_end=sys.argv[2] == 'input')\n"
              "print('closed' if closed else 'left', sys.getrefcount(port) - before)\n")
    for case, port, said in (("abandoned", "input", "left 1"), ("abandoned", "output", "left 1"),
                             ("ending", "input", "left 1"), ("ending", "output", "closed 0"),
                             ("steady", "input", "closed 0"), ("steady", "output", "closed 0")):
        result = subprocess.run([sys.executable, "-c", script, case, port], capture_output=True, text=True, timeout=120)
        assert result.returncode == 0 and result.stdout.split() == said.split(), (case, port, result.stdout, result.stderr)


def test_only_the_process_own_command_leaves_its_ports_to_the_process_end():
    """`main()` (the console script: the process ends with the command) leaves ports to the end;
    `main(argv)` (a caller that goes on, as a test) closes them."""
    script = ("import sys\n"
              "from instrument.control import jackwatch\n"
              "from instrument.cli.main import main\n"
              "if sys.argv[1] == 'own':\n"
              "    sys.argv = ['instrument', 'info']\n"
              "    main()\n"
              "else:\n"
              "    main(['info'])\n"
              "print('leaves' if jackwatch.ENDS_WITH_PROCESS.is_set() else 'closes')\n")
    for case, said in (("own", "leaves"), ("called", "closes")):
        result = subprocess.run([sys.executable, "-c", script, case], capture_output=True, text=True, timeout=120)
        assert result.returncode == 0 and result.stdout.split()[-1] == said, (case, result.stdout[-300:], result.stderr)


def test_a_bug_after_a_jack_restart_prints_its_traceback_and_ends_at_once():
    script = ("import atexit, sys\n"
              "from instrument.control import jackwatch\n"
              "from instrument.cli import main as entry\n"
              "jackwatch.ABANDONED.set()\n"
              "atexit.register(lambda: print('teardown'))\n"
              "def buggy_command(args):\n"
              "    raise RuntimeError('a bug')\n"
              "class Parsed: command = 'run'; run = staticmethod(buggy_command)\n"
              "entry.build_parser = lambda load: type('P', (), {'parse_args': lambda self, argv: Parsed()})()\n"
              "sys.argv = ['instrument', 'run']\n"
              "entry.main()\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert "RuntimeError: a bug" in result.stderr and "buggy_command" in result.stderr
    assert "teardown" not in result.stdout


def test_inspect_says_each_takes_unit_and_style_and_cuts_a_stand_as_training_does(tmp_path):
    """The README's `inspect` "says what it found (steps, units, problems)": it said no unit, and
    called every standing take "not a walk" (its feet never pass) though training reads it as a
    stand, cut into pieces of still standing."""
    from conftest import REPO
    motions = REPO.parent / "shared" / "data" / "bandai-motions"
    if not motions.is_dir():
        import pytest
        pytest.skip(f"standing takes not found in {motions}")
    stand = tmp_path / "me_idle_proud_001.bvh"  # a standing take under a name of the user's
    stand.write_text((motions / "dataset-2_wave-both-hands_active_001.bvh").read_text())
    text, _ = cmu_style_walk(fps=30)
    (tmp_path / "walk7.bvh").write_text(text)  # no style in the name: said so, not an error
    result = run("inspect", "--json", str(tmp_path))
    assert result.returncode == 0, result.stderr
    found = {Path(info["file"]).name: info for info in json.loads(result.stdout)}
    assert found["me_idle_proud_001.bvh"]["unit"] == "stand" and found["me_idle_proud_001.bvh"]["style"] == "proud"
    assert found["me_idle_proud_001.bvh"]["steps"] and not found["me_idle_proud_001.bvh"]["warnings"]
    assert found["walk7.bvh"]["unit"] == "walk" and found["walk7.bvh"]["style"] is None
    text = run("inspect", str(tmp_path)).stdout
    assert "unit     stand, style proud" in text and "not a walk" not in text and "style (none in the name" in text


def _a_wave_and_a_walk(folder: Path, wave: str, walk: str) -> None:
    """A real standing take that waves, and a CMU-style walk, into `folder` under the names given
    (skipped where the shared standing takes are not beside the repository)."""
    from conftest import REPO
    motions = REPO.parent / "shared" / "data" / "bandai-motions"
    if not motions.is_dir():
        import pytest
        pytest.skip(f"standing takes not found in {motions}")
    (folder / wave).write_text((motions / "dataset-2_wave-both-hands_active_001.bvh").read_text())
    text, _ = cmu_style_walk(fps=30)
    (folder / walk).write_text(text)


def test_inspect_reads_a_manifest_as_train_does(tmp_path):
    """`inspect --manifest` says each take's style, unit and gesture as the manifest gives them
    (train's reading), where the takes' names say nothing; a bad row is one line at its line."""
    _a_wave_and_a_walk(tmp_path, "take1.bvh", "take2.bvh")
    (tmp_path / "m.csv").write_text("file,style,unit,gesture\ntake1.bvh,proud,stand,wave\ntake2.bvh,calm,,\n")
    result = run("inspect", "--json", "--manifest", str(tmp_path / "m.csv"))
    assert result.returncode == 0, result.stderr
    found = {Path(info["file"]).name: info for info in json.loads(result.stdout)}
    assert (found["take1.bvh"]["unit"], found["take1.bvh"]["style"], found["take1.bvh"]["gesture"]) == ("stand", "proud", "wave")
    assert (found["take2.bvh"]["unit"], found["take2.bvh"]["style"], found["take2.bvh"]["gesture"]) == ("walk", "calm", None)
    assert "unit     stand (wave), style proud (as the manifest gives them)" in run("inspect", "--manifest", str(tmp_path / "m.csv")).stdout
    (tmp_path / "bad.csv").write_text("file,style,unit,gesture\ntake2.bvh,calm,walk,wave\n")
    result = run("inspect", "--manifest", str(tmp_path / "bad.csv"))
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines() == [f"instrument inspect: error: {tmp_path / 'bad.csv'}:2: gesture 'wave' given to a walk take: "
                                                  "a gesture is a standing take's (unit stand)"]


def test_train_refuses_a_manifest_unit_not_in_the_table_of_units(tmp_path):
    """A tester's `runn` trained a run (the manifest's unit read by its words, as a file name's):
    train now stops at the manifest's line, in one line naming the units, before reading any take."""
    _a_wave_and_a_walk(tmp_path, "take1.bvh", "take2.bvh")
    (tmp_path / "m.csv").write_text("file,style,unit\ntake2.bvh,calm,walk\ntake1.bvh,calm,runn\n")
    result = run("train", "--manifest", str(tmp_path / "m.csv"), "--out", str(tmp_path / "m.npz"))
    assert result.returncode != 0 and not (tmp_path / "m.npz").exists()
    assert result.stderr.strip().splitlines() == [f"instrument train: error: {tmp_path / 'm.csv'}:3: unit 'runn' is not one of "
                                                  "walk, run, turn-left, turn-right, stand"]


def test_inspect_reads_names_with_trains_style_from_and_unit_from(tmp_path):
    """A studio's own names (`actorB_Proud_IdleWave01.bvh`) are trained with `--style-from` and
    `--unit-from`, which inspect did not take: it showed every take as a walk of no style, and
    each standing take as "not a walk", though train read them as stands and their gestures."""
    _a_wave_and_a_walk(tmp_path, "actorB_Proud_IdleWave01.bvh", "actorB_Calm_Walk01.bvh")
    names = ["--style-from", "actorB_([A-Za-z]+)_", "--unit-from", "_([A-Za-z]+?)[0-9]+$"]
    result = run("inspect", "--json", str(tmp_path), *names)
    assert result.returncode == 0, result.stderr
    found = {Path(info["file"]).stem: (info["unit"], info["style"], info["gesture"]) for info in json.loads(result.stdout)}
    assert found == {"actorB_Proud_IdleWave01": ("stand", "proud", "wave"), "actorB_Calm_Walk01": ("walk", "calm", None)}
    assert "unit     stand (wave), style proud (read from the name, as train does)" in run("inspect", str(tmp_path), *names).stdout
    for option, pattern, said in (("--unit-from", "_(x", "--unit-from: not a regular expression"),
                                  ("--style-from", "actorB_[A-Za-z]+_", "--style-from: the expression needs exactly one group, it has 0")):
        result = run("inspect", str(tmp_path), option, pattern)
        assert result.returncode != 0 and result.stderr.strip().splitlines()[-1].startswith(f"instrument inspect: error: {said}"), result.stderr


def test_train_and_inspect_warn_of_a_unit_named_where_the_default_does_not_read(tmp_path):
    """Names with the unit after the style (`actorB_Calm_Jog01.bvh`) are read as walks without
    --unit-from: both commands say so, naming the file and the part, and train still trains."""
    text, _ = cmu_style_walk(fps=30)
    for name in ("actorB_Calm_Jog01", "actorB_Calm_Walk01"):
        (tmp_path / f"{name}.bvh").write_text(text)
    said = ("read as a walk, but its name's 'Jog01' says run (the unit is read from the part before the style: "
            "give --unit-from REGEX or a manifest)")
    inspected = run("inspect", str(tmp_path))
    assert inspected.returncode == 0 and inspected.stdout.count("warning: read as a walk") == 1
    assert f"  warning: {said}" in inspected.stdout
    trained = run("train", str(tmp_path), "--out", str(tmp_path / "m.npz"), "--quiet")
    assert trained.returncode == 0, trained.stderr
    assert [line for line in trained.stderr.splitlines() if "read as a walk" in line] == [
        f"warning: {tmp_path / 'actorB_Calm_Jog01.bvh'}: {said}"]
    quiet = run("inspect", str(tmp_path), "--unit-from", "_([A-Za-z]+?)[0-9]+$")
    assert "read as a walk" not in quiet.stdout and "unit     run" in quiet.stdout


def test_train_says_when_the_takes_rate_is_not_the_models(real_walks, tmp_path):
    """60 fps takes gave a 30 fps model without a word unless `--fps 60` was given: train says
    so in one line, naming the takes' rate, the model's and how to keep theirs (said even with
    --quiet); given --fps, the rate is the one asked for and nothing is said. Real walks
    resampled to 60 fps as the team resamples a rig's takes (examples/other_rigs.py)."""
    from instrument.cli.train_cmd import other_rates
    from instrument.models.modelfile import load_model
    from instrument.motion.bvh import read_bvh, write_bvh
    from instrument.motion.features import resample

    for path in [p for p in real_walks if "_active_" in p.name][:2]:
        write_bvh(tmp_path / path.name, resample(read_bvh(path), 60.0))
    said = ("warning: the takes are at 60 fps, resampled to the model's 30 fps (--fps's default): "
            "give --fps 60 to keep their rate")
    for given, fps, lines in (((), 30.0, [said]), (("--fps", "60"), 60.0, [])):
        model = tmp_path / f"model-{fps:g}.npz"
        trained = run("train", str(tmp_path), "--out", str(model), "--quiet", *given)
        assert trained.returncode == 0, trained.stderr
        assert [line for line in trained.stderr.splitlines() if " fps" in line] == lines, trained.stderr
        assert load_model(model).fps == fps
    assert other_rates([30.0, 60.0, 120.0, 30.0], 30.0) == (
        "2 of the 4 takes are at 60 and 120 fps, resampled to the model's 30 fps (--fps's default): "
        "give --fps 120 to keep the highest rate")
    assert other_rates([30.0, 30.0], 30.0) is None
