"""The Khronos glTF-Validator (npm `gltf-validator`), run through node, for the glTF tests.

Installed once into the test cache (INSTRUMENT_TEST_CACHE, default ~/.cache/instrument-test/
gltf-validator; .ci/run installs it before the tests); a test is skipped, saying why, only when
node or npm is missing or npm cannot install it.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from blender_hosts import CACHE

SCRIPT = Path(__file__).parent / "gltf" / "validate.js"
FOLDER = CACHE / "gltf-validator"


def validator_modules() -> Path:
    """node_modules holding gltf-validator, installed with npm if missing."""
    modules = FOLDER / "node_modules"
    if (modules / "gltf-validator").is_dir():
        return modules
    if shutil.which("node") is None or shutil.which("npm") is None:
        pytest.skip("node and npm are needed for the Khronos glTF-Validator (apt-get install nodejs npm)")
    FOLDER.mkdir(parents=True, exist_ok=True)
    with open(CACHE / "gltf-validator.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (modules / "gltf-validator").is_dir():
            (FOLDER / "package.json").write_text('{"private": true}\n')
            made = subprocess.run(["npm", "install", "--no-audit", "--no-fund", "gltf-validator"], cwd=FOLDER,
                                  capture_output=True, text=True)
            if made.returncode != 0:
                pytest.skip(f"npm could not install gltf-validator: {(made.stderr.strip().splitlines() or ['?'])[-1]}")
    return modules


def validate(path: Path) -> dict:
    """The validator's issues for `path`: numErrors, numWarnings, messages..."""
    result = subprocess.run(["node", str(SCRIPT), str(path)], capture_output=True, text=True, timeout=120,
                            env={"NODE_PATH": str(validator_modules()), "PATH": os.environ.get("PATH", "")})
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)
