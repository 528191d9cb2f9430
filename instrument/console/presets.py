"""Presets written as the TOML the CLI reads (`--presets FILE`, or a show file's [presets.NAME])."""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import UserError


def presets_toml(presets: dict[str, dict[str, float]]) -> str:
    lines = ["# presets saved by the instrument's console: [presets.NAME] tables of target = value", ""]
    for name in sorted(presets):
        lines.append(f"[presets.{json.dumps(name)}]")
        lines += [f"{json.dumps(target)} = {round(value, 6)!r}" for target, value in presets[name].items()]
        lines.append("")
    return "\n".join(lines)


def save_presets(path: str | Path, presets: dict[str, dict[str, float]]) -> None:
    """Replace `path` whole (written beside it, then renamed: a crash never leaves half a file)."""
    path = Path(path)
    temporary = path.with_name(f".{path.name}.saving")
    try:
        temporary.write_text(presets_toml(presets), encoding="utf-8")
        os.replace(temporary, path)
    except OSError as e:
        raise UserError(f"{path}: cannot save presets: {e.strerror or e}") from None
