"""`instrument info`: what a model file holds."""

from __future__ import annotations

import argparse
import json

from ..shipped import default_model_path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="describe a model file: styles, states, durations, provenance, licence")
    p.add_argument("model", nargs="?", metavar="MODEL", help="model file (default: the shipped default model)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def summary(path: str) -> dict:
    from ..models.modelfile import load_model  # (numpy, scipy, numba: loaded when run, not for --help)

    model = load_model(path)
    meta = model.metadata
    layout = model.layout
    return {
        "file": str(path),
        "styles": model.style_names,
        "labels": model.labels,
        "units": model.units,
        "gestures": {name: g.get("repeats") for name, g in (meta.get("gestures") or {}).items()},  # and a tap's half cycles
        "states": model.states,
        "fps": model.fps,
        "static_dimension": layout.dimension,
        "observation_dimension": 3 * layout.dimension,
        "joints": len(layout.skeleton.joints),
        "modelled_joints": len(layout.joints),
        "mean_step_frames": meta.get("mean_step_frames", {}),
        "model_step_frames": {
            name: float(model.style(name).duration_means[:2].sum(axis=1).mean()) for name in model.style_names
        } | {"(average)": float(model.average.duration_means[:2].sum(axis=1).mean())},
        "shortest_state_frames": {name: float(model.style(name).duration_means[:2].min()) for name in model.style_names},  # the walk's
        "takes": len(meta.get("data", [])),
        "frames": sum(d["frames"] for d in meta.get("data", [])),
        "licence": meta.get("licence", ""),
        "attribution": meta.get("attribution", ""),
        "training": meta.get("training", {}),
    }


def run(args: argparse.Namespace) -> int:
    info = summary(args.model or str(default_model_path()))
    if args.json:
        print(json.dumps(info, indent=1))
        return 0
    print(info["file"])
    print(f"  styles     {', '.join(info['styles'])}")
    print(f"  units      {', '.join(info['units'])} (gaits without a unit of their own play the walk)")
    if info["gestures"]:
        print(f"  gestures   {', '.join(f'{g} ({n} half cycles a tap)' for g, n in info['gestures'].items())}")
    print(f"  labels     {', '.join(info['labels'])}; {info['states']} states each; {info['fps']:g} fps")
    print(f"  features   {info['static_dimension']} static ({info['modelled_joints']} of {info['joints']} joints), "
          f"{info['observation_dimension']} with deltas")
    print("  step       mean frames per step (data / model), shortest state of the model:")
    for name in info["styles"]:
        data = info["mean_step_frames"].get(name)  # none for a style trained without walks
        print(f"    {name:<12} {'no walk' if data is None else f'{data:5.1f}':>7} / {info['model_step_frames'][name]:5.1f}"
              f"   {info['shortest_state_frames'][name]:4.1f}")
    adaptation = info["training"].get("adaptation", {})
    if any("units" in chosen for chosen in adaptation.values()):  # models trained before 2026-11-30 chose per style
        print("  adapted    per unit: tree depth / tau (frames), chosen on the unit's own held-out steps (how split):")
        for name, chosen in adaptation.items():
            print(f"    {name:<12} " + ", ".join(_choice(unit, c) for unit, c in chosen.get("units", {}).items()))
    print(f"  data       {info['takes']} takes, {info['frames']} frames")
    print(f"  trained    {info['training'].get('command', '')!s} ({info['training'].get('seconds', '?')} s)")
    print(f"  licence    {info['licence']}")
    if info["attribution"]:
        print(f"  attribution {info['attribution']}")
    return 0


def _choice(unit: str, chosen: dict) -> str:
    """`run 2/16 (halves)`: a unit's adaptation settings as `instrument info` prints them."""
    depth = "none" if chosen["depth"] is None else chosen["depth"]
    return f"{unit} {depth}/{chosen['tau']:g}" + ("" if chosen["folds"] == "takes" else f" ({chosen['folds']})")
