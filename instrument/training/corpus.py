"""A training corpus: BVH takes with their styles, turned into labelled observation segments."""

from __future__ import annotations

import csv
import hashlib
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from ..errors import UserError, located, quoted
from ..motion.bvh import OTHER_CAPTURE_SUFFIXES, Motion, Skeleton, read_bvh
from ..motion.features import FeatureLayout, choose_layout, extract, resample, with_deltas
from ..motion.kinematics import local_transforms
from ..motion.limbs import find_limbs
from ..motion.gestures import gesture_phases
from ..motion.standing import standing_steps
from ..motion.steps import LABELS, segment_steps
from ..motion.upright import upright
from ..models.units import GESTURES, UNITS
from ..textfile import read_text
from ..tomlfile import TomlFile
from .units import checked_gesture, checked_unit, gesture_from_name, take_gesture, turn_as_taken, unit_from_name

# the last but one "_"-separated part, starting with a letter: dataset-2_walk_elderly_003 -> elderly,
# walk_not-confident_001 -> not-confident, style2_take3 -> style2
DEFAULT_STYLE_PATTERN = r"(?:^|_)([A-Za-z][A-Za-z0-9-]*)_[^_]*$"
# a style's name is part of control targets (`style/<name>`, `part/<name>/legs`), of OSC addresses
# (`/walk/style/<name>`) and of synth's `--style NAME.PART=W`: a '/', '.', '=', space or OSC's
# pattern characters in it would make them name something else
STYLE_NAME = re.compile(r"[\w-]+")
# a manifest's columns (CSV) or a [[take]]'s keys (TOML); 'unit' may be left out or empty (a walk), and
# 'gesture' (a standing take's: wave, raise) too (read from the file's name)
MANIFEST_COLUMNS = ("file", "style", "unit", "gesture")


class TakeFile(NamedTuple):
    """A take to read: its file, its style, the motion unit it holds (walk, run, turn-left, ...)
    and a standing take's gesture ("": the one its file's name says, if any)."""

    path: Path
    style: str
    unit: str = "walk"
    gesture: str = ""


def take_files(pairs: Sequence[tuple]) -> list[TakeFile]:
    """(file, style), (file, style, unit) or (file, style, unit, gesture) tuples as TakeFiles (a pair is a walk)."""
    return [p if isinstance(p, TakeFile) else TakeFile(Path(p[0]), *p[1:]) for p in pairs]


@dataclass
class Take:
    path: Path
    style: str
    observations: np.ndarray  # (frames, 3 * D): [o, delta o, delta-delta o]
    steps: list  # Step objects, frame indices into `observations`
    sha256: str
    unit: str = "walk"  # the motion unit its steps are of (for a stand: pieces of still standing)
    gesture: str = ""  # a standing take's gesture (models/gestures.py), "" for none
    phases: list = field(default_factory=list)  # its gesture's phases (motion/gestures.py), as Steps

    @property
    def frames(self) -> int:
        return int(self.observations.shape[0])

    def segments(self, label: str) -> list[np.ndarray]:
        return [self.observations[s.start : s.end] for s in self.steps if s.label == label]


def style_from_name(path: Path, pattern: str) -> str:
    match = re.search(pattern, path.stem)
    if not match or not match.groups() or not match.group(1):
        raise UserError(f"{path}: cannot read a style from the name with the pattern {pattern!r} (give --style-from or a manifest)")
    return checked_style(f"{path}: --style-from", match.group(1).lower())


def checked_style(where: str, style: str) -> str:
    """A style read from a name or a manifest, or an error naming where: a style the live controls
    could not address (`old/man`, `Old Man`) is refused before any take is read."""
    if not STYLE_NAME.fullmatch(style):
        raise UserError(f"{where}: style {quoted(style)} is not a name of letters, digits, '-' and '_' "
                        "(it names the control target style/<name>)")
    return style


def bvh_files(paths: list[str] | list[Path]) -> list[Path]:
    """The BVH files named, and those inside the folders named (searched recursively, sorted); an
    error names a missing path or a folder without takes."""
    files: list[Path] = []
    for name in paths:
        path = Path(name)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.suffix.lower() == ".bvh" and p.is_file())
            if not found:
                raise UserError(f"{path}: no .bvh files in this folder{other_captures(path)}")
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            raise UserError(f"{path}: no such file or folder")
    return files


