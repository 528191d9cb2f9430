"""Measuring models and their walks, apart from what plays live (docs/extending.md#layers).

assessment.py   `instrument evaluate`: walks for a set of style weightings measured as the real takes are
heldout.py      held-out likelihood: how well each model explains takes it was not trained on
recognition.py  a style classifier on per-step features, trained on real takes
"""
