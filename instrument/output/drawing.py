"""Stick figures with matplotlib (an optional extra: pip install 'instrument[view]')."""

from __future__ import annotations

import re

import numpy as np

from ..errors import UserError


def pyplot(backend: str | None = None):
    """matplotlib.pyplot, or a one-line error saying how to install it."""
    try:
        import matplotlib

        if backend:
            matplotlib.use(backend)
        import matplotlib.pyplot as plt
    except ImportError:
        raise UserError("drawing needs matplotlib: pip install 'instrument[view]' (or pip install matplotlib)") from None
    return plt


def side_projection(positions: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(..., J, 2): distance along `direction` (horizontal) and height, for a side view."""
    d = np.array([direction[0], 0.0, direction[2]])
    d = d / (np.linalg.norm(d) or 1.0)
    return np.stack([positions @ d, positions[..., 1]], axis=-1)


def drawn_parents(parents: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Parents for drawing: a top joint that never moves (a ground-level origin such as
    joint_Root) is not joined to the walking body it would trail a line to."""
    parents = np.array(parents)
    for top in np.flatnonzero(parents < 0):
        if np.ptp(positions[:, top], axis=0).max() < 1e-6:
            parents[parents == top] = -1
    return parents


SIDE_COLOURS = {"left": "tab:blue", "right": "tab:red", "": "black"}
_WORDS = re.compile(r"[^A-Za-z]+|(?<=[a-z])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])")  # UpperLeg_L, lHand, LHip


def side_of(name: str) -> str:
    """"left", "right" or "" (the middle) from a joint name: LeftFoot, UpperLeg_L, l_hip, lHand, LHip."""
    lower = name.lower()
    if "left" in lower or "right" in lower:
        return "left" if "left" in lower else "right"
    words = {w.lower() for w in _WORDS.split(name)}
    return "left" if "l" in words else "right" if "r" in words else ""


def bone_colours(names: list[str]) -> list[str]:
    """Each joint's bone colour (the bone from its parent): left blue, right red, middle black."""
    return [SIDE_COLOURS[side_of(n)] for n in names]


def draw_framed(ax, points: np.ndarray, parents: np.ndarray, low: float, high: float, half_width: float,
                colours: list[str] | None = None) -> None:
    """A stick figure centred across the axes, heights from `low` to `high`, no axis lines."""
    ax.axis("off")
    draw_figure(ax, points, parents, colours)
    centre = points[:, 0].mean()
    ax.set_xlim(centre - half_width, centre + half_width)
    ax.set_ylim(low, high)
    ax.set_aspect("equal")


def draw_figure(ax, points: np.ndarray, parents: np.ndarray, colours: list[str] | None = None) -> None:
    for j, p in enumerate(parents):
        if p >= 0:
            colour = colours[j] if colours else "black"
            ax.plot(points[[p, j], 0], points[[p, j], 1], color=colour, linewidth=2, solid_capstyle="round")
