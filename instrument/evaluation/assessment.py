"""`instrument evaluate`'s work: generate walks for a set of style weightings, measure them, and
measure the real takes the model learnt from the same way.

Variants: each style at weight 1, exaggerated (x2), inverted (-1), and every pair at 0.5/0.5.
Each walk starts from rest; its first half second is left out so the figures describe walking.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import extract
from ..motion.kinematics import world_positions
from ..motion.limbs import Limbs, centimetres_per_unit, clearance, find_limbs
from ..motion.quality import pooled, take_floors, walk_figures
from ..motion.steps import segment_steps
from ..synthesis.engine import default_controls, render
from ..training.corpus import TakeFile, make_takes, other_captures, read_motions
from .recognition import LinearDiscriminant, step_features

VARIANT_KINDS = ("one", "x2", "inverted", "pairs")  # also in cli/evaluate_cmd.py
SETTLE_SECONDS = 0.5
FOLDS = 5


@dataclass
class Assessment:
    synth: dict[str, dict[str, float]] = field(default_factory=dict)  # variant name -> figures
    real: dict[str, dict[str, float]] = field(default_factory=dict)  # style -> figures of its real takes
    weights: dict[str, dict[str, float]] = field(default_factory=dict)  # variant name -> style weights


def variants(styles: list[str], kinds: tuple[str, ...] = VARIANT_KINDS) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    if "one" in kinds:
        out |= {s: {s: 1.0} for s in styles}
    if "x2" in kinds:
        out |= {f"{s} x2": {s: 2.0} for s in styles}
    if "inverted" in kinds:
        out |= {f"{s} -1": {s: -1.0} for s in styles}
    if "pairs" in kinds:
        out |= {f"{a}+{b}": {a: 0.5, b: 0.5} for a, b in combinations(styles, 2)}
    return out


def model_limbs(model: Model) -> tuple[Limbs, float, np.ndarray]:
    """The model's legs and arms, centimetres per unit of its skeleton, and its template pose's
    joint positions: what every measure of its motion reads feet, scale and ground from."""
    layout = model.layout
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    if limbs is None:
        raise UserError("the model's skeleton has no two legs below its root: its walks cannot be measured")
    template = world_positions(Motion(layout.skeleton, np.asarray(layout.template)[None], model.fps))[0]
    return limbs, centimetres_per_unit(layout, template), template


def real_pairs(model: Model, folders: Path | list[Path], units: tuple[str, ...] | None = ("walk",)) -> list[TakeFile]:
    """The takes the model's provenance names (those of `units`; None: all), found in `folders`
    (searched recursively; a take listed without a unit is a walk)."""
    folders = [folders] if isinstance(folders, Path) else list(folders)
    on_disk = _on_disk(folders)
    listed = _listed(model, units)
    pairs = [t._replace(path=on_disk[t.path.name]) for t in listed if t.path.name in on_disk]
    if not pairs:
        where = ", ".join(str(f) for f in folders)
        hint = "" if on_disk else "".join(other_captures(f) for f in folders)  # no BVH at all: another format?
        raise UserError(f"{where}: none of the {len(listed)} takes the model was trained on is there{hint}")
    return pairs


def _on_disk(folders: list[Path]) -> dict[str, Path]:
    on_disk: dict[str, Path] = {}
    for folder in folders:
        if not folder.is_dir():
            raise UserError(f"{folder}: no such folder")
        on_disk |= {p.name: p for p in sorted(folder.rglob("*.bvh"))}
    return on_disk


def _listed(model: Model, units: tuple[str, ...] | None) -> list[TakeFile]:
    listed = [TakeFile(Path(d["file"]), d["style"], d.get("unit", "walk"), d.get("gesture", ""))
              for d in model.metadata.get("data", [])]
    return [t for t in listed if units is None or t.unit in units]


def missing_takes(model: Model, folders: list[Path], units: tuple[str, ...] | None = ("walk",)) -> list[str]:
    """One line per unit some of whose listed takes none of `folders` holds: measured without them
    (a unit with none there has no real figures nor targets), which evaluate said nothing of."""
    on_disk = _on_disk(folders)
    by_unit: dict[str, list[str]] = {}
    for take in _listed(model, units):
        by_unit.setdefault(take.unit, []).append(take.path.name)
    lines = []
    for unit, mine in by_unit.items():
        gone = [name for name in mine if name not in on_disk]
        if gone:
            lines.append(f"{len(gone)} of the model's {len(mine)} {unit} takes are not in {', '.join(map(str, folders))} "
                         f"({gone[0]}{' ...' if len(gone) > 1 else ''}): measured without them (give their folder with "
                         "another --real)")
    return lines


def assess(
    model: Model,
    seconds: float = 12.0,
    real: Path | list[Path] | None = None,
    styles: list[str] | None = None,
    kinds: tuple[str, ...] = VARIANT_KINDS,
    progress=None,
) -> Assessment:
    styles = styles or model.style_names
    limbs, cm, template = model_limbs(model)
    layout = model.layout
    result = Assessment(weights=variants(styles, kinds))
    classifier = None
    if real is not None:  # every style's takes: the classifier must know all the styles to tell them apart
        pairs = real_pairs(model, real)
        motions = read_motions(pairs, model.fps)
        takes, _ = make_takes(pairs, motions, layout)  # first: it names a take of another skeleton or units
        positions = [world_positions(m) for m in motions]
        floors = take_floors(positions, limbs)  # each take on its own floor, a made walk on their mean
        ground, sole = floors.mean_ground, floors.mean_sole
        features = [step_features(t.observations[:, : layout.dimension], t.steps) for t in takes]
        classifier = LinearDiscriminant(np.vstack(features), [t.style for t, x in zip(takes, features) for _ in x])
        recognised = _cross_validated(takes, features)
        for style in styles:
            mine = [walk_figures(m, layout, limbs, g, cm, f) for m, p, g, f in zip(motions, pairs, floors.ground, floors.sole)
                    if p.style == style]
            if mine:
                result.real[style] = pooled(mine) | {"recognised": recognised.get(style, float("nan"))}
            if progress:
                progress(f"{style} (real)")
    else:
        ground, sole = _model_ground(model, limbs, template), None
    settle = int(round(SETTLE_SECONDS * model.fps))
    frames = settle + max(1, int(round(seconds * model.fps)))
    for name, weights in result.weights.items():
        motion = render(model, default_controls(model, weights), frames)
        motion = Motion(motion.skeleton, motion.channels[settle:], motion.fps)
        figures = walk_figures(motion, layout, limbs, ground, cm, sole)
        figures["recognised"] = float("nan")
        target = [s for s, w in weights.items() if w > 0]
        if classifier is not None and len(target) == 1:
            steps = segment_steps(motion, layout).steps
            if steps:
                again, _, _ = extract(motion, layout)
                labels = classifier.step_labels(step_features(again, steps))
                figures["recognised"] = float(np.mean([label == target[0] for label in labels]))
        figures["finite"] = float(np.isfinite(motion.channels).all())
        result.synth[name] = figures
        if progress:
            progress(name)
    return result


def _cross_validated(takes, features) -> dict[str, float]:
    """Per style, the share of real steps labelled right by a classifier that did not see their take."""
    fold = np.zeros(len(takes), dtype=int)
    for style in {t.style for t in takes}:
        mine = [k for k, t in enumerate(takes) if t.style == style]
        fold[mine] = np.arange(len(mine)) % FOLDS
    hits: dict[str, list[bool]] = {}
    for f in range(FOLDS):
        train = [k for k in range(len(takes)) if fold[k] != f]
        known = {takes[k].style for k in train}
        if len(known) < 2:
            continue
        classifier = LinearDiscriminant(np.vstack([features[k] for k in train]), [takes[k].style for k in train for _ in features[k]])
        for k in np.flatnonzero(fold == f):
            if takes[k].style not in known:  # its only take: no classifier that did not see it knows the style
                continue
            hits.setdefault(takes[k].style, []).extend(label == takes[k].style for label in classifier.step_labels(features[k]))
    return {s: float(np.mean(h)) for s, h in hits.items()}


def _model_ground(model: Model, limbs: Limbs, template: np.ndarray) -> np.ndarray:
    """Ground clearance without real takes: what training stored, else the template pose's feet."""
    stored = model.metadata.get("contact", {}).get("clearance")
    if stored is not None and np.shape(stored) == (2, len(limbs.feet[0])):
        return np.asarray(stored, dtype=np.float64)
    return clearance([template[None]], limbs)
