"""Any capture a user brings: style names in file names, other skeletons and joint names, and a
model that says so when it meets a skeleton it was not trained on."""

import subprocess
import sys
import time
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_WALKS, needs_walks
from oscrecv import Receiver
from samples import cmu_named_walk
from test_vmc_pose import assert_close, compare

from instrument.errors import UserError
from instrument.training.corpus import (
    DEFAULT_STYLE_PATTERN,
    load_corpus,
    make_takes,
    read_motions,
    style_from_name,
    styled_takes,
)
from instrument.models.modelfile import default_model_path, load_model
from instrument.motion.bvh import Joint, Skeleton, read_bvh
from instrument.motion.limbs import find_limbs
from instrument.output.humanoid import guess_humanoid, read_humanoid
from instrument.output.outputs import make_profile


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("name, style", [
    ("dataset-2_walk_elderly_003", "elderly"),
    ("walk_not-confident_001", "not-confident"),
    ("style2_take3", "style2"),
    ("Capture_Old-Man_12", "old-man"),
])
def test_default_pattern_reads_styles_with_hyphens_and_digits(name, style):
    assert style_from_name(Path(name + ".bvh"), DEFAULT_STYLE_PATTERN) == style


@pytest.mark.parametrize("name", ["walk", "walk_001_002"])
def test_names_without_a_style_are_one_line_errors(name):
    with pytest.raises(UserError, match="cannot read a style"):
        style_from_name(Path(name + ".bvh"), DEFAULT_STYLE_PATTERN)


