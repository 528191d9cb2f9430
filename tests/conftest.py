"""Shared test fixtures: the shipped model, where the real motion capture lives, and how to skip without it."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_WALKS = Path(os.environ.get("INSTRUMENT_WALKS", REPO.parent / "shared" / "data" / "bandai-walk"))
sys.path.insert(0, str(Path(__file__).parent))
# `instrument` is this checkout's package, in the tests and in every command they start, whatever
# the folder pytest was started from: from a clone's parent (a clone in a folder named `instrument`),
# Python would otherwise take the clone's folder for a namespace package of that name and find no code
sys.path.insert(0, str(REPO))
os.environ["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep)
                                                          if p and Path(p).resolve() != REPO])


def play_mapped(mapper, state, event) -> bool:
    """A raw event through a mapping's `Mapper` and then the hub's one check-and-apply path, as a
    device's decoder plays it (control/kinds.py MappedDecoder); False if the mapping does not use it."""
    from instrument.control.hub import ControlHub

    targets = mapper.decode(state, event)
    hub = ControlHub([mapper.mapping], mapper.presets)
    for target in targets or []:
        hub.apply_target(state, target)
    return targets is not None


def walk_files() -> list[Path]:
    return sorted(SHARED_WALKS.glob("*.bvh")) if SHARED_WALKS.is_dir() else []


needs_walks = pytest.mark.skipif(not walk_files(), reason=f"real walks not found in {SHARED_WALKS}")


@pytest.fixture(scope="session")
def model():
    """The shipped default model (plain data: no test changes it)."""
    from instrument.models.modelfile import default_model_path, load_model

    return load_model(default_model_path())


def walk_only(model):
    """The shipped model with its walk's two steps only: a model trained on walks (no run, stand,
    turning steps or gestures), as tests of what such a model does need one."""
    from dataclasses import replace

    from instrument.models.hsmm import HSMM

    return replace(model, metadata={k: v for k, v in model.metadata.items() if k not in ("units", "gestures")}
                   | {"labels": ["right", "left"]},
                   average=HSMM(*(getattr(model.average, p)[:2] for p in HSMM.__dataclass_fields__)),
                   styles=HSMM(*(getattr(model.styles, p)[:, :2] for p in HSMM.__dataclass_fields__)),
                   extras={k: (v[..., :2, :, :] if k.startswith("contact") else v) for k, v in model.extras.items()})


@pytest.fixture(scope="session")
def space(model):
    """The shipped model's style space."""
    from instrument.synthesis.interpolation import style_space

    return style_space(model)


@pytest.fixture(scope="session")
def real_walks() -> list[Path]:
    files = walk_files()
    if not files:
        pytest.skip(f"real walks not found in {SHARED_WALKS}")
    return files


@pytest.fixture(scope="session")
def toe_less(real_walks, tmp_path_factory) -> tuple[Path, Path]:
    """Two takes each of the shared active and elderly walks with their toe joints dropped (each
    foot ends in an End Site where the toes began, as many CMU conversions and some suits do:
    examples/odd_inputs.py's `no-toes`) and the model `instrument train` makes of them: (the
    takes' folder, the model file)."""
    import subprocess

    sys.path.insert(0, str(REPO / "examples"))
    from other_rigs import Rig, build_set, chosen_takes

    folder = tmp_path_factory.mktemp("toe-less")
    takes, model = folder / "takes", folder / "model.npz"
    build_set(chosen_takes(real_walks[0].parent, ["active", "elderly"], 2),
              Rig(30.0, 1.0, "ZXY", keep_root=False, drop=("Toes_L", "Toes_R")), takes)
    trained = subprocess.run([sys.executable, "-m", "instrument", "train", str(takes), "--out", str(model), "--quiet"],
                             capture_output=True, text=True, timeout=1800)
    assert trained.returncode == 0, trained.stderr
    return takes, model


@pytest.fixture(scope="session")
def jack():
    """A JACK server with the dummy driver (real MIDI without a sound card), started if needed."""
    import shutil
    import subprocess
    import time

    if shutil.which("jackd") is None:
        pytest.skip("JACK is not installed (apt-get install jackd2)")
    os.environ["JACK_NO_START_SERVER"] = "1"
    import mido

    backend = mido.Backend("mido.backends.rtmidi/UNIX_JACK", load=True)

    def running() -> bool:
        try:
            backend.get_input_names()
            probe = backend.open_output("instrument-probe", virtual=True)
            probe.close()
            return True
        except Exception:
            return False

    server = None
    if not running():
        server = subprocess.Popen(["jackd", "--no-realtime", "-d", "dummy", "-r", "48000", "-p", "256"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(50):
            time.sleep(0.1)
            if running():
                break
        else:
            server.kill()
            pytest.skip("the JACK server did not start")
    yield backend
    if server is not None:
        server.terminate()
        server.wait(10)
