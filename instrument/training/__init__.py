"""Making a model from takes (`instrument train`), apart from what plays live (docs/extending.md#layers).

corpus.py      BVH takes with their styles, turned into labelled observation segments
average.py     the average model (lambda 0) by EM on every style at once
adaptation.py  each style model adapted from the average one
symmetry.py    the right and left step models made mirror images (a straight walk at turn 0)
contact.py     which foot is planted in each state (the foot lock's statistics)
widen.py       how far each feature's swing must be scaled (the range filter's factors, measured on the engine's walks)
build.py       all of it in order: from takes to a complete Model
"""
