"""Quality of the style models on takes they never saw."""

from instrument.training.build import build_model
from instrument.training.corpus import DEFAULT_STYLE_PATTERN, style_from_name
from instrument.evaluation.heldout import heldout_table, own_style_wins, split_holdout


def test_each_style_model_explains_its_own_held_out_takes_best(real_walks):
    pairs = [(p, style_from_name(p, DEFAULT_STYLE_PATTERN)) for p in real_walks]
    train, held = split_holdout(pairs)
    assert {s for _, s in held} == {s for _, s in pairs}
    assert not set(train) & set(held)
    model, _, _ = build_model(train)
    wins = own_style_wins(heldout_table(model, held))
    assert sum(beats_average for beats_average, _ in wins.values()) >= 5, wins
    assert sum(beats_others for _, beats_others in wins.values()) >= 5, wins
