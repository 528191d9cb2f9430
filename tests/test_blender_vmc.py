"""Blender, headless, drives rigs that are not ours from the VMC stream with the shipped add-on,
and saves what it recorded; in Debian's Blender 3.4 and in PyPI's bpy 4.5 LTS and 5.0.

Per Blender, one `instrument run` feeds two Blender processes over UDP:
- tests/blender/vmc_addon_check.py drives four rigs made from the rest skeleton `instrument
  skeleton` writes: one per bone-name preset of the add-on (Mixamo, Rigify, VRM), each changed
  the way someone else's rig differs (another size, an A-pose, feet turned out, other bone
  rolls), and the rest as imported with a pose applied as its rest pose; it records each rig
  into an Action and saves the scene;
- the add-on itself, run as a headless batch recording (`--rest --record --save`).
Both .blend files are then opened again (tests/blender/blend_check.py): every rig's joints at
the last recorded frame must land where the sent pose puts them (that pose rebuilt here from the
received messages on the rest skeleton, independently of the add-on), and each recording must
hold one key per received frame on consecutive frames.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from blender_hosts import HOSTS, blender_command, blender_env
from oscrecv import free_port
from vmcpose import sent_pose

ROOT = Path(__file__).resolve().parents[1]
ADDON = ROOT / "examples" / "blender" / "instrument_vmc.py"
CHECK = ROOT / "tests" / "blender" / "vmc_addon_check.py"
READ = ROOT / "tests" / "blender" / "blend_check.py"
UNITY_TO_BLENDER = np.array([[-1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
FRAMES, SCALE = 45, 1.3
RIGS = ("MIXAMO", "RIGIFY", "VRM", "APPLIED")
ENDS = {"Head", "LeftHand", "RightHand", "LeftToes", "RightToes"}
INSTRUMENT = [sys.executable, "-m", "instrument"]


def listening(process: subprocess.Popen) -> None:
    """Wait until a Blender script says it listens (fails with its output if it ends first)."""
    seen = []
    for line in process.stdout:
        seen.append(line)
        if "listening on" in line:
            return
    process.wait()
    pytest.fail(f"Blender ended before listening (exit {process.returncode}):\n" + "".join(seen)[-3000:])


@pytest.fixture(scope="module")
def rest(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("blender_rest") / "rest.bvh"
    assert subprocess.run(INSTRUMENT + ["skeleton", "--out", str(path)], capture_output=True).returncode == 0
    return path


@pytest.fixture(scope="module", params=HOSTS)
def driven(request, rest, tmp_path_factory) -> dict:
    """After one `instrument run` fed the check and the add-on's batch recording in one Blender:
    the check's report, and both saved .blend files as read back."""
    host = request.param
    folder = tmp_path_factory.mktemp(f"blender_vmc_{host}")
    report, rigs_blend, take_blend, saved = (folder / n for n in ("report.json", "rigs.blend", "take.blend", "saved.json"))
    env = blender_env(folder)
    check_port = take_port = free_port()
    while take_port == check_port:
        take_port = free_port()
    processes = [
        subprocess.Popen(blender_command(host, CHECK, str(ADDON), str(rest), str(check_port), str(FRAMES), str(SCALE),
                                         str(report), str(rigs_blend)),
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env),
        subprocess.Popen(blender_command(host, ADDON, "--rest", str(rest), "--port", str(take_port), "--frames",
                                         str(FRAMES), "--timeout", "120", "--record", "--save", str(take_blend)),
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)]
    try:
        for process in processes:
            listening(process)
        run = subprocess.run(INSTRUMENT + ["run", "--seconds", "3", "--osc", f"127.0.0.1:{check_port}/vmc",
                                           "--osc", f"127.0.0.1:{take_port}/vmc", "--vmc-root", "path", "--quiet"],
                             capture_output=True, text=True, timeout=180)
        outputs = [process.communicate(timeout=180)[0] for process in processes]
    finally:
        for process in processes:
            process.kill()
    assert run.returncode == 0, run.stderr
    for process, output in zip(processes, outputs):
        assert process.returncode == 0, output[-3000:]
    assert f"saved {FRAMES} recorded frames to {take_blend}" in outputs[1]
    read = subprocess.run(blender_command(host, READ, str(saved), str(rigs_blend), str(take_blend)),
                          capture_output=True, text=True, timeout=300, env=env)
    assert read.returncode == 0, (read.stdout + read.stderr)[-3000:]
    files = json.loads(saved.read_text())
    return {"host": host, "report": json.loads(report.read_text()), "rigs": files[str(rigs_blend)],
            "take": files[str(take_blend)]}


