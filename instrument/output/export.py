"""Writing a motion to a file: the format is the file's extension (.bvh or .glb).

One place decides what an output name means, so `synth --out` and `convert --out` accept the
same names and refuse the same mistakes (one line naming the file) before any work is done.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import UserError
from ..motion.bvh import Motion, write_bvh
from ..outputfile import written

FORMATS = {".bvh": "BVH", ".glb": "binary glTF 2.0"}


def motion_format(path: str | Path) -> str:
    """The extension of `path` (.bvh or .glb), or a one-line UserError naming it."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        choices = ", ".join(f"{s} ({name})" for s, name in FORMATS.items())
        raise UserError(f"{path}: unknown extension {Path(path).suffix or '(none)'!r}; write {choices}")
    return suffix


def write_motion(path: str | Path, motion: Motion) -> None:
    """Write `motion` as BVH or binary glTF by the extension of `path`, atomically."""
    if motion_format(path) == ".bvh":
        write_bvh(path, motion)
        return
    from .gltf import glb_bytes

    try:
        data = glb_bytes(motion)
    except UserError as e:
        raise UserError(f"{path}: {e}") from None
    with written(path) as part:
        part.write_bytes(data)