def test_no_takes_are_one_line_errors_naming_the_folder(tmp_path):
    empty = tmp_path / "captures"
    empty.mkdir()
    (empty / "notes.txt").write_text("the takes are elsewhere\n")
    with pytest.raises(UserError, match=f"^{empty}: no .bvh files in this folder$"):
        styled_takes([empty])
    with pytest.raises(UserError, match=f"^{tmp_path / 'missing'}: no such file or folder$"):
        styled_takes([tmp_path / "missing"])
    with pytest.raises(UserError, match="no takes to read"):
        read_motions([], 30.0)
    with pytest.raises(UserError, match="no takes to read"):
        load_corpus([], 30.0)


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.parametrize("script", ["training_time.py", "heldout_likelihood.py", "one_take.py", "style_fidelity.py"])
def test_the_training_examples_name_a_folder_without_takes(script, tmp_path):
    result = subprocess.run([sys.executable, str(EXAMPLES / script), str(tmp_path)], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert result.stderr.strip() == f"{script}: error: {tmp_path}: no .bvh files in this folder"


@pytest.mark.parametrize("script", ["one_take.py", "style_fidelity.py"])
def test_the_training_examples_check_their_options(script, tmp_path):
    result = subprocess.run([sys.executable, str(EXAMPLES / script), str(tmp_path), "--walks", "0"], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "--walks" in result.stderr


def _skeleton(pairs: list[tuple[str, str | None]]) -> Skeleton:
    names = [n for n, _ in pairs]
    rotation = ("Zrotation", "Xrotation", "Yrotation")
    return Skeleton(tuple(Joint(n, names.index(p) if p else -1, (0.0, 0.0, 0.0), rotation) for n, p in pairs))


def _body(hips: str, spine: list[str], neck: str, head: str, left: list[str], arm: list[str]) -> list[tuple[str, str | None]]:
    """A left half-body (enough to check the names): hips, a spine chain, neck, head, the left
    leg chain (thigh, shin, foot, toes) from the hips and the left arm chain from the spine's top."""
    out, parent = [(hips, None)], hips
    for joint in spine + [neck, head]:
        out.append((joint, parent))
        parent = joint
    for chain, root in ((left, hips), (arm, spine[-1])):
        for joint in chain:
            out.append((joint, root))
            root = joint
    return out


LEG = ["LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes"]
ARM = ["LeftShoulder", "LeftUpperArm", "LeftLowerArm", "LeftHand"]
CONVENTIONS = {
    "CMU": _body("Hips", ["LowerBack", "Spine", "Spine1"], "Neck", "Head",
                 ["LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"], ["LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"]),
    "Mixamo": _body("mixamorig:Hips", ["mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2"],
                    "mixamorig:Neck", "mixamorig:Head",
                    ["mixamorig:LeftUpLeg", "mixamorig:LeftLeg", "mixamorig:LeftFoot", "mixamorig:LeftToeBase"],
                    ["mixamorig:LeftShoulder", "mixamorig:LeftArm", "mixamorig:LeftForeArm", "mixamorig:LeftHand"]),
    "Unreal": _body("pelvis", ["spine_01", "spine_02", "spine_03"], "neck_01", "head",
                    ["thigh_l", "calf_l", "foot_l", "ball_l"], ["clavicle_l", "upperarm_l", "lowerarm_l", "hand_l"]),
    "Rigify": _body("hips", ["spine", "chest", "upper_chest"], "neck", "head",
                    ["thigh.L", "shin.L", "foot.L", "toe.L"], ["shoulder.L", "upper_arm.L", "forearm.L", "hand.L"]),
    "VRoid": _body("J_Bip_C_Hips", ["J_Bip_C_Spine", "J_Bip_C_Chest", "J_Bip_C_UpperChest"], "J_Bip_C_Neck", "J_Bip_C_Head",
                   ["J_Bip_L_UpperLeg", "J_Bip_L_LowerLeg", "J_Bip_L_Foot", "J_Bip_L_ToeBase"],
                   ["J_Bip_L_Shoulder", "J_Bip_L_UpperArm", "J_Bip_L_LowerArm", "J_Bip_L_Hand"]),
    "3ds Max Biped": _body("Bip01 Pelvis", ["Bip01 Spine", "Bip01 Spine1", "Bip01 Spine2"], "Bip01 Neck", "Bip01 Head",
                           ["Bip01 L Thigh", "Bip01 L Calf", "Bip01 L Foot", "Bip01 L Toe0"],
                           ["Bip01 L Clavicle", "Bip01 L UpperArm", "Bip01 L Forearm", "Bip01 L Hand"]),
    # issue 30's suit and the CMU conversions in tests/data/cmu-131: a hip, knee and ankle per leg,
    # and a collar before the shoulder (which is the upper arm); the upper arm and leg were unmapped
    "suit": _body("Hips", ["Chest2", "Chest3", "Chest4"], "Neck", "Head",
                  ["LeftHip", "LeftKnee", "LeftAnkle", "LeftToe"], ["LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist"]),
    # MotionBuilder's HumanIK: CMU's names behind the character's prefix; the upper arm and shin were unmapped
    "HumanIK": _body("Character1_Hips", ["Character1_Spine", "Character1_Spine1", "Character1_Spine2"],
                     "Character1_Neck", "Character1_Head",
                     ["Character1_LeftUpLeg", "Character1_LeftLeg", "Character1_LeftFoot", "Character1_LeftToeBase"],
                     ["Character1_LeftShoulder", "Character1_LeftArm", "Character1_LeftForeArm", "Character1_LeftHand"]),
    # CMU's ASF skeletons (amc2bvh): a lower-case side letter and the bones' Latin names; no limb was mapped
    "CMU ASF": _body("hip", ["lowerback", "upperback", "thorax"], "lowerneck", "head",
                     ["lfemur", "ltibia", "lfoot", "ltoes"], ["lclavicle", "lhumerus", "lradius", "lwrist"]),
}


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_humanoid_bones_are_guessed_from_common_naming_conventions(convention):
    pairs = CONVENTIONS[convention]
    names = [n for n, _ in pairs]
    guessed = guess_humanoid(_skeleton(pairs))
    expected = dict(zip(names, ["Hips", "Spine", "Chest", "UpperChest", "Neck", "Head"] + LEG + ARM))
    assert guessed == expected


def test_a_hip_stub_above_a_named_thigh_is_not_the_thigh():
    """A rig with LeftHip above LeftUpLeg: the thigh is the joint named so, the stub is left out
    (a sided hip is the thigh only where no joint is named as one: the suit's LeftHip, LeftKnee)."""
    pairs = _body("Hips", ["Spine", "Chest", "UpperChest"], "Neck", "Head",
                  ["LeftHip", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"],
                  ["LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"])
    guessed = guess_humanoid(_skeleton(pairs))
    assert guessed["LeftUpLeg"] == "LeftUpperLeg" and "LeftHip" not in guessed


def test_a_spine_without_a_neck_joint_is_guessed_up_to_the_head():
    """A skeleton whose head hangs from the chest (no neck joint) still has its spine mapped:
    VMC avatars need a Spine, and it was left out when no joint was named as a neck."""
    pairs = [(n, p) for n, p in _body("Hips", ["Spine", "Chest"], "Neck", "Head", LEG, ARM) if n != "Neck"]
    pairs = [(n, "Chest" if p == "Neck" else p) for n, p in pairs]
    guessed = guess_humanoid(_skeleton(pairs))
    assert guessed["Spine"] == "Spine" and guessed["Chest"] == "Chest" and guessed["Head"] == "Head"
    assert "Neck" not in guessed.values()


def test_joints_named_for_no_bone_ask_for_a_humanoid_map_in_one_line(tmp_path):
    """A skeleton whose names say nothing (joint01, joint02, ...) made the VMC profile and the
    T-pose rest (`run`'s default output, `skeleton`) raise numpy's "axes don't match array";
    it is one line naming --humanoid, and a map given there plays."""
    import copy
    from dataclasses import replace

    model = load_model(default_model_path())
    skeleton = model.layout.skeleton
    generic = {name: f"joint{k + 1:02d}" for k, name in enumerate(skeleton.names)}
    metadata = copy.deepcopy(model.metadata)
    for joint in metadata["skeleton"]["joints"]:
        joint["name"] = generic[joint["name"]]
    features = metadata["features"]
    features["root"] = generic[features["root"]]
    features["joints"] = [generic[n] for n in features["joints"]]
    features["left_out"] = [generic[n] for n in features["left_out"]]
    features["names"] = [generic.get(n.split(".")[0], n.split(".")[0]) + n[len(n.split(".")[0]):] for n in features["names"]]
    model = replace(model, metadata=metadata)
    assert guess_humanoid(model.layout.skeleton) == {}
    with pytest.raises(UserError, match=r"^no joint name .*joint01, joint02, .* give --humanoid BONES\.toml") as error:
        make_profile("vmc", model)
    assert "\n" not in str(error.value)
    bones = tmp_path / "bones.toml"
    bones.write_text(f'[bones]\n"{generic["Hips"]}" = "Hips"\n')
    assert make_profile("vmc", model, read_humanoid(bones, model.layout.skeleton)).bones == ["Hips"]


def test_a_humanoid_map_naming_one_bone_twice_is_one_line(tmp_path):
    """Two joints mapped to one bone (a copied line left unchanged) sent the bone twice a frame."""
    skeleton = load_model(default_model_path()).layout.skeleton
    bones = tmp_path / "bones.toml"
    bones.write_text('# the legs\n[bones]\n"UpperLeg_L" = "LeftUpperLeg"\n"LowerLeg_L" = "LeftUpperLeg"\n')
    with pytest.raises(UserError) as error:
        read_humanoid(bones, skeleton)
    assert str(error.value) == f"{bones}:4: [bones] 'LowerLeg_L' = 'LeftUpperLeg': 'UpperLeg_L' is LeftUpperLeg already"


@pytest.mark.parametrize("text, line, says", [
    ('[bones]\n"Hips" = "Hips"\n\n[Bones]\n"UpperLeg_L" = "LeftUpperLeg"\n', 4, "Bones: unknown key"),
    ('map = "mine"\n[bones]\n"Hips" = "Hips"\n', 1, "map: unknown key"),
    ('# the hips\n[bones]\n"Hips" = "Hips"\n"UpperLeg_X" = "LeftUpperLeg"\n', 4, "the model's skeleton has no such joint"),
    ('[bones]\n"Hips" = "Hips"\n"UpperLeg_L" = "LeftUpperLegg"\n', 3, "'LeftUpperLegg': not a humanoid bone"),
    ('[bones]\n"Hips" = "Hips"\n[bones.arm]\n"UpperArm_L" = "LeftUpperArm"\n', 3, "the model's skeleton has no such joint"),
])
def test_a_humanoid_map_key_it_does_not_read_is_one_line_at_its_line(model, tmp_path, text, line, says):
    """A second table (`[Bones]`, a note above [bones]) was read past: its bones never moved on
    the avatar and nothing said so. Every refusal names the line."""
    bones = tmp_path / "bones.toml"
    bones.write_text(text)
    with pytest.raises(UserError) as error:
        read_humanoid(bones, model.layout.skeleton)
    assert str(error.value).startswith(f"{bones}:{line}:") and says in str(error.value), error.value


@pytest.mark.parametrize("text, line, says", [
    ('[bones]\n"Hips" = "Hips"\n"UpperLeg_L" = "LeftUperLeg"\n', 3,
     "'LeftUperLeg': not a humanoid bone (did you mean 'LeftUpperLeg'?)"),
    ('[bones]\n"Hips" = "Hips"\n"UperLeg_L" = "LeftUpperLeg"\n', 3,
     "'UperLeg_L': the model's skeleton has no such joint (did you mean 'UpperLeg_L'?)"),
    ('# mine\n[bone]\n"Hips" = "Hips"\n', 2, "bone: unknown key (expected one of bones)"),
    ('[bones]\n"Hips" = 3\n', 2, "3: not a humanoid bone"),
])
def test_a_bad_bone_map_stops_run_at_start_whatever_the_targets_naming_its_line(tmp_path, text, line, says):
    """A bone map the performer named was read only for a VMC target: with the flat profile alone
    (or no OSC) a misspelt bone or joint passed `run` silently, and when it was read the error
    named no line. Now it is read at start whatever the targets: one line naming file and line."""
    bones = tmp_path / "bones.toml"
    bones.write_text(text)
    for targets in (["--no-osc"], ["--osc", "127.0.0.1:9/flat"], ["--osc", "127.0.0.1:9/vmc"]):
        result = cli("run", "--check", "--humanoid", str(bones), *targets)
        assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"instrument run: error: {bones}:{line}: ") and says in lines[0], lines
    bones.write_text('[bones]\n"Hips" = "Hips"\n')  # the check can pass
    assert cli("run", "--check", "--humanoid", str(bones), "--no-osc").returncode == 0


def test_humanoid_guess_of_the_shipped_skeleton():
    guessed = guess_humanoid(load_model(default_model_path()).layout.skeleton)
    assert {guessed[n] for n in ("Hips", "UpperLeg_L", "LowerLeg_R", "Toes_L", "UpperArm_R", "Chest")} == {
        "Hips", "LeftUpperLeg", "RightLowerLeg", "LeftToes", "RightUpperArm", "Chest"}


@pytest.fixture(scope="module")
def cmu_model(real_walks, tmp_path_factory):
    """A model trained on the shared walks rewritten as a CMU-style capture (renamed, re-rooted,
    3-channel ZYX joints), files named with hyphenated and numbered styles."""
    folder = tmp_path_factory.mktemp("cmu")
    for style, source in (("old-man", "_elderly_"), ("style2", "_active_")):
        for k, path in enumerate([p for p in real_walks if source in p.name][:2]):
            (folder / f"capture_{style}_{k + 1:03d}.bvh").write_text(cmu_named_walk(path))
    out = folder / "cmu.npz"
    result = cli("train", str(folder), "--out", str(out), "--quiet")
    assert result.returncode == 0, result.stderr
    return out, folder


def test_cmu_style_capture_trains(cmu_model):
    model = load_model(cmu_model[0])
    assert model.style_names == ["old-man", "style2"]
    joints = model.metadata["skeleton"]["joints"]
    names = [j["name"] for j in joints]
    assert len(joints) == 31 and names[0] == "Hips" and "joint_Root" not in names
    assert {"LHipJoint", "RHipJoint", "LowerBack", "Neck1", "LeftFingerBase", "LeftHandIndex1", "LThumb", "RThumb"} <= set(names)
    assert all(j["channels"] == ["Zrotation", "Yrotation", "Xrotation"] for j in joints[1:])
    assert model.metadata["features"]["root"] == "Hips"


def test_cmu_style_model_synthesises_on_its_own_skeleton(cmu_model, tmp_path):
    out = tmp_path / "walk.bvh"
    result = cli("synth", "--model", str(cmu_model[0]), "--style", "old-man=1", "--seconds", "3", "--out", str(out))
    assert result.returncode == 0, result.stderr
    walk = read_bvh(out)
    assert walk.frames == 90 and walk.skeleton.names == load_model(cmu_model[0]).layout.skeleton.names


def test_cmu_style_model_streams_vmc_with_guessed_bones(cmu_model):
    receiver = Receiver()
    try:
        command = [sys.executable, "-m", "instrument", "run", "--model", str(cmu_model[0]), "--seconds", "2",
                   "--osc", f"127.0.0.1:{receiver.port}/vmc", "--quiet"]
        result = subprocess.run(command, capture_output=True, text=True, timeout=120)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and sum(1 for a, _ in receiver.messages() if a == "/VMC/Ext/OK") < 60:
            time.sleep(0.1)
    finally:
        receiver.close()
    assert result.returncode == 0, result.stderr
    messages = receiver.messages()
    bones = {p[0] for a, p in messages if a == "/VMC/Ext/Bone/Pos"}
    assert {"Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperLeg", "RightLowerLeg", "LeftFoot", "RightToes",
            "LeftUpperArm", "RightLowerArm", "LeftHand"} <= bones
    assert sum(1 for a, _ in messages if a == "/VMC/Ext/OK") == 60


def test_cmu_style_model_poses_a_normalised_avatar_as_the_capture(cmu_model):
    """The VMC pose on the 31-joint layout, by test_vmc_pose's avatar, within 5 deg of a whole take.

    The spine bend is left out: it is measured on the line from the hips to the humanoid Spine,
    and CMU's LowerBack (guessed as the Spine) sits on the hips, so that line has no direction."""
    model = load_model(cmu_model[0])
    take = read_bvh(sorted(cmu_model[1].glob("*.bvh"))[0])
    mapping = guess_humanoid(take.skeleton)
    assert mapping["LowerBack"] == "Spine" and mapping["Neck"] == "Neck" and mapping["LeftHand"] == "LeftHand"
    for root in ("hips", "path"):
        worst = compare(make_profile("vmc", model, vmc_root=root), take, mapping)
        assert_close({name: w for name, w in worst.items() if name != "spine bend"})


def test_a_model_says_so_when_it_meets_another_skeleton(cmu_model, real_walks, tmp_path):
    model = load_model(cmu_model[0])
    bandai = real_walks[0]
    with pytest.raises(UserError) as error:
        make_takes([(bandai, "normal")], read_motions([(bandai, "normal")], model.fps), model.layout)
    message = str(error.value)
    assert str(bandai) in message and "another skeleton" in message and "joint_Root" in message
    bones = tmp_path / "bones.toml"
    bones.write_text('[bones]\n"UpperLeg_L" = "LeftUpperLeg"\n')
    with pytest.raises(UserError, match="another skeleton"):
        read_humanoid(bones, model.layout.skeleton)
    result = cli("run", "--model", str(cmu_model[0]), "--seconds", "1", "--osc", "127.0.0.1:9/vmc", "--humanoid", str(bones))
    assert result.returncode == 1 and "another skeleton" in result.stderr and "Traceback" not in result.stderr


def test_mixed_skeletons_in_one_training_name_the_difference(cmu_model, real_walks, tmp_path):
    _, folder = cmu_model
    first = sorted(folder.glob("*.bvh"))[0]
    result = cli("train", str(first), str(real_walks[0]), "--out", str(tmp_path / "x.npz"), "--quiet")
    assert result.returncode == 1 and real_walks[0].name in result.stderr and "joint_Root" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


# ---- takes a user may bring that the instrument cannot model as they are: said in one line -------

def _position_columns(skeleton: Skeleton, joint: int) -> list[int]:
    start = skeleton.channel_start()[joint]
    return [start + k for k, c in enumerate(skeleton.joints[joint].channels) if c.endswith("position")]


def _scaled(motion, factor: float):
    """The take in other units: every offset and position channel times `factor`."""
    import dataclasses

    from instrument.motion.bvh import Motion

    joints = tuple(dataclasses.replace(j, offset=tuple(v * factor for v in j.offset),
                                       end_site=None if j.end_site is None else tuple(v * factor for v in j.end_site))
                   for j in motion.skeleton.joints)
    skeleton = Skeleton(joints)
    channels = motion.channels.copy()
    for j in range(len(joints)):
        channels[:, _position_columns(skeleton, j)] *= factor
    return Motion(skeleton, channels, motion.fps)


def test_a_take_in_other_units_is_named_in_training_and_in_evaluation(real_walks, tmp_path):
    from instrument.motion.bvh import write_bvh

    chosen = [p for p in real_walks if "_normal_" in p.name][:2] + [p for p in real_walks if "_active_" in p.name][:2]
    for path in chosen[:-1]:
        (tmp_path / path.name).write_bytes(path.read_bytes())
    odd = tmp_path / chosen[-1].name
    write_bvh(odd, _scaled(read_bvh(chosen[-1]), 0.01))  # one take in metres among centimetres
    result = cli("train", str(tmp_path), "--out", str(tmp_path / "x.npz"), "--quiet")
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and odd.name in result.stderr and "other units" in result.stderr
    assert not (tmp_path / "x.npz").exists()
    model = load_model(default_model_path())  # evaluation against takes in other units than the model's
    with pytest.raises(UserError, match="other units") as error:
        make_takes([(odd, "active")], read_motions([(odd, "active")], model.fps), model.layout)
    assert str(odd) in str(error.value)


def test_a_take_of_another_skeleton_is_named_against_the_skeleton_most_takes_share(real_walks, tmp_path):
    """One take of another rig sorted first: the error named the two takes of the corpus's own
    skeleton as the ones that differ (from "the first file's")."""
    odd = tmp_path / "a_walk_odd_001.bvh"
    odd.write_text(real_walks[0].read_text().replace("JOINT Hips", "JOINT pelvis"))
    pairs = [(odd, "odd"), (real_walks[0], "normal"), (real_walks[1], "normal")]
    with pytest.raises(UserError) as error:
        read_motions(pairs, 30.0)
    assert str(error.value).startswith(f"skeleton differs from that of 2 of the 3 takes ({real_walks[0]}): {odd} "
                                       f"({odd.name}: 22 joints against 22; it lacks Hips and has pelvis instead)"), error.value


def test_a_take_of_another_body_size_is_said_in_training(real_walks, tmp_path):
    """A performer 0.7 times the size of the first walk's (a child among adults, each captured on
    their own skeleton) trained without a word, and that style's walk slid its feet 14.6 cm/s on
    the model's one skeleton (the others' 0.00); 0.8 times walked with the hips 4.6% low."""
    from instrument.motion.bvh import write_bvh

    chosen = [p for p in real_walks if "_normal_" in p.name][:1] + [p for p in real_walks if "_active_" in p.name][:1]
    small = tmp_path / chosen[1].name
    write_bvh(small, _scaled(read_bvh(chosen[1]), 0.7))
    same = tmp_path / "same.bvh"
    write_bvh(same, _scaled(read_bvh(chosen[1]), 1.0))
    _, takes, warnings, _ = load_corpus([(chosen[0], "normal"), (small, "active"), (same, "calm")], 30.0)
    assert len(takes) == 3
    said = [w for w in warnings if "times the size of the skeleton the model keeps" in w]
    assert said == [f"{small}: its body is 0.70 times the size of the skeleton the model keeps (the first walk's): its "
                    "style's hips' height and speeds are learnt in the take's units and played on that skeleton (hips "
                    "low or high, strides that do not fit it); give one body size"], warnings


def test_a_root_that_moves_but_never_turns_is_a_one_line_error(real_walks, tmp_path):
    """A floor joint ('Reference') carrying the body's position above hips that turn without
    moving: the heading would be read from a joint that never turns (the walks came out at a
    third of their speed, sliding), so training says what to change."""
    from instrument.motion.bvh import Motion, write_bvh

    for path in [p for p in real_walks if "_normal_" in p.name][:2]:
        motion = read_bvh(path)
        skeleton, channels = motion.skeleton, motion.channels.copy()
        floor, hips = 0, 1  # joint_Root (never moves in these takes) and Hips
        channels[:, _position_columns(skeleton, floor)] = channels[:, _position_columns(skeleton, hips)]
        channels[:, _position_columns(skeleton, hips)] = 0.0
        write_bvh(tmp_path / path.name, Motion(skeleton, channels, motion.fps))
    result = cli("train", str(tmp_path), "--out", str(tmp_path / "x.npz"), "--quiet")
    assert result.returncode == 1 and "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert "'joint_Root' carries the body's position but never turns" in result.stderr and "'Hips'" in result.stderr
    result = cli("inspect", str(tmp_path / path.name))
    assert result.returncode == 1 and path.name in result.stderr and "never turns" in result.stderr


def test_evaluating_against_takes_of_another_skeleton_is_a_one_line_error(cmu_model, real_walks, tmp_path):
    """The takes the model names, found in the folder, but on another skeleton (the clearance of
    their feet was measured first, and failed with a traceback)."""
    model_path, folder = cmu_model
    for k, name in enumerate(sorted(p.name for p in folder.glob("*.bvh"))):
        (tmp_path / name).write_bytes(real_walks[k].read_bytes())
    result = cli("evaluate", str(model_path), "--real", str(tmp_path), "--seconds", "2", "--variants", "one")
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "another skeleton" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_a_style_whose_takes_have_no_steps_is_said_to_be_left_out(real_walks, tmp_path):
    from instrument.training.build import build_model
    from instrument.motion.bvh import Motion, write_bvh

    pairs = [(p, "normal") for p in real_walks if "_normal_" in p.name][:2]
    standing = read_bvh(pairs[0][0])
    still = tmp_path / "standing_still_001.bvh"
    write_bvh(still, Motion(standing.skeleton, np.repeat(standing.channels[:1], 90, axis=0), standing.fps))
    model, report, _ = build_model(pairs + [(still, "still")])
    assert model.style_names == ["normal"]
    assert any("'still'" in w and "no such style" in w for w in report.warnings)


# The arms and legs found from the joint tree on rigs of other conventions (motion/limbs.py).
# Offsets in cm, Y up, facing +Z, the left side at +X. `across` bends the left elbow so the hand
# swings in front of the body past its middle, as a walk's arm swing can in a template pose: the
# head is then further out on the left than any left-hand joint.
def _arm_chain(side: float, names: list[str], fingers: list[str], thumb: str | None, across: bool):
    collar, shoulder, elbow, wrist = names
    forearm = (-15.0, 0.0, 15.0) if across else (0.0, -25.0, 0.0)
    out = [(collar, None, (side * 3.0, 0.0, 0.0)), (shoulder, collar, (side * 15.0, 0.0, 0.0)),
           (elbow, shoulder, (side * -10.0, -25.0, 10.0) if across else (0.0, -28.0, 0.0)),
           (wrist, elbow, forearm)]
    parent = wrist
    for finger in fingers:
        out.append((finger, parent, (0.0, -4.0, 0.0)))
        parent = finger
    if thumb:
        out.append((thumb, wrist, (side * 2.0, -3.0, 2.0)))
    return out


def _humanoid(across: bool, spine: list[str], neck: list[str], legs: dict[float, list[str]], arms: dict[float, list[str]],
              fingers: dict[float, list[str]] | None = None, thumbs: dict[float, str] | None = None,
              hip_joints: dict[float, str] | None = None) -> Skeleton:
    """A full humanoid: spine[0] is the hips (the root); the neck chain and both arms hang from
    the spine's top; each leg (hip, knee, ankle, toes) from the hips, through a hip joint where
    given (CMU's LHipJoint)."""
    rows = [(spine[0], None, (0.0, 95.0, 0.0))] + [(j, p, (0.0, 45.0 / (len(spine) - 1), 0.0)) for p, j in pairwise(spine)]
    rows += [(j, p, (0.0, 12.0, 0.0)) for p, j in zip(spine[-1:] + neck, neck)]
    for side in (1.0, -1.0):
        parent = spine[0]
        if hip_joints:
            rows.append((hip_joints[side], parent, (0.0, 0.0, 0.0)))
            parent = hip_joints[side]
        hip, knee, ankle, toes = legs[side]
        rows += [(hip, parent, (side * 9.0, -5.0, 0.0)), (knee, hip, (0.0, -42.0, 0.0)), (ankle, knee, (0.0, -40.0, 0.0)),
                 (toes, ankle, (0.0, -6.0, 12.0))]
        arm = _arm_chain(side, arms[side], (fingers or {}).get(side, []), (thumbs or {}).get(side), across and side > 0)
        rows += [(j, p or spine[-1], o) for j, p, o in arm]
    names = [n for n, _, _ in rows]
    rotation = ("Zrotation", "Xrotation", "Yrotation")
    return Skeleton(tuple(Joint(n, names.index(p) if p else -1, o, (("Xposition", "Yposition", "Zposition") if p is None else ())
                                + rotation) for n, p, o in rows))


def _sided(left: list[str], right: list[str]) -> dict[float, list[str]]:
    return {1.0: left, -1.0: right}


RIGS = {  # each rig, with the left hand hanging or swung across (see _arm_chain)
    "Bandai": lambda across: _humanoid(across, ["Hips", "Spine", "Chest"], ["Neck", "Head"],
                        _sided(["UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L"], ["UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"]),
                        _sided(["Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L"], ["Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R"])),
    "CMU 31 joints": lambda across: _humanoid(across, ["Hips", "LowerBack", "Spine", "Spine1"], ["Neck", "Neck1", "Head"],
                               _sided(["LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"], ["RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"]),
                               _sided(["LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"], ["RightShoulder", "RightArm", "RightForeArm", "RightHand"]),
                               _sided(["LeftFingerBase", "LeftHandIndex1"], ["RightFingerBase", "RightHandIndex1"]),
                               {1.0: "LThumb", -1.0: "RThumb"}, {1.0: "LHipJoint", -1.0: "RHipJoint"}),
    "Mixamo": lambda across: _humanoid(across, ["mixamorig:Hips", "mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2"], ["mixamorig:Neck", "mixamorig:Head", "mixamorig:HeadTop_End"],
                        _sided([f"mixamorig:Left{j}" for j in ("UpLeg", "Leg", "Foot", "ToeBase")], [f"mixamorig:Right{j}" for j in ("UpLeg", "Leg", "Foot", "ToeBase")]),
                        _sided([f"mixamorig:Left{j}" for j in ("Shoulder", "Arm", "ForeArm", "Hand")], [f"mixamorig:Right{j}" for j in ("Shoulder", "Arm", "ForeArm", "Hand")]),
                        _sided(["mixamorig:LeftHandIndex1", "mixamorig:LeftHandIndex2"], ["mixamorig:RightHandIndex1", "mixamorig:RightHandIndex2"]),
                        {1.0: "mixamorig:LeftHandThumb1", -1.0: "mixamorig:RightHandThumb1"}),
    "23-joint suit": lambda across: _humanoid(across, ["Hips", "Chest", "Chest2", "Chest3", "Chest4"], ["Neck", "Head"],
                               _sided([f"Left{j}" for j in ("Hip", "Knee", "Ankle", "Toe")], [f"Right{j}" for j in ("Hip", "Knee", "Ankle", "Toe")]),
                               _sided([f"Left{j}" for j in ("Collar", "Shoulder", "Elbow", "Wrist")], [f"Right{j}" for j in ("Collar", "Shoulder", "Elbow", "Wrist")])),
}
JOINT_COUNTS = {"CMU 31 joints": 31, "23-joint suit": 23}
ARMS = {"Bandai": [("UpperArm_L", "LowerArm_L"), ("UpperArm_R", "LowerArm_R")],
        "CMU 31 joints": [("LeftArm", "LeftForeArm"), ("RightArm", "RightForeArm")],
        "Mixamo": [("mixamorig:LeftArm", "mixamorig:LeftForeArm"), ("mixamorig:RightArm", "mixamorig:RightForeArm")],
        "23-joint suit": [("LeftShoulder", "LeftElbow"), ("RightShoulder", "RightElbow")]}


def _limb_names(skeleton: Skeleton, template: np.ndarray) -> tuple[list, list]:
    limbs = find_limbs(skeleton, 0, template)
    names = skeleton.names
    return (sorted((names[s], names[e]) for s, e in limbs.arms),
            sorted((names[leg.hip], names[leg.knee], names[leg.ankle]) for leg in limbs.legs))


@pytest.mark.parametrize("across", [False, True], ids=["hanging", "hand across"])
@pytest.mark.parametrize("rig", RIGS)
def test_both_arms_are_found_on_rigs_of_every_convention(rig, across):
    skeleton = RIGS[rig](across)
    if rig in JOINT_COUNTS:
        assert len(skeleton.joints) == JOINT_COUNTS[rig]
    template = np.zeros(sum(len(j.channels) for j in skeleton.joints))
    template[1] = 95.0
    arms, legs = _limb_names(skeleton, template)
    assert arms == ARMS[rig]
    assert len(legs) == 2 and all(skeleton.names.index(hip) < skeleton.names.index(knee) for hip, knee, _ in legs)


@needs_walks
def test_both_arms_of_the_shared_skeleton_in_every_pose_of_the_takes():
    """Every 10th frame of a real take of each style as the template pose: the hands swing
    across the body's middle in some of them (the neck was then taken for an arm in 1 frame in 11)."""
    found = set()
    for take in sorted(SHARED_WALKS.glob("*_001.bvh")):
        motion = read_bvh(take)
        names = motion.skeleton.names
        root = names.index("Hips")
        found |= {tuple(sorted((names[s], names[e]) for s, e in find_limbs(motion.skeleton, root, frame).arms))
                  for frame in motion.channels[::10]}
    assert found == {(("UpperArm_L", "LowerArm_L"), ("UpperArm_R", "LowerArm_R"))}


def test_styles_that_differ_only_in_case_are_said_to_be_two(real_walks):
    """A manifest keeps its styles' case and a file name's is read lower-cased, so `Normal` in a
    manifest and `normal` from a name train two styles: training says so."""
    from instrument.training.corpus import load_corpus

    normal = [p for p in real_walks if "_normal_" in p.name][:2]
    _, takes, warnings, _ = load_corpus([(normal[0], "Normal"), (normal[1], "normal")], 30.0)
    assert {t.style for t in takes} == {"Normal", "normal"}
    assert "styles 'Normal' and 'normal' differ only in case: the model has them as 2 styles" in warnings
    _, _, warnings, _ = load_corpus([(normal[0], "normal"), (normal[1], "normal")], 30.0)
    assert not any("differ only in case" in w for w in warnings)
