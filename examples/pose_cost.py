"""Per-frame cost of the pose path (features to world pose, the feet planted), compiled against
the plain-Python path it replaced, in the same run (a benchmark, not a test).

    python examples/pose_cost.py [--characters 1 200] [--frames 100] [--repeat 5]

Before: tests/reference_lock.py (the Python foot lock and pose stream), one character after
another (timed on up to 3 characters and scaled to N: it costs the same per character). After: `CrowdPoses`, one compiled call a frame for all characters. Also the two ways
of batching restore_local and forward kinematics over N characters: numpy over N (a loop over
joints for the kinematics) against the numba kernels. The window solve of the streaming
generator is timed in the same run as the yardstick (`instrument bench`'s `window_solve_us`):
on a shared machine an absolute time moves, a ratio much less.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from instrument.cli.benchmarks import median_seconds
from instrument.models.modelfile import load_model
from instrument.motion.features import ROOT_FEATURES, FeatureLayout
from instrument.motion.kinematics import _compose
from instrument.motion.restore_frame import FrameRestorer
from instrument.motion.rotations import axis_angle_matrix, expmap_to_matrix
from instrument.synthesis.posing import CrowdPoses
from instrument.shipped import default_model_path
from instrument.synthesis.contact import contact_space
from instrument.synthesis.footlock import FootLock
from instrument.synthesis.interpolation import interpolate, style_space
from instrument.synthesis.mlpg import mlpg_continued
from instrument.synthesis.engine import walk_features
from instrument.synthesis.widen import without_range
from instrument.synthesis.parameters import default_lookahead
from instrument.synthesis.stream import Controls

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import reference_lock  # noqa: E402  (the oracle lives with the tests)


def restore_numpy(static: np.ndarray, layout: FeatureLayout, fps: float, positions: np.ndarray, headings: np.ndarray):
    """restore_local's arithmetic for one frame of N characters, vectorised over N with numpy."""
    count = static.shape[0]
    heading = axis_angle_matrix("y", headings)
    expmaps = np.zeros((count, 1 + len(layout.joints), 3))
    expmaps[:, 0, 0], expmaps[:, 0, 2] = static[:, 4], static[:, 5]
    expmaps[:, 1:] = static[:, len(ROOT_FEATURES):].reshape(count, len(layout.joints), 3)
    matrices = expmap_to_matrix(expmaps)
    template_rot, template_trans, parent_rot, parent_pos = layout.template_pose
    rotations = np.broadcast_to(template_rot, (count,) + template_rot.shape).copy()
    translations = np.broadcast_to(template_trans, (count,) + template_trans.shape).copy()
    rotations[:, layout.root] = parent_rot.T @ (heading @ matrices[:, 0] @ layout.heading_reference)
    root_pos = positions.copy()
    root_pos[:, 1] = static[:, 0]
    translations[:, layout.root] = (root_pos - parent_pos) @ parent_rot
    rotations[:, list(layout.joints)] = layout.reference @ matrices[:, 1:]
    step = np.zeros((count, 3))
    step[:, 0], step[:, 2] = static[:, 1], static[:, 2]
    positions += np.einsum("nij,nj->ni", heading, step) / fps
    headings += static[:, 3] / fps
    return rotations, translations


def kinematics_numpy(parents: np.ndarray, rotations: np.ndarray, translations: np.ndarray):
    """World transforms of N poses: numpy over N, a loop over joints (parents before children)."""
    world_rot, world_pos = np.empty_like(rotations), np.empty_like(translations)
    for j, p in enumerate(parents):
        if p < 0:
            world_rot[:, j], world_pos[:, j] = rotations[:, j], translations[:, j]
        else:
            world_rot[:, j] = world_rot[:, p] @ rotations[:, j]
            world_pos[:, j] = world_pos[:, p] + np.einsum("nab,nb->na", world_rot[:, p], translations[:, j])
    return world_rot, world_pos


def per_frame_us(work, frames: int, repeat: int) -> float:
    return 1e6 * median_seconds(work, repeat) / frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--characters", type=int, nargs="+", default=[1, 200])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    model = load_model(default_model_path())
    space, contact, layout = style_space(model), contact_space(model), model.layout
    controls = Controls(np.full(len(model.style_names), 1.5 / len(model.style_names)))
    static, ids = walk_features(without_range(model), controls, args.frames)
    shares = contact.shares(controls.weights)[0][ids]
    lam = interpolate(space, controls.weights)
    window = 2 + default_lookahead(model.fps) + 1
    means, precisions = lam.means[ids[None, :window]], lam.precisions[ids[None, :window]]
    known = np.zeros((1, 2, layout.dimension))
    solve = per_frame_us(lambda: [mlpg_continued(means, precisions, known) for _ in range(args.frames)], args.frames,
                         args.repeat)
    print(f"window solve ({window} frames): {solve:.1f} us (the yardstick)")
    parents = np.asarray(layout.skeleton.parents, dtype=np.int64)
    restorer = FrameRestorer(layout, model.fps)
    for count in args.characters:
        rows = np.repeat(static[:, None], count, axis=1)
        frame_shares = np.repeat(shares[:, None], count, axis=1)

        sample = min(count, 3)  # the Python path costs the same per character whatever N: timed on a few

        def before():
            for n in range(sample):  # the Python path: one character after another
                stream = reference_lock.PoseStream(layout, model.fps,
                                                   reference_lock.FootLock(layout, contact.clearance, model.fps))
                for row, share in zip(static, shares):
                    stream.next(row, share)

        def after():
            crowd = CrowdPoses(layout, model.fps, count, FootLock(layout, contact.clearance, model.fps))
            for row, share in zip(rows, frame_shares):
                crowd.next(row, share)

        positions, headings = np.zeros((count, 3)), np.zeros(count)
        shape = (count, len(parents))
        rot, trans = np.empty(shape + (3, 3)), np.empty(shape + (3,))
        world_rot, world_pos = np.empty_like(rot), np.empty_like(trans)
        np_rot, np_trans = restore_numpy(rows[0], layout, model.fps, positions.copy(), headings.copy())
        restorer.next(rows[0], positions.copy(), headings.copy(), rot, trans)
        assert np.abs(np_rot - rot).max() < 1e-12 and np.abs(np_trans - trans).max() < 1e-9  # the same arithmetic
        figures = {
            "pose path with the lock, before (Python)": per_frame_us(before, args.frames, max(1, args.repeat // 2))
            * count / sample,
            "pose path with the lock, after (compiled)": per_frame_us(after, args.frames, args.repeat),
            "restore, numpy over N": per_frame_us(
                lambda: [restore_numpy(r, layout, model.fps, positions, headings) for r in rows], args.frames, args.repeat),
            "restore, compiled": per_frame_us(
                lambda: [restorer.next(r, positions, headings, rot, trans) for r in rows], args.frames, args.repeat),
            "forward kinematics, numpy over N": per_frame_us(
                lambda: [kinematics_numpy(parents, rot, trans) for _ in rows], args.frames, args.repeat),
            "forward kinematics, compiled": per_frame_us(
                lambda: [_compose(parents, rot, trans, world_rot, world_pos) for _ in rows], args.frames, args.repeat),
        }
        print(f"{count} character(s), per frame (per character; x the window solve):")
        for name, us in figures.items():
            print(f"  {name:44s} {us:9.1f} us ({us / count:7.1f} us; x{us / count / solve:.2f})")


if __name__ == "__main__":
    main()
