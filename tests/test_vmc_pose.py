"""The VMC profile poses a normalised humanoid the way the captured body was posed.

A synthetic Unity-normalised avatar (T-pose, palms down, feet flat, Y up, left-handed, its own
proportions) is posed from the wire the way EVMC4U does it: each received local rotation is
written straight into its T-pose bone, the avatar's origin from /VMC/Ext/Root/Pos and the hips'
position from their Bone/Pos. Joint angles measured on that avatar (elbow, knee, wrist bend,
forearm twist, foot pitch, toes, torso lean and twist, head) are compared with the same angles
measured on the BVH itself, frame by frame over whole walks.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle
from scipy.spatial.transform import Rotation

from oscrecv import Receiver

from instrument.control.events import ControlEvent
from instrument.models.modelfile import load_model
from instrument.motion.bvh import Joint, Motion, Skeleton, read_bvh, write_bvh
from instrument.motion.features import choose_layout, extract
from instrument.motion.kinematics import channels_from_local, forward_kinematics, local_transforms
from instrument.output.humanoid import guess_humanoid, read_humanoid
from instrument.output.outputs import make_profile
from instrument.output.vmc import VmcProfile
from instrument.synthesis.posing import Pose
from instrument.shipped import default_model_path

WALKS = sorted((Path(__file__).resolve().parents[1] / "examples" / "data").glob("*.bvh"))
TOLERANCE = 5.0  # degrees

# The avatar: HumanBodyBones parent and T-pose offset from it (Unity: metres, +X right, +Z ahead)
AVATAR = {
    "Hips": (None, (0.0, 0.95, 0.0)), "Spine": ("Hips", (0.0, 0.10, 0.0)), "Chest": ("Spine", (0.0, 0.12, 0.0)),
    "UpperChest": ("Chest", (0.0, 0.10, 0.0)), "Neck": ("UpperChest", (0.0, 0.13, 0.0)), "Head": ("Neck", (0.0, 0.10, 0.0)),
}
for _side, _x in (("Left", -1.0), ("Right", 1.0)):
    AVATAR.update({
        f"{_side}Shoulder": ("UpperChest", (_x * 0.02, 0.09, 0.0)),
        f"{_side}UpperArm": (f"{_side}Shoulder", (_x * 0.10, 0.0, 0.0)),
        f"{_side}LowerArm": (f"{_side}UpperArm", (_x * 0.27, 0.0, 0.0)),
        f"{_side}Hand": (f"{_side}LowerArm", (_x * 0.25, 0.0, 0.0)),
        f"{_side}UpperLeg": ("Hips", (_x * 0.09, -0.06, 0.0)), f"{_side}LowerLeg": (f"{_side}UpperLeg", (0.0, -0.43, 0.0)),
        f"{_side}Foot": (f"{_side}LowerLeg", (0.0, -0.42, 0.0)), f"{_side}Toes": (f"{_side}Foot", (0.0, -0.07, 0.12)),
    })
FLIP = np.diag([1.0, 1.0, -1.0])  # Unity's left-handed axes <-> right-handed, both Y up


def decode(datagrams: list[bytes]) -> tuple[tuple[np.ndarray, np.ndarray], dict[str, tuple[np.ndarray, np.ndarray]]]:
    """The root transform and each bone's (position, quaternion) of one frame, from the wire."""
    root, bones = None, {}
    for datagram in datagrams:
        for m in OscBundle(datagram):
            if m.address == "/VMC/Ext/Root/Pos":
                root = (np.array(m.params[1:4]), np.array(m.params[4:8]))
            elif m.address == "/VMC/Ext/Bone/Pos":
                bones[m.params[0]] = (np.array(m.params[1:4]), np.array(m.params[4:8]))
    return root, bones


def pose_avatar(root, bones) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """EVMC4U's way: local rotations into the T-pose bones, the hips' local position, the root
    transform; then world rotations and positions, turned into right-handed axes."""
    root_rot = Rotation.from_quat(root[1]).as_matrix()
    world_rot, world_pos = {}, {}
    for bone, (parent, offset) in AVATAR.items():  # parents listed first
        local = Rotation.from_quat(bones[bone][1]).as_matrix() if bone in bones else np.eye(3)
        if parent is None:
            world_rot[bone] = root_rot @ local
            world_pos[bone] = root[0] + root_rot @ bones[bone][0]
        else:
            world_rot[bone] = world_rot[parent] @ local
            world_pos[bone] = world_pos[parent] + world_rot[parent] @ np.array(offset)
    return ({b: FLIP @ r @ FLIP for b, r in world_rot.items()}, {b: FLIP @ p for b, p in world_pos.items()})


