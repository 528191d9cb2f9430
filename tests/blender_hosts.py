"""The Blenders the tests run scripts in: Debian's `blender` 3.4 and PyPI's `bpy` 4.5 LTS and 5.0.

A script written for `blender -b --python SCRIPT -- ARGS` runs unchanged as `python SCRIPT --
ARGS` with the `bpy` module installed: `import bpy` is a headless Blender (`bpy.app.background`
is true) with the same add-ons (the BVH and glTF importers). Each `bpy` version lives in a
virtual environment of its own, made once and kept under the test cache
(INSTRUMENT_TEST_CACHE, default ~/.cache/instrument-test/bpy-4.5 and bpy-5.0; .ci/run makes
them before the tests). A test is skipped, with the reason, only when a host cannot exist here:
no `blender` command, no CPython 3.11 (the only Python PyPI's `bpy` wheels are built for), or
pip failing to install the wheel.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

HOSTS = ("3.4", "4.5", "5.0")  # Debian's Blender, the 4.5 LTS and 5.0 bpy wheels
BPY_VERSIONS = {"4.5": "bpy==4.5.*", "5.0": "bpy==5.0.*"}
CACHE = Path(os.environ.get("INSTRUMENT_TEST_CACHE", Path.home() / ".cache" / "instrument-test"))


def python311() -> str | None:
    """A CPython 3.11 to make the bpy environments with: this one, else `python3.11` on PATH."""
    if sys.version_info[:2] == (3, 11):
        return sys.executable
    return shutil.which("python3.11")


def bpy_python(host: str) -> Path:
    """The Python of the environment holding `bpy` for `host`, made (pip install) if missing.

    Made in a folder of its own beside the final one and renamed when complete, under a lock,
    so an interrupted install or two test runs at once never leave a half environment."""
    folder = CACHE / f"bpy-{host}"
    python = folder / "bin" / "python"
    if python.exists():
        return python
    base = python311()
    if base is None:
        pytest.skip(f"Blender {host} as a module: PyPI's bpy wheels need CPython 3.11, and there is none here")
    CACHE.mkdir(parents=True, exist_ok=True)
    with open(CACHE / f"bpy-{host}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if python.exists():  # made by another run while this one waited
            return python
        partial = CACHE / f"bpy-{host}.partial"
        shutil.rmtree(partial, ignore_errors=True)
        made = subprocess.run([base, "-m", "venv", str(partial)], capture_output=True, text=True)
        if made.returncode == 0:
            made = subprocess.run([str(partial / "bin" / "python"), "-m", "pip", "install", "-q", BPY_VERSIONS[host]],
                                  capture_output=True, text=True)
        if made.returncode != 0:
            shutil.rmtree(partial, ignore_errors=True)
            reason = (made.stderr.strip().splitlines() or ["(no message)"])[-1]
            pytest.skip(f"Blender {host} as a module: pip could not install {BPY_VERSIONS[host]}: {reason}")
        partial.rename(folder)
    return python


def blender_command(host: str, script: Path | str, *args: str) -> list[str]:
    """The command that runs `script` headless in `host`, with `args` after `--` (skips the test
    if the host cannot exist here)."""
    if host == "3.4":
        blender = shutil.which("blender")
        if blender is None:
            pytest.skip("blender is not installed (apt-get install blender)")
        return [blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(script), "--", *args]
    return [str(bpy_python(host)), str(script), "--", *args]


def blender_env(tmp_path: Path) -> dict[str, str]:
    """The environment for a host: the user's own Blender settings and add-ons left out (as
    --factory-startup does for the `blender` command), the test's Python path kept out."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    config = tmp_path / "blender-user"
    config.mkdir(exist_ok=True)
    env.update(BLENDER_USER_CONFIG=str(config), BLENDER_USER_SCRIPTS=str(config), BLENDER_USER_DATAFILES=str(config))
    return env
