"""The first run after installing: numba's compiled kernels go to the user's cache folder (never
beside the installed package, where a regular install's cache used to hide an editable install
made after it), and the command says it is compiling instead of going silent for half a minute.

(The two install orders of the README, `pip install '.[view]'` then `pip install -e '.[test]'`
and the reverse, were run by hand in a throwaway virtual environment; docs/cli.md says so.)"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from conftest import REPO
from samples import cmu_style_walk
from waiting import StderrLines

COMPILING = "compiling the walk's kernels for this machine"


def clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "CACHE_DIRECTORY", "XDG_CACHE_HOME")}
    return env | extra


def kernels_in(folder) -> list:
    return sorted(folder.rglob("*.nbi"))


def test_a_first_run_says_it_is_compiling_into_the_users_cache_and_a_second_says_nothing(tmp_path):
    walk = tmp_path / "walk.bvh"
    walk.write_text(cmu_style_walk(fps=30)[0])
    cache = tmp_path / "cache home"
    env = clean_env(XDG_CACHE_HOME=str(cache))
    started = time.time()
    first = subprocess.run([sys.executable, "-m", "instrument", "inspect", str(walk)], capture_output=True, text=True,
                           timeout=600, env=env)
    assert first.returncode == 0, first.stderr
    assert first.stderr.startswith(COMPILING) and str(cache / "instrument" / "numba") in first.stderr.splitlines()[0]
    assert kernels_in(cache / "instrument" / "numba")  # compiled and kept there ...
    package = REPO / "instrument"
    assert not [p for p in kernels_in(package) if p.stat().st_mtime >= started - 1]  # ... and nothing beside the code
    second = subprocess.run([sys.executable, "-m", "instrument", "inspect", str(walk)], capture_output=True, text=True,
                            timeout=600, env=env)
    assert second.returncode == 0 and COMPILING not in second.stderr, second.stderr


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_a_first_run_compiles_ends_it_at_once_with_one_line(tmp_path, signum):
    """Ctrl-C while a first `run` compiled (half a minute) waited for the compile to end: it ran
    in the first frame, with the devices open, where a signal only asks the loop to stop. The
    kernels are compiled before anything opens, where a signal ends the process at once: one
    line, 130 (143 for SIGTERM), nothing written, and the start-up never goes on to open the
    outputs (on main the compile ended, the show said its start-up line and exited 0)."""
    bvh, log, cache = tmp_path / "take.bvh", tmp_path / "take.jsonl", tmp_path / "cache"
    process = subprocess.Popen([sys.executable, "-m", "instrument", "run", "--no-osc", "--seconds", "5", "--bvh", str(bvh),
                                "--record", str(log)], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                               env=clean_env(NUMBA_CACHE_DIR=str(cache)))
    stderr = StderrLines(process)
    try:
        stderr.wait_for(COMPILING)
        process.send_signal(signum)
        process.wait(600)
    finally:
        if process.poll() is None:
            process.kill()
    lines = stderr.text().splitlines()
    assert process.returncode == 128 + signum, lines
    assert len(lines) == 2 and lines[0].startswith(COMPILING), lines
    assert lines[1] == f"instrument run: stopped by {signal.Signals(signum).name} before anything was opened"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache"]  # no recording, no log


def test_the_cache_folder_follows_the_user_systemd_and_an_explicit_choice(tmp_path):
    def cache_dir(**extra: str) -> str:
        code = "import instrument, os; print(os.environ['NUMBA_CACHE_DIR'])"
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True,
                              env=clean_env(**extra)).stdout.strip()

    from instrument import _kernels_fingerprint

    version = _kernels_fingerprint()  # one folder per version of the kernels' sources
    assert cache_dir(HOME=str(tmp_path)) == str(tmp_path / ".cache" / "instrument" / "numba" / version)
    assert cache_dir(XDG_CACHE_HOME=str(tmp_path / "xdg")) == str(tmp_path / "xdg" / "instrument" / "numba" / version)
    assert cache_dir(CACHE_DIRECTORY=str(tmp_path / "var")) == str(tmp_path / "var" / "numba" / version)  # systemd's
    assert cache_dir(NUMBA_CACHE_DIR=str(tmp_path / "mine")) == str(tmp_path / "mine")


def test_a_changed_kernel_source_compiles_into_a_new_cache_folder(tmp_path):
    """numba checks a cached kernel against its own file only: the stream's step, cached against
    the solver it calls in another file, crashed the process once the solver had changed. The
    cache folder is named by every kernel module's text, so a change to any of them (here a copy
    of the package with one comment added to the solver) compiles afresh."""
    copy = tmp_path / "instrument"
    shutil.copytree(REPO / "instrument", copy, ignore=shutil.ignore_patterns("__pycache__"))
    code = "import instrument, os; print(os.environ['NUMBA_CACHE_DIR'])"

    def folder() -> str:
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True,
                              cwd=tmp_path, env={**clean_env(HOME=str(tmp_path)), "PYTHONPATH": str(tmp_path)}).stdout.strip()

    before = folder()
    with open(copy / "synthesis" / "mlpg.py", "a") as solver:
        solver.write("# changed\n")
    after = folder()
    assert before.startswith(str(tmp_path / ".cache" / "instrument" / "numba")) and before != after


def test_the_suite_runs_from_the_parent_of_a_clone_in_a_folder_named_instrument(tmp_path):
    """A clone in a folder named `instrument`, its tests started from the folder above it: there
    Python takes the clone's folder for a namespace package `instrument` holding no code (every
    command failed with "cannot import name '__version__' from 'instrument' (unknown location)"),
    unless the tests put their own checkout first, for themselves and the commands they start
    (tests/conftest.py). A copy of this checkout, with no PYTHONPATH, shows it."""
    clone = tmp_path / "instrument"
    shutil.copytree(REPO, clone, ignore=shutil.ignore_patterns(".git", "__pycache__", ".pytest_cache", "*.nbi", "*.nbc"))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    result = subprocess.run([sys.executable, "-m", "pytest", "instrument/tests/test_cli.py", "-q", "-p", "no:cacheprovider",
                             "-k", "help_lists_the_subcommands or version_and_help_load_no_subcommand"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0 and "2 passed" in result.stdout, result.stdout[-3000:] + result.stderr[-2000:]
