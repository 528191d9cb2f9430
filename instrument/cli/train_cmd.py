"""`instrument train`: learn an average model and one model per style from BVH takes."""

from __future__ import annotations

import argparse
import re
import shlex
import sys
import time
from pathlib import Path

from ..errors import UserError
from ..outputfile import check_output
from .arguments import checked
from .progress import Progress


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train style models from BVH takes")
    p.add_argument("data", nargs="*", metavar="DATA", help="BVH files or folders")
    p.add_argument("--out", required=True, metavar="MODEL.npz", help="where to write the model")
    p.add_argument("--force", action="store_true", help="overwrite the model if it exists (default: refuse)")
    add_name_options(p)
    p.add_argument("--manifest", metavar="FILE",
                   help="CSV (file,style[,unit[,gesture]]) or TOML ([[take]] file, style[, unit, gesture]) naming takes, "
                        "styles, units and standing takes' gestures")
    p.add_argument("--fps", type=checked("train --fps"),
                   help="frame rate the model works at (default 30; takes at another rate are resampled to it)")
    p.add_argument("--states", type=checked("train --states"), default=5, help="states per step model (default 5)")
    p.add_argument("--licence", help="licence of the model (that of the training data; default: says it is unspecified)")
    p.add_argument("--attribution", default="", help="attribution the licence requires")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(run=run)


# a take read as a walk whose name says another unit elsewhere (training/units.unit_said_elsewhere)
UNIT_ELSEWHERE = ("read as a walk, but its name's {} (the unit is read from the part before the style: "
                  "give --unit-from REGEX or a manifest)")


def add_name_options(p: argparse.ArgumentParser) -> None:
    """--style-from and --unit-from, for train and for inspect (which shows what train reads)."""
    p.add_argument("--style-from", metavar="REGEX",
                   help="regular expression with one group that finds the style in a file name (without .bvh); "
                        "default: the last but one '_'-separated part, so dataset-2_walk_elderly_003.bvh is elderly")
    p.add_argument("--unit-from", metavar="REGEX",
                   help="regular expression with one group that finds the motion unit in a file name (a word for walk, "
                        "run, turn-left, turn-right or stand; a stand's gesture is read there too); default: the part "
                        "before the style, so dataset-2_walk-turn-left_active_001.bvh is turn-left, and a name that "
                        "says nothing is a walk")


def name_patterns(args: argparse.Namespace) -> tuple[str, str | None]:
    """The style's and the unit's expressions (--style-from, --unit-from; None: the default unit
    part), each checked to compile with exactly one group."""
    from ..training.corpus import DEFAULT_STYLE_PATTERN

    for option, given in (("--style-from", args.style_from), ("--unit-from", args.unit_from)):
        if given is None:
            continue
        try:
            groups = re.compile(given).groups
        except re.error as e:
            raise UserError(f"{option}: not a regular expression: {e}") from None
        if groups != 1:
            raise UserError(f"{option}: the expression needs exactly one group, it has {groups}")
    return args.style_from or DEFAULT_STYLE_PATTERN, args.unit_from


def _pairs(args: argparse.Namespace) -> list:
    from ..training.corpus import bvh_files, read_manifest, styled_takes
    from ..training.units import unit_said_elsewhere

    pairs: list = []
    if args.manifest:
        pairs += read_manifest(Path(args.manifest))
    if args.data:
        style_from, unit_from = name_patterns(args)
        listed = {p.path.resolve() for p in pairs}  # a take the manifest names takes its style from there
        named = styled_takes([f for f in bvh_files(args.data) if f.resolve() not in listed], style_from, unit_from)
        for take in named if unit_from is None else []:  # said even with --quiet: something to act on
            elsewhere = unit_said_elsewhere(take.path) if take.unit == "walk" else None
            if elsewhere:
                print(f"warning: {take.path}: {UNIT_ELSEWHERE.format(elsewhere)}", file=sys.stderr)
        pairs += named
    if not pairs:
        raise UserError("no training data: give BVH files or folders, or --manifest")
    first: dict = {}
    for take in pairs:  # twice, a take would weigh double (or teach two styles the same steps)
        seen = first.setdefault(take.path.resolve(), take)
        if seen is not take:
            raise UserError(f"{take.path}: named twice (as {seen.style} {seen.unit} and as {take.style} {take.unit}); "
                            "give each take once")
    return pairs


def other_rates(rates: list[float], fps: float) -> str | None:
    """What to say where takes captured at `rates` (one a file) train a model at the default
    rate `fps`, which they are resampled to (60 fps takes gave a 30 fps model without a word):
    their rates, the model's, and how to keep theirs. None where every take is at the model's."""
    other = sorted({rate for rate in rates if abs(rate - fps) >= 1e-9})  # `resample`'s test
    if not other:
        return None
    count = sum(abs(rate - fps) >= 1e-9 for rate in rates)
    takes = ("the takes are" if count == len(rates) else
             f"{count} of the {len(rates)} takes {'is' if count == 1 else 'are'}")
    named = [f"{rate:g}" for rate in other]
    listed = named[0] if len(named) == 1 else f"{', '.join(named[:-1])} and {named[-1]}"
    return (f"{takes} at {listed} fps, resampled to the model's {fps:g} fps "
            f"(--fps's default): give --fps {other[-1]:g} to keep {'their' if len(other) == 1 else 'the highest'} rate")


def _styles(count: int) -> str:
    return f"{count} style" if count == 1 else f"{count} styles"


def run(args: argparse.Namespace) -> int:
    # the training code (numpy, scipy, numba): loaded when run, not for --help
    from ..training.build import UNSPECIFIED_LICENCE, build_model
    from ..models.modelfile import save_model
    from ..motion.features import DEFAULT_FPS

    check_output(args.out, args.force)
    if Path(args.out).suffix.lower() != ".npz":  # a model is read back by its content, but named as one
        raise UserError(f"--out {args.out}: give a .npz file (a model)")
    pairs = _pairs(args)
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr))
    styles = sorted({p.style for p in pairs})
    units = sorted({p.unit for p in pairs})
    say(f"training on {len(pairs)} takes, {_styles(len(styles))}: {', '.join(styles)}; units: {', '.join(units)}")
    started = time.perf_counter()
    command = "instrument train " + " ".join(shlex.quote(a) for a in sys.argv[2:]) if sys.argv[1:2] == ["train"] else ""
    model, report, takes = build_model(
        pairs, DEFAULT_FPS if args.fps is None else args.fps, args.states, command, args.licence or UNSPECIFIED_LICENCE,
        args.attribution,
        progress=Progress(args.quiet),
        on_iteration=lambda i, ll: say(f"EM iteration {i:2d}: log-likelihood per frame {ll:.4f}"),
    )
    save_model(args.out, model)
    rates = other_rates(report.capture_rates, model.fps) if args.fps is None else None  # given: the rate asked for
    for w in report.warnings + ([rates] if rates else []):  # said even with --quiet: not progress, something to act on
        print(f"warning: {w}", file=sys.stderr)
    steps = sum(len(t.steps) for t in takes)
    say(f"done in {time.perf_counter() - started:.1f} s: {len(takes)} takes, {steps} steps, "
        f"{_styles(len(model.style_names))}, {model.layout.dimension} features x 3 -> {args.out}")
    return 0
