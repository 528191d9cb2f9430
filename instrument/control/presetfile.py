"""Tables of target = value as files hold them: [presets.NAME] in a presets file, a show file, a
mapping or a score, and a score's ramps. Every value goes through the one check
(control/checks.py: `held_refusal`), so `"style/elderly" = 50` is refused alike in each, naming
the file, the line and the key."""

from __future__ import annotations

from collections.abc import Collection
from typing import TYPE_CHECKING

from ..errors import quoted
from ..tomlfile import Field, Key, TomlFile
from .checks import held_refusal
from .spec import PRESET_NAME, TABLE

if TYPE_CHECKING:
    from .state import ControlState


class AnyStyle:
    """Stands for a model's styles when none is at hand (a mapping read without a model, or one
    written for the default model): every style name is taken, the values are still checked."""

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name != ""

    def __iter__(self):
        return iter(())


ANY_STATES = 9999  # with AnyStyle: phase/<k> of any k a model may have


def model_of(state: ControlState | None, styles_known: bool = True) -> tuple[Collection[str], int]:
    """(styles, states) to check names against: the state's, or any when there is none (or its
    styles are not to be held against the file)."""
    if state is None:
        return AnyStyle(), ANY_STATES
    return (state.style_index if styles_known else AnyStyle()), state.states


def held_values(doc: TomlFile, path: Key, values: object, model: tuple[Collection[str], int],
                shown: str | None = None, empty: bool = False) -> dict[str, float]:
    """The table at `path` of `doc` as target -> value, each checked; the first bad one is a
    UserError `file:line: key: target: problem` (`shown`: the key as the message names it;
    `empty`: whether a table with nothing in it is taken)."""
    shown = shown if shown is not None else ".".join(str(p) for p in path if not isinstance(p, int))
    if not isinstance(values, dict) or not (values or empty):
        raise doc.error(path, "expected a table of target = number", shown)
    styles, states = model
    out = {}
    for target, value in values.items():
        why = held_refusal(target, value, styles, states)
        if why is not None:
            raise doc.error(path + (target,), why.text, shown)
        out[target] = float(TABLE[target.split("/")[0]].number(value))  # gait = "run" holds 2
    return out


def read_presets_file(path: str, model: tuple[Collection[str], int]) -> dict[str, dict[str, float]]:
    """A presets file (`--presets`, what the console saves): [presets.NAME] tables and nothing else."""
    doc = TomlFile(path)
    doc.check((), doc.data, {"presets": Field("table")})
    return read_presets(doc, model)


def read_presets(doc: TomlFile, model: tuple[Collection[str], int], path: Key = ("presets",)) -> dict[str, dict[str, float]]:
    """The file's [presets.NAME] tables (none: {}), checked."""
    tables = doc.data
    for name in path:
        tables = tables.get(name, {}) if isinstance(tables, dict) else {}
    if not isinstance(tables, dict):
        raise doc.error(path, "expected [presets.NAME] tables of target = number")
    out = {}
    for name, values in tables.items():
        if not PRESET_NAME.match(name):
            raise doc.error(path + (name,), f"{quoted(name)}: a preset name is 1 to 40 letters, digits, '_', '.', '-'",
                            ".".join(path))
        out[name] = held_values(doc, path + (name,), values, model, ".".join(path + (name,)), empty=True)
    return out