def other_captures(folder: Path) -> str:
    """" (it holds 2 .glb files: ...)" when a folder without BVH holds captures in another format, so
    a user who exported the wrong format learns it; "" otherwise."""
    kinds = sorted({p.suffix.lower() for p in folder.rglob("*")
                    if p.is_file() and p.suffix.lower() in OTHER_CAPTURE_SUFFIXES})
    if not kinds:
        return ""
    return f" (it holds {' and '.join(kinds)} files: export the takes as .bvh)"


def styled_takes(paths: list[str] | list[Path], pattern: str = DEFAULT_STYLE_PATTERN,
                 unit_pattern: str | None = None) -> list[TakeFile]:
    """Every BVH file named or inside the folders named, its style and unit read from its name
    (training/units.py: a walk unless the name says otherwise)."""
    takes = [TakeFile(f, style_from_name(f, pattern), unit_from_name(f, unit_pattern)) for f in bvh_files(paths)]
    # a stand's gesture from the part its unit was read in (--unit-from's group, training/units.py)
    return [t._replace(gesture=gesture_from_name(t.path, unit_pattern) or "") if t.unit == "stand" else t for t in takes]


def read_manifest(path: Path) -> list[TakeFile]:
    """Takes from a CSV (header `file,style`, optionally `,unit` and then `,gesture`) or TOML
    ([[take]] file = ..., style = ..., optionally unit = ..., gesture = ...); a take without a
    unit is a walk, a standing take without a gesture the one its file's name says (if any)."""
    base = path.parent
    pairs: list[TakeFile] = []
    lines: dict[Path, int] = {}  # each take's file -> the line that named it first

    def add(take: TakeFile, line: int) -> None:
        first = lines.setdefault(take.path.resolve(), line)
        if first != line:  # twice, a take would weigh double (or teach two styles the same steps)
            raise located(path, f"{quoted(take.path.name)}: named twice (line {first} too); give each take once", line)
        pairs.append(take)

    if path.suffix.lower() == ".toml":
        toml = TomlFile(path)
        unknown = sorted(set(toml.data) - {"take"})
        if unknown:  # [[takes]], [[Take]]: its takes were dropped unread
            raise UserError(f"{path}:{toml.line(unknown[0])}: unknown table or key {unknown[0]!r} "
                            "(a manifest holds [[take]] tables)")
        takes = toml.data.get("take")
        if not isinstance(takes, list) or not takes:
            raise UserError(f"{path}: expected [[take]] tables with keys 'file' and 'style'")
        for k, take in enumerate(takes):
            where = f"{path}:{toml.line('take', k)}: take {k + 1}"
            unknown = sorted(set(take) - set(MANIFEST_COLUMNS)) if isinstance(take, dict) else []
            if unknown:  # a misspelt 'unit' would train a run as a walk
                raise UserError(f"{path}:{toml.line('take', k, unknown[0])}: take {k + 1}: unknown key {unknown[0]!r} "
                                f"(a take has {', '.join(MANIFEST_COLUMNS)})")
            if not isinstance(take, dict) or not isinstance(take.get("file"), str) or not isinstance(take.get("style"), str) \
                    or not take["file"].strip() or not take["style"].strip():
                raise UserError(f"{where}: needs string keys 'file' and 'style', neither empty")
            unit, gesture = take.get("unit", ""), take.get("gesture", "")
            if not isinstance(unit, str):
                raise UserError(f"{path}:{toml.line('take', k, 'unit')}: take {k + 1}: 'unit' is a string ({', '.join(UNITS)})")
            if not isinstance(gesture, str):
                raise UserError(f"{path}:{toml.line('take', k, 'gesture')}: take {k + 1}: "
                                f"'gesture' is a string ({', '.join(GESTURES)})")
            at = {key: f"{path}:{toml.line('take', k, key)}: take {k + 1}" if key in take else where for key in ("unit", "gesture")}
            said, unit = bool(unit.strip()), checked_unit(at["unit"], unit)  # at the line of the key that says it
            add(TakeFile(_listed_file(base, take["file"], where), checked_style(where, take["style"]), unit,
                         checked_gesture(at["gesture"], gesture, unit, said)), toml.line("take", k))
        return pairs
    text = read_text(path)
    reader = csv.reader(text.splitlines())
    try:
        rows = list(reader)
    except csv.Error as e:  # a field longer than csv's limit (128 kB), a NUL byte
        raise located(path, f"not a CSV manifest: {e}", reader.line_num) from None
    header = [c.strip().lower() for c in rows[0]] if rows else []
    while header and not header[-1]:  # a spreadsheet's trailing empty columns
        header.pop()
    if header not in [list(MANIFEST_COLUMNS[:n]) for n in (2, 3, 4)]:
        # another column (`units`, a note) would be dropped unread: a run trained as a walk
        raise located(path, "a CSV manifest starts with the header 'file,style' (or 'file,style,unit', "
                            f"'file,style,unit,gesture'), not {quoted(','.join(rows[0]) if rows else '')}", 1)
    with_units, with_gestures = len(header) >= 3, len(header) == 4
    for number, row in enumerate(rows[1:], 2):
        if not row or not "".join(row).strip():
            continue
        if len(row) < 2 or not row[0].strip() or not row[1].strip():  # name what is missing
            lacking = f"{quoted(row[0].strip())}: no style" if row[0].strip() else "no file"
            raise located(path, f"{lacking}: each take is a line file,style (neither empty)", number)
        if len(row) > len(header) and "".join(row[len(header):]).strip():
            raise located(path, f"{len(row)} fields, but the header {quoted(','.join(rows[0]))} names {len(header)}", number)
        said = row[2].strip() if with_units and len(row) > 2 else ""
        unit = checked_unit(f"{path}:{number}", said)
        gesture = row[3].strip() if with_gestures and len(row) > 3 else ""
        add(TakeFile(_listed_file(base, row[0].strip(), f"{path}:{number}"),
                     checked_style(f"{path}:{number}", row[1].strip()), unit,
                     checked_gesture(f"{path}:{number}", gesture, unit, bool(said))), number)
    if not pairs:
        raise located(path, "a header and no takes: give a line file,style for each take", 1)
    return pairs


