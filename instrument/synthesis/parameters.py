"""What a performer can ask of the synthesizer and a crowd, as plain names and numbers (no numpy).

The control table (control/targets.py) and the command line's option table (control/options.py)
name these; keeping them here, apart from the code that uses them, lets those tables load in a
few milliseconds (`instrument COMMAND --help` imports no numpy, scipy or numba).
"""

# the body-part groups a style can be weighted by, one by one (synthesis/interpolation.py
# derives each group's feature dimensions from the skeleton)
GROUPS = ("root", "legs", "upper")

# the gaits a performer chooses between (the `gait` target's values 0, 1, 2), each played by the
# model's unit of that name (a model without a unit plays its walk; synthesis/units.py)
GAITS = ("stand", "walk", "run")

# the gestures a performer can start (the `gesture/<gesture>` targets), layered on the gait's upper
# body when the model has them (defined with the model's format: models/gestures.py; synthesis/gestures.py)
from ..models.units import GESTURES  # noqa: E402,F401

# how far the step rate goes, relative to the model's (synthesis/durations.py)
MIN_SPEED, MAX_SPEED = 0.25, 4.0

# frames the streaming MLPG looks ahead at 30 fps: one stride (two steps); see docs/method.md for the
# trade-off. It is a time (1.07 s): as many of a model's frames as last as long (`default_lookahead`)
DEFAULT_LOOKAHEAD = 32


def default_lookahead(fps: float) -> int:
    """The look-ahead in frames of a model at `fps`: DEFAULT_LOOKAHEAD's 1.07 s. Counted in frames,
    a 120 fps walk looked 0.27 s ahead and strayed from the whole walk's MLPG as a 30 fps one with
    8 frames does (the worst feature 3.7% of its spread against 0.007%; docs/evaluate.md)."""
    return max(1, round(DEFAULT_LOOKAHEAD * fps / 30.0))  # motion.features.REFERENCE_FPS (not imported: no numpy here)

# a crowd (synthesis/engine.py): metres between neighbours on the floor, and how many characters a
# VMC target sends unless asked (a VMC stream costs several times a character's walk)
DEFAULT_SPACING = 1.5
DEFAULT_VMC_CHARACTERS = 16