def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def elevation(v: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(v[..., 1], np.hypot(v[..., 0], v[..., 2])))


def twist(relative: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Signed twist (degrees) of rotations about `axis` (their swing-twist split)."""
    q = Rotation.from_matrix(relative).as_quat()
    along = q[..., :3] @ (axis / np.linalg.norm(axis))
    return np.degrees(np.angle(np.exp(2j * np.arctan2(along, q[..., 3]))))


def heading_of(line: np.ndarray) -> np.ndarray:
    return np.arctan2(line[..., 0], line[..., 2])


def body_angles(pos: dict, rot: dict, hand_axis: dict, head_axis: np.ndarray, flat_pitch: dict, toe_flat: dict,
                foot_axis: dict | None = None):
    """Joint angles (degrees) per frame, from world positions and rotations keyed by humanoid bone.

    `hand_axis[side]` and `head_axis` are where the hand and head point in their own frames;
    `flat_pitch[side]` the foot's ankle-to-toes elevation when it stands flat; `toe_flat[side]`
    the toes' rotation relative to the foot when it stands flat (the toes straight).
    `foot_axis[side]`, for the avatar, is the direction in its foot frame of the BVH's
    ankle-to-toes line: the avatar's own toes sit at another pitch, and a roll of the foot
    about the BVH's line would move them."""
    out = {}
    up = np.array([0.0, 1.0, 0.0])
    for s in ("Left", "Right"):
        arm = [pos[f"{s}{b}"] for b in ("UpperArm", "LowerArm", "Hand")]
        leg = [pos[f"{s}{b}"] for b in ("UpperLeg", "LowerLeg", "Foot", "Toes")]
        out[f"{s} elbow"] = angle(arm[1] - arm[0], arm[2] - arm[1])
        out[f"{s} knee"] = angle(leg[1] - leg[0], leg[2] - leg[1])
        hand = rot[f"{s}Hand"] @ hand_axis[s]
        out[f"{s} wrist bend"] = angle(arm[2] - arm[1], hand)
        out[f"{s} forearm twist"] = twist(np.swapaxes(rot[f"{s}UpperArm"], -1, -2) @ rot[f"{s}Hand"], hand_axis[s])
        if foot_axis is None:  # the BVH: ankle to toes
            out[f"{s} foot pitch"] = elevation(leg[3] - leg[2]) - flat_pitch[s]
        else:  # the avatar: the same line in its foot, ahead and down by the BVH's flat pitch at rest
            out[f"{s} foot pitch"] = elevation(rot[f"{s}Foot"] @ foot_axis[s]) - flat_pitch[s]
        toes = toe_flat[s].T @ np.swapaxes(rot[f"{s}Foot"], -1, -2) @ rot[f"{s}Toes"]  # from straight
        out[f"{s} toes"] = np.degrees(Rotation.from_matrix(toes).magnitude())
    out["torso lean"] = angle(pos["Neck"] - pos["Hips"], up)
    hips_line, shoulder_line = pos["LeftUpperLeg"] - pos["RightUpperLeg"], pos["LeftUpperArm"] - pos["RightUpperArm"]
    out["torso twist"] = np.degrees(np.angle(np.exp(1j * (heading_of(shoulder_line) - heading_of(hips_line)))))
    out["spine bend"] = angle(pos["Spine"] - pos["Hips"], pos["Neck"] - pos["Chest"])
    out["head tilt"] = angle(rot["Head"] @ head_axis, up)
    return out


def compare(profile: VmcProfile, motion: Motion, mapping: dict[str, str]) -> dict[str, float]:
    """Worst difference (degrees) per angle between the avatar and the BVH over the whole walk."""
    skeleton = motion.skeleton
    rotations, translations = local_transforms(motion)
    world_rot, world_pos = forward_kinematics(skeleton, rotations, translations)
    joint = {bone: skeleton.index(name) for name, bone in mapping.items()}
    avatar_rot, avatar_pos = {b: [] for b in AVATAR}, {b: [] for b in AVATAR}
    for t in range(motion.frames):
        pose = Pose(t, t / motion.fps, rotations[t], translations[t], world_rot[t], world_pos[t])
        rot, pos = pose_avatar(*decode(profile.datagrams(pose, {})))
        for b in AVATAR:
            avatar_rot[b].append(rot[b])
            avatar_pos[b].append(pos[b])
    avatar_rot = {b: np.array(v) for b, v in avatar_rot.items()}
    avatar_pos = {b: np.array(v) for b, v in avatar_pos.items()}

    # the BVH's own conventions: a hand, head or toe at rest points along its offset; the foot
    # stands flat where the ankle and the toes are lowest; the toes are straight there
    def along(bone):
        offset = skeleton.offsets[joint[bone]]
        return offset / np.linalg.norm(offset)

    bvh_rot = {b: world_rot[:, j] for b, j in joint.items()}
    bvh_pos = {b: world_pos[:, j] for b, j in joint.items()}
    flat, toe_flat = {}, {}
    for s in ("Left", "Right"):
        foot, toes = bvh_pos[f"{s}Foot"], bvh_pos[f"{s}Toes"]
        length = np.linalg.norm(toes[0] - foot[0])
        flat[s] = -np.degrees(np.arcsin((foot[:, 1].min() - toes[:, 1].min()) / length))
        flattest = int(np.argmin(foot[:, 1]))
        toe_flat[s] = bvh_rot[f"{s}Foot"][flattest].T @ bvh_rot[f"{s}Toes"][flattest]
    axes = {s: along(f"{s}Hand") for s in ("Left", "Right")}
    expected = body_angles(bvh_pos, bvh_rot, axes, along("Head"), flat, toe_flat)

    pitch = {s: np.radians(flat[s]) for s in ("Left", "Right")}
    foot_axis = {s: np.array([0.0, np.sin(pitch[s]), -np.cos(pitch[s])]) for s in ("Left", "Right")}
    avatar_axes = {"Left": np.array([-1.0, 0.0, 0.0]), "Right": np.array([1.0, 0.0, 0.0])}
    measured = body_angles(avatar_pos, avatar_rot, avatar_axes, np.array([0.0, 1.0, 0.0]), flat,
                           {s: np.eye(3) for s in ("Left", "Right")}, foot_axis)
    worst = {}
    for name in expected:
        difference = np.abs(np.asarray(measured[name]) - np.asarray(expected[name]))
        if "twist" in name:
            difference = np.minimum(difference, 360.0 - difference)
        worst[name] = float(np.max(difference))
    return worst


def assert_close(worst: dict[str, float]) -> None:
    bad = {name: round(w, 1) for name, w in worst.items() if not w <= TOLERANCE}
    everything = {k: round(v, 1) for k, v in worst.items()}
    assert not bad, f"avatar and BVH differ by more than {TOLERANCE} deg: {bad} (all: {everything})"


@pytest.mark.parametrize("walk", WALKS, ids=[w.stem for w in WALKS])
def test_normalised_avatar_matches_the_bvh_with_the_shipped_model(walk):
    model = load_model(default_model_path())
    motion = read_bvh(walk)
    assert motion.skeleton.same_layout(model.layout.skeleton)
    for root in ("hips", "path"):
        profile = make_profile("vmc", model, vmc_root=root)
        assert_close(compare(profile, motion, guess_humanoid(motion.skeleton)))


# Another skeleton: Mixamo's names, in metres, resting in a T-pose (facing +Z, left = +X) with
# every bone's frame rolled about itself by its own angle. The same walk re-expressed on it
# (every joint's frame changed, the motion unchanged).
MIXAMO = {"joint_Root": "Root", "Hips": "mixamorig:Hips", "Spine": "mixamorig:Spine", "Chest": "mixamorig:Spine1",
          "Neck": "mixamorig:Neck", "Head": "mixamorig:Head"}
for _side, _s in (("Left", "L"), ("Right", "R")):
    MIXAMO.update({f"Shoulder_{_s}": f"mixamorig:{_side}Shoulder", f"UpperArm_{_s}": f"mixamorig:{_side}Arm",
                   f"LowerArm_{_s}": f"mixamorig:{_side}ForeArm", f"Hand_{_s}": f"mixamorig:{_side}Hand",
                   f"UpperLeg_{_s}": f"mixamorig:{_side}UpLeg", f"LowerLeg_{_s}": f"mixamorig:{_side}Leg",
                   f"Foot_{_s}": f"mixamorig:{_side}Foot", f"Toes_{_s}": f"mixamorig:{_side}ToeBase"})
REST_DIRECTION = {"Shoulder_L": (1, 0, 0), "UpperArm_L": (1, 0, 0), "LowerArm_L": (1, 0, 0), "Hand_L": (1, 0, 0),
                  "Shoulder_R": (-1, 0, 0), "UpperArm_R": (-1, 0, 0), "LowerArm_R": (-1, 0, 0), "Hand_R": (-1, 0, 0),
                  "UpperLeg_L": (0, -1, 0), "LowerLeg_L": (0, -1, 0), "Foot_L": (0, -0.5, 1), "Toes_L": (0, 0, 1),
                  "UpperLeg_R": (0, -1, 0), "LowerLeg_R": (0, -1, 0), "Foot_R": (0, -0.5, 1), "Toes_R": (0, 0, 1)}


def on_another_skeleton(motion: Motion, seed: int = 7) -> Motion:
    skeleton = motion.skeleton
    rotations, translations = local_transforms(motion)
    rolls = Rotation.random(len(skeleton.joints), random_state=seed).as_rotvec()
    change = []  # per joint C: new frame = old frame @ C, so the new rest points the bone its T-pose way
    for j, joint in enumerate(skeleton.joints):
        children = skeleton.children(j)
        along = skeleton.offsets[children[0]] if children else skeleton.offsets[j]
        rest = np.array(REST_DIRECTION.get(joint.name, (0, 1, 0)), dtype=float)
        rest /= np.linalg.norm(rest)
        roll = Rotation.from_rotvec(rest * np.linalg.norm(rolls[j]))  # a roll about the bone itself
        swing, _ = Rotation.align_vectors([along / np.linalg.norm(along)], [rest])
        change.append((swing * roll).as_matrix())
    change = np.array(change)
    parent_change = np.array([change[p] if p >= 0 else np.eye(3) for p in skeleton.parents])
    new_rot = np.swapaxes(parent_change, -1, -2) @ rotations @ change
    new_trans = np.einsum("jki,tjk->tji", parent_change, translations) / 100.0
    joints = []
    for j, joint in enumerate(skeleton.joints):
        offset = parent_change[j].T @ skeleton.offsets[j] / 100.0
        joints.append(Joint(MIXAMO[joint.name], joint.parent, tuple(offset), joint.channels,
                            None if joint.end_site is None else (0.0, 0.0, 0.0)))
    other = Skeleton(tuple(joints))
    return Motion(other, channels_from_local(other, new_rot, new_trans), motion.fps)


@pytest.fixture(scope="module")
def other_skeleton(tmp_path_factory):
    """Both walks re-expressed on the other skeleton, a model trained on them with `instrument
    train`, and the humanoid map as a --humanoid file: (model path, map path, {walk: motion})."""
    folder = tmp_path_factory.mktemp("other")
    motions, paths = {}, []
    for walk in WALKS:
        original = read_bvh(walk)
        motion = on_another_skeleton(original)
        # the same walk: the joints are where they were (in metres now)
        assert np.allclose(forward_kinematics(motion.skeleton, *local_transforms(motion))[1] * 100.0,
                           forward_kinematics(original.skeleton, *local_transforms(original))[1], atol=1e-4)
        path = folder / walk.name
        write_bvh(path, motion)
        motions[walk.stem], paths = read_bvh(path), paths + [str(path)]
    model = folder / "other.npz"
    result = subprocess.run([sys.executable, "-m", "instrument", "train", *paths, "--out", str(model), "--quiet"],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    humanoid = folder / "bones.toml"
    mapping = {MIXAMO[name]: bone for name, bone in guess_humanoid(read_bvh(WALKS[0]).skeleton).items()}
    humanoid.write_text("[bones]\n" + "".join(f'"{joint}" = "{bone}"\n' for joint, bone in mapping.items()))
    return model, humanoid, motions, mapping


@pytest.mark.parametrize("walk", WALKS, ids=[w.stem for w in WALKS])
def test_normalised_avatar_matches_the_bvh_with_a_model_on_another_skeleton(walk, other_skeleton):
    model_path, humanoid, motions, mapping = other_skeleton
    model = load_model(model_path)
    motion = motions[walk.stem]
    for root in ("hips", "path"):
        profile = make_profile("vmc", model, read_humanoid(humanoid, model.layout.skeleton), vmc_root=root)
        assert profile.scale == 1.0  # metres, recognised
        assert_close(compare(profile, motion, mapping))


CMU_ASF = sorted((Path(__file__).parent / "data" / "cmu-131").glob("*.bvh"))


@pytest.mark.parametrize("take", CMU_ASF, ids=[t.stem for t in CMU_ASF])
def test_a_cmu_take_with_its_asf_names_poses_the_avatar_as_the_capture(take):
    """The public CMU takes name their joints as CMU's ASF files do: LeftHip (the thigh) under
    LHipJoint, LeftShoulder (the upper arm) under LeftCollar, both collars and the lower neck
    starting at the top of the chest, the lower back at the hips. Before, no upper arm or upper
    leg was found, the chest's left-right line had no length and every torso bone was sent as
    NaN. The VMC profile made from the take itself now sends finite values and poses the
    avatar's limbs and head as the capture. Not compared: the torso (its lean, twist and bend
    are measured on lines between joints the avatar spaces otherwise, CMU's lower back sitting
    on its hips and its lower neck on its chest: 4 to 12 degrees off) and the foot's pitch (the
    flattest stance of a take of 4 steps)."""
    motion = read_bvh(take)
    mapping = guess_humanoid(motion.skeleton)
    assert {joint: mapping.get(joint) for joint in ("LeftHip", "RightHip", "LeftCollar", "LeftShoulder", "RightShoulder",
                                                     "lowerback", "lowerneck")} == {
        "LeftHip": "LeftUpperLeg", "RightHip": "RightUpperLeg", "LeftCollar": "LeftShoulder",
        "LeftShoulder": "LeftUpperArm", "RightShoulder": "RightUpperArm", "lowerback": "Spine", "lowerneck": "Neck"}
    layout = choose_layout([motion])
    features = extract(motion, layout)[0][:, : layout.dimension]
    forward = np.array([features[:, 1].mean(), 0.0, features[:, 2].mean()])
    profile = VmcProfile(layout, mapping, forward, stance=features)
    for rotation in profile.tpose.rotations.values():
        assert np.all(np.isfinite(rotation))
    worst = compare(profile, motion, mapping)
    assert_close({name: w for name, w in worst.items() if not name.startswith(("spine", "torso")) and "foot pitch" not in name})


def test_run_sends_the_path_in_the_root_and_leaves_the_fingers_out_on_request(tmp_path):
    log = tmp_path / "turning.jsonl"  # walking in a curve, so the heading changes
    log.write_text(ControlEvent(0.1, "test", "turn", 0.8).to_json() + "\n")
    receiver = Receiver()
    try:
        result = subprocess.run([sys.executable, "-m", "instrument", "run", "--seconds", "2", "--fast", "--quiet",
                                 "--replay", str(log), "--osc", f"127.0.0.1:{receiver.port}/vmc", "--vmc-root", "path",
                                 "--no-relaxed-hands"], capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
        deadline = time.monotonic() + 10
        while sum(1 for a, _ in receiver.messages() if a == "/VMC/Ext/OK") < 60 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        receiver.close()
    messages = receiver.messages()
    roots = np.array([p[1:4] for a, p in messages if a == "/VMC/Ext/Root/Pos"])
    hips = np.array([p[1:4] for a, p in messages if a == "/VMC/Ext/Bone/Pos" and p[0] == "Hips"])
    assert len(roots) == 60 and len(hips) == 60
    assert np.all(roots[:, 1] == 0.0)  # on the floor
    assert np.linalg.norm(roots[-1] - roots[0]) > 1.0  # two seconds of walking: over a metre of path
    assert np.all(np.abs(hips[:, [0, 2]]) < 0.3) and np.all((0.6 < hips[:, 1]) & (hips[:, 1] < 1.3))  # hips over the root
    # the root faces where it goes: its forward (+Z) along the path's direction
    turns = np.array([p[4:8] for a, p in messages if a == "/VMC/Ext/Root/Pos"])
    forward = Rotation.from_quat(turns).apply([0.0, 0.0, 1.0])
    travel = roots[10:] - roots[:-10]  # a third of a second of walking
    along = np.sum(forward[5:-5] * travel, axis=1) / np.linalg.norm(travel, axis=1)
    assert np.median(along) > np.cos(np.radians(20.0)), np.median(along)
    heading = np.degrees(np.unwrap(np.arctan2(forward[:, 0], forward[:, 2])))
    assert abs(heading[-1] - heading[0]) > 20.0  # it did turn
    assert all(len(p) <= 1400 for p in receiver.datagrams)
    assert not any(a == "/VMC/Ext/Bone/Pos" and "Index" in p[0] for a, p in messages)


def test_relaxed_hand_curls_every_finger_towards_the_palm():
    model = load_model(default_model_path())
    motion = read_bvh(WALKS[0])
    rotations, translations = local_transforms(motion)
    world_rot, world_pos = forward_kinematics(motion.skeleton, rotations, translations)
    pose = Pose(0, 0.0, rotations[0], translations[0], world_rot[0], world_pos[0])
    _, bones = decode(make_profile("vmc", model).datagrams(pose, {}))
    fingers = [b for b in bones if any(f in b for f in ("Thumb", "Index", "Middle", "Ring", "Little"))]
    assert len(fingers) == 30
    for bone in fingers:
        along = np.array([-1.0 if bone.startswith("Left") else 1.0, 0.0, 0.0])  # the T-pose finger, Unity axes
        curled = Rotation.from_quat(bones[bone][1]).as_matrix() @ along
        bend = np.degrees(np.arccos(np.clip(curled @ along, -1.0, 1.0)))
        assert curled[1] < 0.0 and 5.0 <= bend <= 35.0, (bone, curled, bend)  # down, towards the palm
    _, without = decode(make_profile("vmc", model, fingers=False).datagrams(pose, {}))
    assert set(without) == set(bones) - set(fingers)


@pytest.mark.parametrize("walk", WALKS, ids=[w.stem for w in WALKS])
def test_limb_roll_is_normalised_elbows_bend_about_the_vertical_and_knees_across(walk):
    """Palms down in the T-pose means an elbow bends the forearm forward, about the vertical;
    a knee bends about the left-right axis. A roll left in the reference shows as a tilted axis."""
    model = load_model(default_model_path())
    motion = read_bvh(walk)
    rotations, translations = local_transforms(motion)
    world_rot, world_pos = forward_kinematics(motion.skeleton, rotations, translations)
    profile = make_profile("vmc", model)
    local = {b: [] for b in ("LeftLowerArm", "RightLowerArm", "LeftLowerLeg", "RightLowerLeg")}
    for t in range(motion.frames):
        pose = Pose(t, t / motion.fps, rotations[t], translations[t], world_rot[t], world_pos[t])
        _, bones = decode(profile.datagrams(pose, {}))
        for bone in local:
            local[bone].append(bones[bone][1])
    for bone, quats in local.items():
        q = np.array(quats)
        if "Arm" in bone:  # the bend only: the forearm's twist about itself (X) taken out
            twist = np.zeros_like(q)
            twist[:, 0], twist[:, 3] = q[:, 0], q[:, 3]
            q = (Rotation.from_quat(q) * Rotation.from_quat(twist).inv()).as_quat()  # q = swing * twist
        vector = Rotation.from_quat(q).as_rotvec()
        bent = np.linalg.norm(vector, axis=1) > np.radians(10.0)
        axis = np.abs(vector[bent] / np.linalg.norm(vector[bent], axis=1, keepdims=True))
        expected = 1 if "Arm" in bone else 0  # Unity's Y, or X
        assert bent.sum() > 10 and np.median(axis[:, expected]) > 0.97, (bone, np.median(axis, axis=0))