def _listed_file(base: Path, name: str, where: str) -> Path:
    """A manifest's take file (relative to the manifest's folder), refused at the line naming it
    when it is not there: a typo is found before any take is read, where it was written."""
    file = base / name
    try:
        there, folder = file.is_file(), file.is_dir()
    except (OSError, ValueError) as e:  # a name too long for the file system, a NUL byte
        raise UserError(f"{where}: {quoted(name)}: cannot read ({getattr(e, 'strerror', None) or e})") from None
    if not there:
        raise UserError(f"{where}: {quoted(name)}: " + ("a folder, not a BVH file" if folder else "no such file"))
    return file


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def skeleton_difference(expected: Skeleton, found: Skeleton) -> str:
    """What differs between two skeletons, in a few words for an error message."""
    missing = [n for n in expected.names if n not in found.names]
    extra = [n for n in found.names if n not in expected.names]
    if missing or extra:
        parts = ([f"lacks {', '.join(missing[:4])}" + (" ..." if len(missing) > 4 else "")] if missing else []) + (
            [f"has {', '.join(extra[:4])}" + (" ..." if len(extra) > 4 else "") + " instead"] if extra else [])
        return f"{len(found.names)} joints against {len(expected.names)}; it " + " and ".join(parts)
    for a, b in zip(expected.joints, found.joints):
        if (a.name, a.channels) != (b.name, b.channels) or expected.names[a.parent] != found.names[b.parent]:
            return (f"joint {a.name!r} differs in its parent, place or channels "
                    f"({' '.join(b.channels)} against {' '.join(a.channels)})")
    return "same joints"


UNITS_APART = 2.0  # a take this many times larger or smaller than the others is in other units
# a take this many times larger or smaller than the model's skeleton is another body: said (the
# model learns the hips' height and speeds in units, and plays every style on its one skeleton)
SIZES_APART = 1.1


def body_size(skeleton: Skeleton, channels: np.ndarray) -> float:
    """A typical bone's length in one frame (the median of the non-zero ones): which units a take
    is in, whatever its pose, its axes or how far from the origin it stands (a joint carrying the
    body's position is one outlier among many bones)."""
    lengths = np.linalg.norm(local_transforms(Motion(skeleton, channels[None], 30.0))[1][0], axis=1)
    lengths = lengths[lengths > 1e-9]
    return float(np.median(lengths)) if len(lengths) else 0.0


def _units_problem(size: float, reference: float) -> str | None:
    if reference > 0 and size > 0 and not 1 / UNITS_APART < size / reference < UNITS_APART:
        return f"its bones are {size / reference:.3g} times as long as those of"
    return None


