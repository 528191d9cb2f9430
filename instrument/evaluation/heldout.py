"""Held-out scoring: how well each model explains takes it was not trained on."""

from __future__ import annotations

from pathlib import Path

from ..models.hsmm import HSMM, log_likelihood
from ..models.modelfile import Model
from ..training.corpus import Take, make_takes, read_motions


def split_holdout(pairs: list[tuple[Path, str]], every: int = 5) -> tuple[list[tuple[Path, str]], list[tuple[Path, str]]]:
    """Per style, every `every`-th take (about 20% for 5) is held out; the rest trains."""
    train, held = [], []
    for style in sorted({s for _, s in pairs}):
        mine = sorted(p for p in pairs if p[1] == style)
        for k, pair in enumerate(mine):
            (held if k % every == every - 1 else train).append(pair)
    return train, held


def score(model: HSMM, takes: list[Take], states: int) -> float:
    """Log-likelihood per frame of all steps of the takes."""
    total, frames = 0.0, 0
    for k, label in enumerate(("right", "left")):
        segments = [seg for t in takes for seg in t.segments(label) if len(seg) >= states]
        if segments:
            ll, n = log_likelihood(model, k, segments)
            total, frames = total + ll, frames + n
    return total / max(frames, 1)


def heldout_table(model: Model, held: list[tuple[Path, str]]) -> dict[str, dict[str, float]]:
    """table[true style][model name] = held-out log-likelihood per frame; model names are the
    styles and '(average)'."""
    takes, _ = make_takes(held, read_motions(held, model.fps), model.layout)
    table: dict[str, dict[str, float]] = {}
    for style in sorted({t.style for t in takes}):
        mine = [t for t in takes if t.style == style]
        row = {"(average)": score(model.average, mine, model.states)}
        for name in model.style_names:
            row[name] = score(model.style(name), mine, model.states)
        table[style] = row
    return table


def own_style_wins(table: dict[str, dict[str, float]]) -> dict[str, tuple[bool, bool]]:
    """Per style: (beats the average model, beats every other style's model) on its own takes."""
    out = {}
    for style, row in table.items():
        others = [v for k, v in row.items() if k not in (style, "(average)")]
        out[style] = (row[style] > row["(average)"], row[style] > max(others) if others else True)
    return out


def format_table(table: dict[str, dict[str, float]]) -> str:
    names = list(next(iter(table.values())).keys())
    lines = ["held-out takes \\ model  " + " ".join(f"{n[:9]:>9}" for n in names)]
    for style, row in table.items():
        best = max(row, key=row.get)
        cells = " ".join(f"{row[n]:9.2f}{'*' if n == best else ' '}"[:10] for n in names)
        lines.append(f"{style:<23} {cells}")
    wins = own_style_wins(table)
    lines.append(f"own model beats average: {sum(a for a, _ in wins.values())}/{len(wins)}; "
                 f"beats all other styles: {sum(b for _, b in wins.values())}/{len(wins)}")
    return "\n".join(lines)

