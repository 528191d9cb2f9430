"""Property-based fuzzing of the model loader (Hypothesis): the shipped model's metadata and
arrays, mutated, either load into a model the engine walks with finite poses, or are refused with
one line naming the file (instrument.errors.UserError); never another exception."""

from __future__ import annotations

import copy
import json
import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from instrument.errors import UserError
from instrument.models.modelfile import default_model_path, load_model
from instrument.synthesis.engine import Engine, default_controls

SHIPPED = np.load(default_model_path(), allow_pickle=False)
ARRAYS = {name: SHIPPED[name] for name in SHIPPED.files}
METADATA = json.loads(str(ARRAYS["metadata"]))
EXAMPLES = int(os.environ.get("INSTRUMENT_FUZZ_EXAMPLES", "60"))

ODD_VALUES = st.sampled_from([None, 0, -1, 1e308, float("nan"), float("inf"), "", "walk", [], {}, [1, 2], {"a": 1},
                              10 ** 400, True, "\U0001F3B5" * 50, [[0.0]] * 3])


def paths(value, prefix=()):
    """Every key path into a JSON value (dicts and lists)."""
    yield prefix
    if isinstance(value, dict):
        for key, inner in value.items():
            yield from paths(inner, prefix + (key,))
    elif isinstance(value, list):
        for k, inner in enumerate(value[:4]):
            yield from paths(inner, prefix + (k,))


METADATA_PATHS = [p for p in paths(METADATA) if p]


@st.composite
def mutated_models(draw):
    metadata = copy.deepcopy(METADATA)
    arrays = dict(ARRAYS)
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["set", "drop", "array"]))
        if kind == "array":
            name = draw(st.sampled_from(sorted(n for n in ARRAYS if n != "metadata")))
            change = draw(st.sampled_from(["scale", "nan", "shape", "int", "empty"]))
            a = arrays[name]
            arrays[name] = {"scale": lambda: a * draw(st.sampled_from([1e7, -1e7, 1e-300, 0.0])),
                            "nan": lambda: np.where(np.arange(a.size).reshape(a.shape) == 0, np.nan, a),
                            "shape": lambda: a.reshape(-1)[: max(a.size - 1, 0)],
                            "int": lambda: np.nan_to_num(a).astype(np.int64) if a.dtype.kind == "f" else a,
                            "empty": lambda: np.zeros((0,))}[change]()
            continue
        path = draw(st.sampled_from(METADATA_PATHS))
        parent = metadata
        try:
            for key in path[:-1]:
                parent = parent[key]
            if kind == "drop" and isinstance(parent, dict):
                parent.pop(path[-1], None)
            else:
                parent[path[-1]] = draw(ODD_VALUES)
        except (KeyError, IndexError, TypeError):  # an earlier mutation changed the way there
            pass
    return metadata, arrays


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(mutated_models())
def test_a_mutated_model_loads_and_walks_or_is_one_line(model_parts):
    metadata, arrays = model_parts
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mutated.npz"
        try:
            text = json.dumps(metadata)
        except ValueError:  # e.g. an integer JSON cannot write: the file can't hold it either
            return
        np.savez(path, **arrays | {"metadata": np.array(text)})
        try:
            model = load_model(path)
        except UserError as error:
            message = str(error)
            assert len(message.splitlines()) == 1 and str(path) in message, message
            return
        # accepted: it must be a model the engine walks with
        engine = Engine(model)
        controls = default_controls(model, {model.style_names[0]: 1.0})
        for k in range(5):
            pose = engine.frame(k / engine.fps, controls)
        assert np.isfinite(pose.world_positions).all()


def test_a_metadata_number_too_large_for_a_float_is_one_line(tmp_path):
    """JSON holds whole numbers of any size; numpy's isfinite cannot take one past 2**64 (the
    fuzzer's find, a TypeError from the loader): such a frame rate is refused in one line."""
    path = tmp_path / "huge.npz"
    np.savez(path, **ARRAYS | {"metadata": np.array(json.dumps(METADATA | {"fps": 10 ** 400}))})
    try:
        load_model(path)
    except UserError as error:
        assert len(str(error).splitlines()) == 1 and "'fps'" in str(error) and str(path) in str(error)
    else:
        raise AssertionError("a frame rate of 10**400 was accepted")
