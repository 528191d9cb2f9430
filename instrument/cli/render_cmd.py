"""`instrument render`: a contact sheet (PNG) or an animation (GIF) of a recorded performance."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import UserError
from ..outputfile import check_output, written
from .arguments import checked

SHEET_FIGURES, SHEET_SPACING = 12, 0.1  # the default contact sheet: 12 figures, 0.1 s apart


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="draw a BVH recording: contact sheet (.png) or animation (.gif)")
    p.add_argument("--bvh", required=True, metavar="FILE.bvh")
    p.add_argument("--out", required=True, metavar="walk.png|walk.gif")
    p.add_argument("--force", action="store_true", help="overwrite the --out file if it exists (default: refuse)")
    p.add_argument("--every", type=checked("render --every"), help="draw every Nth frame (default: a PNG shows 12 figures 0.1 s apart, about one stride; a GIF plays at 15 fps)")
    p.set_defaults(run=run)


def sheet_frames(frames: int, fps: float, every: int | None = None) -> list[int]:
    """The frames a contact sheet shows: every `every`th, or by default SHEET_FIGURES of them
    SHEET_SPACING seconds apart (figures a stride apart all look alike: the walk seems frozen;
    a tenth of a second apart they show the gait)."""
    step = every or max(1, int(round(fps * SHEET_SPACING)))
    return list(range(0, frames, step))[: None if every else SHEET_FIGURES]


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".gif"):
        raise UserError(f"--out {out}: give a .png (contact sheet) or a .gif (animation)")
    check_output(out, args.force, inputs=(args.bvh,))
    # numpy, numba (the skeleton's kinematics) and matplotlib: loaded when run, not for --help
    import numpy as np

    from ..motion.bvh import read_bvh
    from ..motion.kinematics import world_positions
    from ..motion.upright import upright_take
    from ..output.drawing import bone_colours, draw_framed, drawn_parents, pyplot, side_projection

    motion, _ = upright_take(read_bvh(args.bvh))  # drawn standing whatever axis was up (a Z-up capture lay flat)
    plt = pyplot("Agg")
    positions = world_positions(motion)
    parents = drawn_parents(motion.skeleton.parents, positions)
    path = positions[-1].mean(axis=0) - positions[0].mean(axis=0)
    points = side_projection(positions, path if np.linalg.norm(path[[0, 2]]) > 1e-6 else np.array([0.0, 0.0, 1.0]))
    height = np.ptp(points[..., 1]) or 1.0
    low, high = points[..., 1].min() - 0.05 * height, points[..., 1].max() + 0.05 * height
    colours = bone_colours(motion.skeleton.names)  # left limbs blue, right red
    if out.suffix.lower() == ".png":
        frames = sheet_frames(motion.frames, motion.fps, args.every)
        columns = min(6, len(frames))
        rows = (len(frames) + columns - 1) // columns
        fig, axes = plt.subplots(rows, columns, figsize=(2 * columns, 3 * rows), squeeze=False)
        for ax in axes.ravel():
            ax.axis("off")
        for ax, f in zip(axes.ravel(), frames):
            draw_framed(ax, points[f], parents, low, high, 0.5 * height, colours)
            ax.set_title(f"{f / motion.fps:.2f} s", fontsize=8)
        fig.tight_layout()
        with written(out) as part:
            fig.savefig(part, dpi=80, format="png")
    else:
        from matplotlib.animation import FuncAnimation, PillowWriter

        every = args.every or max(1, int(round(motion.fps / 15)))
        frames = list(range(0, motion.frames, every))
        fig, ax = plt.subplots(figsize=(4, 4))

        def draw(f):
            ax.clear()
            draw_framed(ax, points[f], parents, low, high, 0.6 * height, colours)

        with written(out) as part:  # Pillow picks the format by the file name: give it one ending .gif
            gif = part.with_name(part.name + ".gif")
            FuncAnimation(fig, draw, frames=frames).save(gif, writer=PillowWriter(fps=motion.fps / every))
            gif.replace(part)
    plt.close("all")
    print(f"wrote {out}", file=sys.stderr)
    return 0
