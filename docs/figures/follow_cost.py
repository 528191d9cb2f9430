"""Per-frame cost of the body following its stance foot (synthesis/follow.py), against the foot
lock without it and the bare pose, measured in the same process (the minimum of 7 blocks of
300 frames of the normal walk, so a busy machine inflates all three alike)."""

import time

import numpy as np

from instrument.models.modelfile import default_model_path, load_model
from instrument.synthesis.posing import PoseStream
from instrument.synthesis.contact import contact_space
from instrument.synthesis.footlock import FootLock
from instrument.synthesis.engine import default_controls, walk_features
from instrument.synthesis.widen import without_range

model = load_model(default_model_path())
contact = contact_space(model)
controls = default_controls(model, {"normal": 1.0})
static, ids = walk_features(without_range(model), controls, 300)
shares = contact.shares(controls.weights)[0][ids]


def per_frame_us(lock: bool, follow: bool = True) -> float:
    stream = PoseStream(model.layout, model.fps, FootLock(model.layout, contact.clearance, model.fps) if lock else None)
    if not follow:
        stream.crowd._follow = lambda *args: None  # the lock alone
    start = time.perf_counter()
    for row, share in zip(static, shares):
        stream.next(row, share if lock else None)
    return (time.perf_counter() - start) / len(static) * 1e6


per_frame_us(True)  # compile and warm up
pose, alone, followed = (min(np.array([[per_frame_us(False), per_frame_us(True, False), per_frame_us(True)] for _ in range(7)]).T[k]) for k in range(3))
print(f"pose {pose:.0f} us/frame; lock alone +{alone - pose:.0f} us; with the follow step +{followed - pose:.0f} us: "
      f"the follow step {followed - alone:.0f} us ({(followed - alone) / (alone - pose):.2f}x the lock's own)")
