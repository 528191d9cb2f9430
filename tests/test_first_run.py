"""The first run after installing: numba's compiled kernels go to the user's cache folder (never
beside the installed package, where a regular install's cache used to hide an editable install
made after it), and the command says it is compiling instead of going silent for half a minute.

(The two install orders of the README, `pip install '.[view]'` then `pip install -e '.[test]'`
and the reverse, were run by hand in a throwaway virtual environment; docs/cli.md says so.)"""

from __future__ import annotations

import os
import subprocess
import sys
import time

from conftest import REPO
from samples import cmu_style_walk

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


def test_the_cache_folder_follows_the_user_systemd_and_an_explicit_choice(tmp_path):
    def cache_dir(**extra: str) -> str:
        code = "import instrument, os; print(os.environ['NUMBA_CACHE_DIR'])"
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True,
                              env=clean_env(**extra)).stdout.strip()

    assert cache_dir(HOME=str(tmp_path)) == str(tmp_path / ".cache" / "instrument" / "numba")
    assert cache_dir(XDG_CACHE_HOME=str(tmp_path / "xdg")) == str(tmp_path / "xdg" / "instrument" / "numba")
    assert cache_dir(CACHE_DIRECTORY=str(tmp_path / "var")) == str(tmp_path / "var" / "numba")  # systemd's CacheDirectory=
    assert cache_dir(NUMBA_CACHE_DIR=str(tmp_path / "mine")) == str(tmp_path / "mine")