def test_the_scene_takes_the_rest_files_rate(driven):
    assert driven["report"]["fps"] == 30.0
    assert driven["rigs"]["fps"] == driven["take"]["fps"] == 30.0  # and keeps it in the saved files


@pytest.mark.parametrize("rig", RIGS)
def test_addon_drives_the_rig_within_a_centimetre(rest, driven, rig):
    """At the last recorded frame of the saved file, every driven joint and the ends of the hands,
    head and toes are where the sent pose puts them (after the rig's scale)."""
    result = driven["report"]["rigs"][rig]
    assert result["count"] == FRAMES
    assert result["operators"]  # Start and Stop from the panel work with this rig and its preset
    saved = driven["rigs"]["armatures"][result["object"]]
    assert saved["frame"] == result["last_frame"]
    expected, ends = sent_pose(rest, driven["report"]["messages"])
    names = result["names"]
    assert len(names) == 21 and ENDS <= set(names)
    for human, bone in names.items():
        ours = UNITY_TO_BLENDER @ expected[human]
        head = np.array(saved["heads"][bone]) / result["scale"]
        assert np.linalg.norm(head - ours) < 0.01, (driven["host"], rig, human, head, ours)
    for human in ENDS:  # the end bones point the sent way too
        ours = UNITY_TO_BLENDER @ ends[human]
        tail = np.array(saved["tails"][names[human]]) / result["scale"]
        assert np.linalg.norm(tail - ours) < 0.01, (driven["host"], rig, human, tail, ours)


@pytest.mark.parametrize("rig", RIGS)
def test_addon_records_one_key_per_frame(driven, rig):
    result = driven["report"]["rigs"][rig]
    keys = driven["rigs"]["armatures"][result["object"]]["keys"]
    assert set(keys) == set(result["names"].values()) and len(keys) == 21
    for bone, frames in keys.items():
        assert len(frames) == FRAMES and np.all(np.diff(frames) == 1.0), (driven["host"], rig, bone, frames[:5])


def test_batch_recording_saves_what_it_recorded(driven):
    """The add-on run headless with --record --save: the saved file has one key per received
    frame on every driven bone of the imported rest."""
    (armature,) = driven["take"]["armatures"].values()
    keys = armature["keys"]
    assert len(keys) == 21
    for bone, frames in keys.items():
        assert len(frames) == FRAMES and np.all(np.diff(frames) == 1.0), (driven["host"], bone, frames[:5])


def test_rigs_are_rested_as_the_check_says(driven):
    """The rigs differ from the sent rest as described: arms 40 deg down, the applied spine 10 deg
    forward, bones named by the presets (so a rig found its bones by its preset, not by luck)."""
    rigs = driven["report"]["rigs"]
    for rig in RIGS:
        assert abs(rigs[rig]["rest_arm_drop"] - 40.0) < 0.5, (rig, rigs[rig]["rest_arm_drop"])
    assert abs(rigs["APPLIED"]["rest_spine_lean"] - 10.0) < 0.5, rigs["APPLIED"]["rest_spine_lean"]
    assert abs(rigs["MIXAMO"]["rest_spine_lean"]) < 0.5
    assert rigs["MIXAMO"]["names"]["LeftUpperArm"] == "mixamorig:LeftArm"
    assert rigs["RIGIFY"]["names"]["LeftUpperArm"] == "upper_arm.L"
    assert rigs["VRM"]["names"]["LeftUpperArm"] == "J_Bip_L_UpperArm"


@pytest.mark.parametrize("host", HOSTS)
def test_batch_recording_refuses_to_start_without_a_place_to_save(rest, tmp_path, host):
    """Nothing is recorded that could not be kept: no --save (and no .blend open), or a --save
    file that exists without --force, ends the run before it listens, saying why."""
    kept = tmp_path / "kept.blend"
    kept.write_bytes(b"an earlier take")
    for extra, reason in (([], "needs --save FILE.blend"), (["--save", str(kept)], "already exists; give --force")):
        result = subprocess.run(blender_command(host, ADDON, "--rest", str(rest), "--port", str(free_port()), "--record",
                                                *extra),
                                capture_output=True, text=True, timeout=300, env=blender_env(tmp_path))
        assert result.returncode != 0 and reason in result.stdout + result.stderr, (host, result.stdout[-2000:])
        assert "listening on" not in result.stdout
    assert kept.read_bytes() == b"an earlier take"
