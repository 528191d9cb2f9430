"""`instrument view`: a live stick figure from the flat OSC profile, to see the walk at once."""

from __future__ import annotations

import argparse
import os
import socket
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..output.drawing import bone_colours, draw_framed, drawn_parents, pyplot
from ..output.osc import FLAT_PORT
from ..outputfile import check_output, written
from ..shipped import default_model_path
from .arguments import checked


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="live stick figure of the flat OSC profile (needs matplotlib)")
    p.add_argument("--model", help="model file whose skeleton is drawn (default: the shipped default model)")
    p.add_argument("--port", type=checked("view --port"), default=FLAT_PORT, help=f"UDP port to listen on, 127.0.0.1 (default {FLAT_PORT})")
    p.add_argument("--frames", type=checked("view --frames"), help="stop after this many frames (default: until the window closes)")
    p.add_argument("--save", metavar="PNG", help="draw off screen and save the last frame here (no window)")
    p.add_argument("--force", action="store_true", help="overwrite the --save file if it exists (default: refuse)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from pythonosc.osc_bundle import OscBundle
    from pythonosc.osc_message import OscMessage

    from ..models.modelfile import load_model  # (scipy, numba: loaded when run, not for --help)

    if args.save:
        if Path(args.save).suffix.lower() != ".png":
            raise UserError(f"--save {args.save}: give a .png file")
        check_output(args.save, args.force)
    elif not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) and sys.platform.startswith("linux"):
        raise UserError("no display to open a window on (DISPLAY is not set): give --save FRAME.png to draw off screen")
    skeleton = load_model(args.model or default_model_path()).layout.skeleton
    names, parents = skeleton.names, skeleton.parents
    colours = bone_colours(names)
    index = {f"/walk/bone/{n}/pos": k for k, n in enumerate(names)}
    plt = pyplot("Agg" if args.save else None)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind(("127.0.0.1", args.port))
    except OSError as e:
        raise UserError(f"--port {args.port}: cannot listen: {e.strerror}") from None
    sock.settimeout(0.05)
    fig, ax = plt.subplots(figsize=(5, 5))
    positions = np.zeros((len(names), 3))
    first = None
    shown = 0
    last_frame_at = time.monotonic()
    print(f"listening on 127.0.0.1:{args.port} for the flat profile", file=sys.stderr)
    try:
        while (not args.frames or shown < args.frames) and (args.save or plt.fignum_exists(fig.number)):
            try:
                data = sock.recv(65536)
            except socket.timeout:
                if not args.save:
                    plt.pause(0.01)
                if time.monotonic() - last_frame_at > 10 and args.save:
                    raise UserError(f"no frames arrived on port {args.port} for 10 s")
                continue
            contents = OscBundle(data) if OscBundle.dgram_is_bundle(data) else [OscMessage(data)]
            for m in contents:
                if m.address in index:
                    positions[index[m.address]] = m.params
                elif m.address == "/walk/frame":
                    shown += 1
                    last_frame_at = time.monotonic()
                    first = positions.copy() if first is None else first
                    _draw(ax, positions, drawn_parents(parents, np.stack([first, positions])), m.params[0], colours)
                    if not args.save:
                        plt.pause(0.001)
    except KeyboardInterrupt:
        pass
    finally:
        sock.close()
    if args.save:
        with written(args.save) as part:
            fig.savefig(part, dpi=80, format="png")
        print(f"saved frame {shown - 1} to {args.save}", file=sys.stderr)
    return 0


def _draw(ax, positions: np.ndarray, parents: np.ndarray, frame: int, colours: list[str]) -> None:
    ax.clear()
    points = np.stack([positions[:, 2], positions[:, 1]], axis=1)  # side view: forward and up
    height = max(np.ptp(points[:, 1]), 1e-6)
    draw_framed(ax, points, parents, points[:, 1].min() - 0.1 * height, points[:, 1].max() + 0.1 * height, 0.7 * height, colours)
    ax.set_title(f"frame {frame}")
