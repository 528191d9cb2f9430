"""`instrument inspect`: what a user checks about their motion capture before training."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import UserError
from .train_cmd import UNIT_ELSEWHERE, add_name_options, name_patterns

if TYPE_CHECKING:  # (the training's modules load numpy: not for --help)
    from ..training.corpus import TakeFile


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("inspect", help="check BVH files: skeleton, frames, steps found, warnings")
    p.add_argument("paths", nargs="*", metavar="FILE_OR_DIR", help="BVH files or folders holding them")
    p.add_argument("--manifest", metavar="FILE", help="the takes a training manifest names, with the style, unit and "
                   "gesture it gives each (as train --manifest reads them)")
    add_name_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON document instead of text")
    p.set_defaults(run=run)


def describe(path: Path, listed: TakeFile | None = None, style_from: str | None = None, unit_from: str | None = None) -> dict:
    """What a take holds; its style, unit and gesture as a manifest's row `listed` (a TakeFile)
    gives them, else as `train` reads them from the name (with its --style-from and --unit-from:
    a studio's own names were shown as walks without a style, though train read them right)."""
    # numpy, and scipy and numba for finding the steps: loaded when run, not for --help (nor for `train`'s)
    from ..motion.bvh import read_bvh
    from ..motion.features import choose_layout
    from ..motion.standing import standing_steps
    from ..motion.steps import contiguous_runs, segment_steps
    from ..motion.upright import upright
    from ..training.corpus import DEFAULT_STYLE_PATTERN, style_from_name
    from ..training.units import gesture_from_name, take_gesture, unit_from_name, unit_said_elsewhere

    motion, up = upright(read_bvh(path))
    if listed is not None:
        unit, style = listed.unit, listed.style
    else:
        unit = unit_from_name(path, unit_from)  # what `train` reads from the name
        try:
            style = style_from_name(path, style_from or DEFAULT_STYLE_PATTERN)
        except UserError:
            style = None
    gesture = take_gesture(path, unit, listed.gesture if listed is not None else gesture_from_name(path, unit_from) or "")
    # a standing take's "steps" are its pieces of still standing, as training cuts them
    segmentation = standing_steps(motion, choose_layout([motion])) if unit == "stand" else segment_steps(motion)
    steps = segmentation.steps
    warnings = list(segmentation.warnings)
    elsewhere = unit_said_elsewhere(path) if listed is None and unit_from is None and unit == "walk" else None
    if elsewhere:
        warnings.append(UNIT_ELSEWHERE.format(elsewhere))
    if up != "+Y":
        warnings.append(f"{up} is up in this capture: read turned Y up (the models trained on it and their walks are Y up)")
    runs = contiguous_runs(steps)
    if len(runs) > 1 and unit != "stand":
        warnings.append(f"steps fall into {len(runs)} separate runs")
    skeleton = motion.skeleton
    return {
        "file": str(path),
        "frames": motion.frames,
        "fps": motion.fps,
        "up": up,
        "duration": motion.duration,
        "style": style,
        "unit": unit,
        "gesture": gesture,
        "said_by": "manifest" if listed is not None else "name",
        "joints": [{"name": j.name, "channels": list(j.channels)} for j in skeleton.joints],
        "channels": skeleton.channel_count,
        "feet": [foot for foot in segmentation.feet if foot],  # none found: [], not ["", ""]
        "steps": [{"label": s.label, "start": s.start, "frames": s.frames} for s in steps],
        "warnings": warnings,
    }


def _text(info: dict) -> str:
    steps = info["steps"]
    mean = sum(s["frames"] for s in steps) / len(steps) if steps else 0.0
    rotation_orders = sorted({"".join(c[0] for c in j["channels"] if c.endswith("rotation")) or "-" for j in info["joints"]})
    lines = [
        info["file"],
        f"  joints   {len(info['joints'])} ({', '.join(j['name'] for j in info['joints'])})",
        f"  channels {info['channels']} (rotation orders {', '.join(rotation_orders)})",
        f"  frames   {info['frames']} at {info['fps']:g} fps, {info['duration']:.2f} s",
        f"  unit     {info['unit']}" + (f" ({info['gesture']})" if info.get("gesture") else "")
        + f", style {info['style'] or '(none in the name: give train --style-from or a manifest)'}"
        + (" (as the manifest gives them)" if info.get("said_by") == "manifest" else " (read from the name, as train does)"),
        f"  {'stills' if info['unit'] == 'stand' else 'steps '}   {len(steps)}, mean {mean:.1f} frames "
        f"({mean / info['fps']:.2f} s)"
        + ("; pieces of still standing with the arms down" if info["unit"] == "stand" else
           f"; feet {' / '.join(info['feet']) or 'not found'}"),
    ]
    lines += [f"  warning: {w}" for w in info["warnings"]]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from ..training.corpus import bvh_files, read_manifest

    if not args.paths and not args.manifest:
        raise UserError("give BVH files or folders, or --manifest FILE")
    style_from, unit_from = name_patterns(args)
    takes = [(path, None) for path in bvh_files(args.paths)] if args.paths else []
    if args.manifest:
        takes += [(take.path, take) for take in read_manifest(Path(args.manifest))]
    results, failed = [], 0
    for path, listed in takes:
        try:
            info = describe(path, listed, style_from, unit_from)
        except UserError as error:
            failed += 1
            message = str(error) if str(error).startswith(str(path)) else f"{path}: {error}"  # which file, always
            print(f"instrument inspect: error: {message}", file=sys.stderr)
            if args.json:
                results.append({"file": str(path), "error": message})
            continue
        results.append(info)
        if not args.json:
            print(_text(info))
    if args.json:
        json.dump(results, sys.stdout, indent=1)
        print()
    return 1 if failed else 0
