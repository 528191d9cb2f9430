"""Model files: one .npz of plain arrays plus a JSON metadata entry; no pickle anywhere.

Arrays:
    average_means, average_variances            (labels, states, 3D)
    average_duration_means, average_duration_variances   (labels, states)
    style_means, style_variances                (styles, labels, states, 3D)
    style_duration_means, style_duration_variances       (styles, labels, states)
    static_std                                  (D,) standard deviation of each static feature in the data
    static_step_max                             (D,) largest frame-to-frame change of each static feature in the data
    contact_average, contact_styles             optional (synthesis/contact.py): share of frames with each foot
                                                planted per (label, state), (labels, states, 2) and (styles, ...)
    range_average, range_styles                 optional (synthesis/widen.py): the log ratio of each static
                                                feature's range in the data to that in a made walk, (D,) and (styles, D)
    metadata                                    a 0-d string array holding JSON
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..motion.bvh import Skeleton
from ..motion.features import FeatureLayout
from ..models.units import UNITS
from ..motion.gestures import PHASES
from ..outputfile import written
from ..shipped import default_model_path  # noqa: F401  (re-exported: where the default model is)
from .hsmm import HSMM

FORMAT = "instrument-style-model"
FORMAT_VERSION = 1
PARAMETERS = ("means", "variances", "duration_means", "duration_variances")
LARGEST = 1e6  # no mean, duration or deviation of a trained walk comes near this (the shipped model's largest: 142)
OPTIONAL = ("contact_average", "contact_styles", "range_average", "range_styles")  # arrays a model may hold; their users check their shapes


@dataclass(frozen=True)
class Model:
    """The average model, the style models stacked on a leading axis, and what describes them."""

    metadata: dict
    average: HSMM
    styles: HSMM  # each array has a leading axis over metadata["styles"]
    static_std: np.ndarray
    static_step_max: np.ndarray
    extras: dict = field(default_factory=dict)  # optional arrays (contact statistics); a model without them runs as before

    @property
    def style_names(self) -> list[str]:
        return list(self.metadata["styles"])

    @property
    def labels(self) -> list[str]:
        return list(self.metadata["labels"])

    @property
    def units(self) -> list[str]:
        """The motion units, in label order (label = 2 * unit + foot); a model without the entry
        was trained on walks alone."""
        return list(self.metadata.get("units", ["walk"]))

    @property
    def states(self) -> int:
        return int(self.metadata["states"])

    @property
    def fps(self) -> float:
        return float(self.metadata["fps"])

    @property
    def layout(self) -> FeatureLayout:
        return FeatureLayout.from_dict(Skeleton.from_dict(self.metadata["skeleton"]), self.metadata["features"])

    def style(self, name: str) -> HSMM:
        k = self.style_names.index(name)
        return HSMM(*(getattr(self.styles, p)[k] for p in PARAMETERS))


def save_model(path: str | Path, model: Model) -> None:
    """Write atomically, so an interrupted save never leaves a broken model in place."""
    path = Path(path)
    arrays = {f"average_{p}": getattr(model.average, p) for p in PARAMETERS}
    arrays |= {f"style_{p}": getattr(model.styles, p) for p in PARAMETERS}
    arrays["static_std"] = model.static_std
    arrays["static_step_max"] = model.static_step_max
    arrays |= {name: np.asarray(value) for name, value in model.extras.items() if name in OPTIONAL}
    metadata = dict(model.metadata, format=FORMAT, format_version=FORMAT_VERSION)
    arrays["metadata"] = np.array(json.dumps(metadata, indent=1))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{path}: cannot write: {e.strerror or e}") from None
    with written(path) as part, open(part, "wb") as f:  # a failed write leaves no PATH.part behind
        np.savez_compressed(f, **arrays)


def load_model(path: str | Path) -> Model:
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{path}: is a folder, not a model file")
    if not path.is_file():
        raise UserError(f"{path}: no such model file")
    try:  # (is_zipfile calls a file it cannot read "not a zip file")
        with open(path, "rb") as f:
            f.read(4)
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e.strerror or e}") from None
    if not zipfile.is_zipfile(path):
        raise UserError(f"{path}: not a model file (a model is an .npz archive, as `instrument train` writes)")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as e:
        raise UserError(f"{path}: not a readable model file ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else 'corrupt'})") from None
    if "metadata" not in arrays:
        raise UserError(f"{path}: not a model file (no metadata entry)")
    try:
        metadata = json.loads(str(arrays["metadata"]))
    except json.JSONDecodeError as e:
        raise UserError(f"{path}: metadata is not valid JSON ({e.msg})") from None
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT:
        raise UserError(f"{path}: not an instrument style model")
    if metadata.get("format_version") != FORMAT_VERSION:
        raise UserError(f"{path}: model format version {metadata.get('format_version')} is not supported (this instrument reads {FORMAT_VERSION})")
    _check_metadata(path, metadata)
    _check_shapes(path, metadata, arrays)
    average = HSMM(*(arrays[f"average_{p}"] for p in PARAMETERS))
    styles = HSMM(*(arrays[f"style_{p}"] for p in PARAMETERS))
    extras = {name: arrays[name] for name in OPTIONAL if name in arrays and np.isfinite(arrays[name]).all()}
    return Model(metadata, average, styles, arrays["static_std"], arrays["static_step_max"], extras)


CHANNELS = {f"{axis}{kind}" for axis in "XYZ" for kind in ("rotation", "position")}


def _check_metadata(path: Path, metadata: dict) -> None:
    """Every metadata entry a command reads has the type it needs, so a model broken by hand or
    by another program is one line naming the entry, never a traceback in `info`, `run` or `skeleton`."""
    def broken(key: str, expected: str) -> UserError:
        shown = json.dumps(metadata.get(key))
        return UserError(f"{path}: metadata {key!r}: expected {expected}, not {shown[:60]}{'...' if len(shown) > 60 else ''}")

    def number(value) -> bool:  # a whole number of any size (JSON's), or a finite real one
        return (isinstance(value, int) and not isinstance(value, bool)) or (isinstance(value, float) and math.isfinite(value))

    for key in ("fps", "states", "labels", "styles", "skeleton", "features"):
        if key not in metadata:
            raise UserError(f"{path}: metadata lacks {key!r}")
    if not number(metadata["fps"]) or not 1 <= metadata["fps"] <= 1000:
        raise broken("fps", "a frame rate from 1 to 1000")
    if not isinstance(metadata["states"], int) or isinstance(metadata["states"], bool) or metadata["states"] < 1:
        raise broken("states", "a whole number of at least 1")
    for key in ("labels", "styles"):
        names = metadata[key]
        if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names) or len(set(names)) < len(names):
            raise broken(key, "a list of different names")
    if any("/" in name for name in metadata["styles"]):  # style/old/man would be no style's target (training refuses more)
        raise broken("styles", "names without '/' (each is the control target style/<name>)")
    try:
        skeleton = Skeleton.from_dict(metadata["skeleton"])
        layout = FeatureLayout.from_dict(skeleton, metadata["features"])
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as e:
        raise UserError(f"{path}: metadata 'skeleton' or 'features' is broken ({type(e).__name__}: {e})") from None
    for k, joint in enumerate(skeleton.joints):
        if not (joint.parent == -1 if k == 0 else 0 <= joint.parent < k) or not set(joint.channels) <= CHANNELS:
            raise UserError(f"{path}: metadata 'skeleton': joint {k} ({joint.name}) has a parent or channels no skeleton has")
    if len(layout.template) != sum(len(j.channels) for j in skeleton.joints) or not all(map(number, layout.template)):
        raise UserError(f"{path}: metadata 'features': the template pose does not fit the skeleton's channels")
    names = metadata["features"].get("names")
    if not isinstance(names, list) or len(names) != layout.dimension:
        raise UserError(f"{path}: metadata 'features': 'names' does not list the {layout.dimension} features of its joints")
    if "units" in metadata:
        units = metadata["units"]
        if not isinstance(units, list) or not units or not all(isinstance(u, str) for u in units) \
                or units[0] != "walk" or not set(units) <= set(UNITS) or len(set(units)) < len(units) \
                or 2 * len(units) + _gesture_label_count(path, metadata) != len(metadata["labels"]):
            raise broken("units", f"a list of different units, the walk first, of {', '.join(UNITS)}, two labels each "
                         "(and the gestures' after them)")
    elif len(metadata["labels"]) != 2 + _gesture_label_count(path, metadata):
        raise broken("labels", "a right and a left step (a model of more labels names its units)")
    optional = {  # entries `info` and the synthesis read when they are there
        "data": (lambda v: isinstance(v, list) and all(isinstance(d, dict) and isinstance(d.get("frames"), int)
                                                         and all(isinstance(d.get(key, ""), str) for key in ("file", "style", "unit", "gesture"))
                                                         for d in v),
                 "a list of takes, each with its file, style and frames (and its unit and gesture, as text)"),
        "mean_step_frames": (lambda v: isinstance(v, dict) and all(map(number, v.values())), "a table of numbers"),
        "training": (lambda v: isinstance(v, dict), "a table"),
        "contact": (lambda v: isinstance(v, dict) and _numbers_2d(v.get("clearance", [[0.0]]))
                    and number(v.get("tip_clearance", 0.0)),
                    "a table whose clearance is rows of numbers and tip_clearance a number"),
        "licence": (lambda v: isinstance(v, str), "a text"),
        "attribution": (lambda v: isinstance(v, str), "a text"),
    }
    for key, (fits, expected) in optional.items():
        if key in metadata and not fits(metadata[key]):
            raise broken(key, expected)


def _gesture_label_count(path: Path, metadata: dict) -> int:
    """How many labels the "gestures" entry gives (models/gestures.py), each gesture's right after
    the units' and the last gesture's; an entry that does not fit is one line naming it."""
    entry = metadata.get("gestures")
    if entry is None:
        return 0
    first = 2 * len(metadata.get("units", ["walk"]))
    if not isinstance(entry, dict) or not all(
            isinstance(g, dict) and g.get("first") == first + len(PHASES) * k and isinstance(g.get("repeats", 2), int)
            and g.get("repeats", 2) >= 1 for k, g in enumerate(entry.values())):
        raise UserError(f"{path}: metadata 'gestures': expected each gesture's first label, {len(PHASES)} labels apart "
                        f"after the units' {first}, and its repeats")
    return len(PHASES) * len(entry)


def _numbers_2d(value) -> bool:
    """True for rows of finite numbers, all as long (a table numpy reads as a 2-D float array)."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return array.ndim == 2 and bool(np.isfinite(array).all())