def read_motions(pairs: Sequence[tuple], fps: float, progress=None) -> list[Motion]:
    """Read and resample every take; an error names the files whose skeleton differs from the
    first, or whose body is of another size than the others' (a take in other units)."""
    return read_motions_and_rates(pairs, fps, progress)[0]


def read_motions_and_rates(pairs: Sequence[tuple], fps: float, progress=None) -> tuple[list[Motion], list[float]]:
    """`read_motions`, and each take's frame rate as captured (training says where it is not
    the model's)."""
    pairs = take_files(pairs)
    if not pairs:
        raise UserError("no takes to read: no .bvh file was given")
    motions: list[Motion] = []
    rates: list[float] = []
    for k, (path, *_) in enumerate(pairs):
        if not path.is_file():
            raise UserError(f"{path}: no such file")
        captured = upright(read_bvh(path))[0]  # Y up, whatever the capture's axes
        rates.append(captured.fps)
        motions.append(resample(captured, fps))
        if progress:
            progress(k + 1, len(pairs), "reading")
    # the skeleton most takes share (the first such on a tie): an odd take sorted first named the others
    layouts = [m.skeleton.layout_key() for m in motions]
    counts = Counter(layouts)
    common = max(range(len(motions)), key=lambda k: (counts[layouts[k]], -k))
    first = motions[common].skeleton
    different = [(p.path, m) for p, m in zip(pairs, motions) if not m.skeleton.same_layout(first)]
    if different:
        shared = counts[layouts[common]]
        whose = "the first file's" if shared == 1 else f"that of {shared} of the {len(pairs)} takes"
        raise UserError(
            f"skeleton differs from {whose} ({pairs[common][0]}): {', '.join(str(p) for p, _ in different[:5])}"
            + (f" and {len(different) - 5} more" if len(different) > 5 else "")
            + f" ({different[0][0].name}: {skeleton_difference(first, different[0][1].skeleton)})"
        )
    sizes = [body_size(m.skeleton, m.channels[0]) for m in motions]
    typical = float(np.median(sizes))
    odd = [(p.path, _units_problem(size, typical)) for p, size in zip(pairs, sizes) if _units_problem(size, typical)]
    if odd:
        raise UserError(f"{odd[0][0]}: {odd[0][1]} the other takes' (in other units? metres among centimetres): "
                        "convert it or leave it out" + (f" ({len(odd) - 1} more such takes)" if len(odd) > 1 else ""))
    return motions, rates


def make_takes(pairs: Sequence[tuple], motions: list[Motion], layout: FeatureLayout, progress=None,
               states: int = 5) -> tuple[list[Take], list[str]]:
    """Observation vectors and steps of each motion (for a stand, its still pieces: standing.py);
    takes without steps are left out with a warning."""
    takes: list[Take] = []
    warnings: list[str] = []
    # per style, its standing takes' pieces so far, from 0 or 1 by turns (the label of its next piece,
    # standing.py): two styles of one single-piece take each still give the stand both labels
    stand_pieces: dict[str, int] = {}
    reference = body_size(layout.skeleton, np.asarray(layout.template))
    for k, ((path, style, unit, named), motion) in enumerate(zip(take_files(pairs), motions)):
        if not motion.skeleton.same_layout(layout.skeleton):
            raise UserError(f"{path}: the model was trained on another skeleton: this file's "
                            f"{skeleton_difference(layout.skeleton, motion.skeleton)}")
        size = body_size(motion.skeleton, motion.channels[0])
        problem = _units_problem(size, reference)
        if problem:
            raise UserError(f"{path}: {problem} the skeleton it is measured against (the model's, or the first "
                            "take's; in other units? metres against centimetres)")
        if reference > 0 and not 1 / SIZES_APART < size / reference < SIZES_APART:
            # measured: a style from a body 0.8 times the skeleton's walked with its hips 4.6% low, from 0.7 times
            # its feet slid 14.6 cm/s (others': 0.00)
            warnings.append(f"{path}: its body is {size / reference:.2f} times the size of the skeleton the model keeps "
                            "(the first walk's): its style's hips' height and speeds are learnt in the take's units and "
                            "played on that skeleton (hips low or high, strides that do not fit it); give one body size")
        static, _, _ = extract(motion, layout)
        if unit == "stand":
            first = stand_pieces.setdefault(style, len(stand_pieces) % 2)
            segmentation = standing_steps(motion, layout, states, first=first)
            stand_pieces[style] = first + len(segmentation.steps)
        else:
            segmentation = segment_steps(motion, layout)
        gesture = take_gesture(path, unit, named)
        phases = gesture_phases(motion, layout, states) if gesture else []
        warnings += [f"{path}: {w}" for w in segmentation.warnings]
        if not segmentation.steps and not phases:
            warnings.append(f"{path}: no steps, left out")
            continue
        unit, turned = turn_as_taken(unit, _step_frames(static, segmentation.steps)[:, layout.names.index("root.yaw_rate")],
                                     motion.fps)
        if turned:
            warnings.append(f"{path}: {turned}")
        if unit is None:
            continue
        takes.append(Take(path, style, with_deltas(static), segmentation.steps, _sha256(path), unit,
                          gesture or "", phases))
        if progress:
            progress(k + 1, len(pairs), "features")
    return takes, warnings


