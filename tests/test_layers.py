"""The code's layers (docs/extending.md#layers): the import-linter contracts in pyproject.toml
hold for the package, and each of them breaks when a copy of the package is given the import it
forbids (so a kept contract means something)."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CONTRACTS = ("Each layer imports only the layers below it", "Live code never loads training or evaluation",
             "No import cycles between siblings")


def lint_imports(root: Path) -> tuple[dict[str, str], str]:
    """Runs lint-imports on the package in `root` with `root`'s pyproject.toml: each contract's
    name -> "KEPT" or "BROKEN", and the whole report."""
    env = {**os.environ, "PYTHONPATH": str(root), "COLUMNS": "200"}  # the copy's package, not an installed one
    result = subprocess.run([sys.executable, "-c", "from importlinter.cli import lint_imports_command; lint_imports_command()",
                             "--no-cache"], cwd=root, env=env, capture_output=True, text=True, timeout=300)
    report = result.stdout + result.stderr
    verdicts = dict(re.findall(r"^(.+?) (KEPT|BROKEN)$", result.stdout, re.MULTILINE))
    assert set(verdicts) == set(CONTRACTS), report
    assert (result.returncode == 0) == all(v == "KEPT" for v in verdicts.values()), report
    return verdicts, report


def test_the_package_keeps_its_layers_and_has_no_import_cycle():
    verdicts, report = lint_imports(ROOT)
    assert all(v == "KEPT" for v in verdicts.values()), report


AT_THE_TOP = "from __future__ import annotations\n"
IN_A_FUNCTION = "\n\ndef _added():\n    {}\n"

# (file, what is added to it, how, the contracts it must break); each case alone in a fresh copy
CASES = {
    "control imports runtime": ("control/values.py", "from ..runtime.health import Health", AT_THE_TOP,
                                {"Each layer imports only the layers below it", "No import cycles between siblings"}),
    "synthesis imports training inside a function": ("synthesis/engine.py", "from ..training import widen", IN_A_FUNCTION,
                                                     {"Each layer imports only the layers below it",
                                                      "Live code never loads training or evaluation",
                                                      "No import cycles between siblings"}),
    "output imports evaluation (below it, but not live)": ("output/osc.py", "from ..evaluation import assessment",
                                                           AT_THE_TOP, {"Live code never loads training or evaluation"}),
    "two synthesis modules import each other": ("synthesis/stream.py", "from .engine import Engine", IN_A_FUNCTION,
                                                {"No import cycles between siblings"}),
    "a top-level module no layer names": ("unplaced.py", "from . import errors", None,
                                          {"Each layer imports only the layers below it"}),
    "an upward import only for type checking": ("control/values.py",
                                                "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                                "    from ..runtime.health import Health",
                                                AT_THE_TOP, set()),
}


@pytest.mark.parametrize("case", CASES)
def test_each_contract_breaks_when_its_rule_is_broken(tmp_path, case):
    shutil.copytree(ROOT / "instrument", tmp_path / "instrument", ignore=shutil.ignore_patterns("__pycache__", "static"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    file, line, where, broken = CASES[case]
    path = tmp_path / "instrument" / file
    if where is None:
        path.write_text(line + "\n")
    elif where == AT_THE_TOP:
        text = path.read_text()
        assert AT_THE_TOP in text
        path.write_text(text.replace(AT_THE_TOP, AT_THE_TOP + line + "\n", 1))
    else:
        path.write_text(path.read_text() + where.format(line))
    verdicts, report = lint_imports(tmp_path)
    assert {contract for contract, verdict in verdicts.items() if verdict == "BROKEN"} == broken, report
