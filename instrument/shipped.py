"""Files that ship with the instrument: found in a checkout, or where the package installed them."""

from __future__ import annotations

from pathlib import Path

from .errors import UserError

_TOP = Path(__file__).resolve().parents[1]
_PACKAGE = Path(__file__).resolve().parent
PLACES = {"models": "shipped_models", "examples/demo": "shipped_demo", "mappings": "shipped_mappings"}  # checkout -> installed


def shipped_file(folder: str, name: str) -> Path:
    checkout = _TOP / folder / name
    if checkout.is_file():
        return checkout
    installed = _PACKAGE / PLACES[folder] / name
    if installed.is_file():
        return installed
    raise UserError(f"shipped file {folder}/{name} is missing (looked in {checkout} and {installed})")


def default_model_path() -> Path:
    return shipped_file("models", "default.npz")


def demo_score_path() -> Path:
    return shipped_file("examples/demo", "demo.toml")


def shipped_mappings() -> list[Path]:
    """Every mapping file that ships (mappings/*.toml)."""
    for folder in (_TOP / "mappings", _PACKAGE / PLACES["mappings"]):
        if folder.is_dir():
            return sorted(folder.glob("*.toml"))
    return []