def _step_frames(static: np.ndarray, steps: list) -> np.ndarray:
    """The frames of `static` inside the steps (not the stretches segmentation dropped)."""
    return static[np.concatenate([np.arange(s.start, s.end) for s in steps])] if steps else static[:0]


def load_corpus(pairs: Sequence[tuple], fps: float, progress=None, states: int = 5
                ) -> tuple[FeatureLayout, list[Take], list[str], list[float]]:
    """Read, resample, check skeletons, choose the feature layout (from the walks: the template
    pose and the root's axes are a walker's), extract features and steps. Last, each file's
    frame rate as captured."""
    pairs = take_files(pairs)
    motions, rates = read_motions_and_rates(pairs, fps, progress)
    walks = [m for p, m in zip(pairs, motions) if p.unit == "walk"]
    layout = choose_layout(walks or motions)
    _check_feet(layout, pairs[0].path)
    takes, warnings = make_takes(pairs, motions, layout, progress, states)
    if not takes:  # the warnings are not printed on this path: the line carries the first file's reason
        reason = next((w for w in warnings if not w.endswith(": no steps, left out") and ": dropped " not in w), None)
        raise UserError("no steps found in any file: nothing to train on" + (f" (the first: {reason})" if reason else ""))
    kept = {t.style for t in takes}
    warnings += [f"style {style!r}: none of its takes has steps, so the model has no such style"
                 for style in sorted({p.style for p in pairs} - kept)]
    # a style without a unit the others have plays the average's there, moved only as its other units
    # are (said: a folder missing one style's runs trained without a word); a style without walks is
    # said by the adaptation (training/adaptation.py)
    warnings += [f"style {style!r}: no {unit} take, so its {unit} is the average's, moved only as its other units are"
                 for style in sorted(kept) for unit in UNITS if unit != "walk" and any(t.unit == unit for t in takes)
                 and not any(t.style == style and t.unit == unit for t in takes)]
    by_case: dict[str, list[str]] = {}
    for style in sorted(kept):  # a manifest keeps its styles' case, a file name's is read lower-cased
        by_case.setdefault(style.lower(), []).append(style)
    warnings += [f"styles {' and '.join(map(repr, same))} differ only in case: the model has them as "
                 f"{len(same)} styles" for same in by_case.values() if len(same) > 1]
    return layout, takes, warnings, rates


def _check_feet(layout: FeatureLayout, path: Path) -> None:
    """Both feet with the same joints, or a one-line error before training: the foot lock holds
    each foot by its own joints side by side (a skeleton with toes on one foot only was a
    traceback after the whole of training)."""
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    if limbs is None or len({len(foot) for foot in limbs.feet}) == 1:
        return
    names = [", ".join(layout.skeleton.joints[j].name for j in foot) for foot in limbs.feet]
    raise UserError(f"{path}: the feet have different joints ({names[0]} against {names[1]}): "
                    "give both feet the same joints (toes on both or on neither)")


def segments_by_label(takes: list[Take], states: int, units: Sequence[str] = ("walk",)) -> list[list[np.ndarray]]:
    """For each label (each unit's right and left step, label = 2 * unit + foot), the observation
    segments of its steps (those long enough for every state)."""
    return [[seg for take in takes if take.unit == unit for seg in take.segments(foot) if len(seg) >= states]
            for unit in units for foot in LABELS]
