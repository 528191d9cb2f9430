"""The motion units a model may hold, in the order a model stores them.

Each unit has a right and a left step's labels (label = 2 * unit + foot; a stand's "steps" are
pieces of still standing, motion/standing.py). A model trained on walks alone holds only "walk"
(and its metadata may not even say so: `Model.units`).
"""

UNITS = ("walk", "run", "turn-left", "turn-right", "stand")