def _check_shapes(path: Path, metadata: dict, arrays: dict) -> None:
    try:
        labels, states, styles = len(metadata["labels"]), int(metadata["states"]), len(metadata["styles"])
        static = len(metadata["features"]["names"])
    except (KeyError, TypeError, ValueError) as e:
        raise UserError(f"{path}: metadata lacks {e}") from None
    expected = {
        "average_means": (labels, states, 3 * static),
        "average_variances": (labels, states, 3 * static),
        "average_duration_means": (labels, states),
        "average_duration_variances": (labels, states),
        "style_means": (styles, labels, states, 3 * static),
        "style_variances": (styles, labels, states, 3 * static),
        "style_duration_means": (styles, labels, states),
        "style_duration_variances": (styles, labels, states),
        "static_std": (static,),
        "static_step_max": (static,),
    }
    for name, shape in expected.items():
        if name not in arrays:
            raise UserError(f"{path}: array {name!r} is missing")
        if arrays[name].shape != shape or arrays[name].dtype.kind != "f":
            raise UserError(f"{path}: array {name!r} has shape {arrays[name].shape}, the metadata says {shape}")
        if not np.isfinite(arrays[name]).all():
            raise UserError(f"{path}: array {name!r} holds values that are not finite")
        limit = LARGEST ** 2 if "variances" in name else LARGEST
        if np.abs(arrays[name]).max(initial=0.0) > limit:
            raise UserError(f"{path}: array {name!r} holds values beyond {limit:g}, far past any walk's angles, "
                            "distances or durations (the synthesis would overflow): not a trained model")
    for name in ("average_variances", "style_variances", "average_duration_variances", "style_duration_variances"):
        if (arrays[name] <= 0).any():
            raise UserError(f"{path}: array {name!r} holds variances that are not positive")

