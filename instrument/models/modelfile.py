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
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..motion.bvh import Skeleton
from ..motion.features import FeatureLayout
from ..shipped import default_model_path  # noqa: F401  (re-exported: where the default model is)
from .hsmm import HSMM

FORMAT = "instrument-style-model"
FORMAT_VERSION = 1
PARAMETERS = ("means", "variances", "duration_means", "duration_variances")
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
    tmp = path.with_name(path.name + ".part")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)
        tmp.replace(path)
    except OSError as e:
        raise UserError(f"{path}: cannot write: {e.strerror or e}") from None


def load_model(path: str | Path) -> Model:
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: no such model file")
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
    _check_shapes(path, metadata, arrays)
    average = HSMM(*(arrays[f"average_{p}"] for p in PARAMETERS))
    styles = HSMM(*(arrays[f"style_{p}"] for p in PARAMETERS))
    extras = {name: arrays[name] for name in OPTIONAL if name in arrays and np.isfinite(arrays[name]).all()}
    return Model(metadata, average, styles, arrays["static_std"], arrays["static_step_max"], extras)


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
    for name in ("average_variances", "style_variances", "average_duration_variances", "style_duration_variances"):
        if (arrays[name] <= 0).any():
            raise UserError(f"{path}: array {name!r} holds variances that are not positive")

