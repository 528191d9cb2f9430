"""Unattended operation: systemd's notify protocol with the test as the listener (READY=1, the
frame loop petting the watchdog, a frozen loop caught and restarted), the health line and the
status endpoint over real UDP, the generated unit, and attract mode with pick-up."""

import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from conftest import REPO
from instrument.cli.showplan import kept_names
from instrument.control.attract import Attract, AttractSettings
from instrument.control.events import ControlEvent
from instrument.control.hub import ControlHub
from instrument.control.mapping import load_mapping
from instrument.control.score import preset_tour
from instrument.control.state import ControlState
from instrument.motion.bvh import read_bvh
from instrument.terminal import Console
from instrument.runtime.health import Health
from instrument.runtime.notify import SystemdNotifier
from instrument.runtime.performance import Show, perform
from oscrecv import Receiver, frame_count, free_port
from waiting import StderrLines, wait_until

RUN = [sys.executable, "-m", "instrument", "run"]


class NotifyListener:
    """What systemd does with $NOTIFY_SOCKET: a unix datagram socket, each message timed on arrival."""

    def __init__(self, tmp_path, abstract: bool = False):
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        if abstract:
            name = f"instrument-test-{os.getpid()}-{time.monotonic_ns()}"
            self.sock.bind("\0" + name)
            self.env = "@" + name
        else:
            path = str(tmp_path / "notify.sock")
            self.sock.bind(path)
            self.env = path
        self.sock.settimeout(0.1)
        self.received: list[tuple[float, str]] = []
        self.running = True
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        while self.running:
            try:
                data = self.sock.recv(4096)
            except socket.timeout:
                continue
            except OSError:
                return
            self.received.append((time.monotonic(), data.decode()))

    def times(self, word: str) -> list[float]:
        return [t for t, text in self.received if word in text.split("\n")]

    def wait_for(self, word: str, count: int = 1, timeout: float = 90.0, after: float = 0.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if len([t for t in self.times(word) if t > after]) >= count:
                return True
            time.sleep(0.02)
        return False

    def close(self):
        self.running = False
        self.thread.join(2)
        self.sock.close()


class Freezer:
    """An output that hangs when told to, as a stuck renderer call would: the loop freezes."""

    name = "freezer"

    def __init__(self):
        self.go = threading.Event()
        self.go.set()
        self.stuck = threading.Event()  # set while a frame is held in send()
        self.frames = 0

    def prepare(self, frame):
        return frame.index

    def send(self, index):
        self.frames += 1
        if not self.go.is_set():
            self.stuck.set()
            self.go.wait()
            self.stuck.clear()

    def close(self):
        pass


def test_the_frame_loop_pets_the_watchdog_and_a_frozen_loop_stops(model, tmp_path):
    listener = NotifyListener(tmp_path)
    # WatchdogSec: systemd kills a service that sends no WATCHDOG=1 for this long. 5 s, as the unit the
    # tests below write (`service --watchdog 5`; its default is 10). The loop pets every third of it
    # (notify.PETS_PER_INTERVAL), so the widest gap asserted below leaves two pets' room for slow frames.
    # At 2 s (a pet every 0.67 s) a frame held up over 1.3 s on the loaded machine (load ~6 on the
    # shared 2 cores) failed the test though neither of those units' watchdogs would have fired: the
    # loop's petting is unchanged, the test's interval is now a real unit's
    watchdog = 5.0
    notifier = SystemdNotifier({"NOTIFY_SOCKET": listener.env, "WATCHDOG_USEC": str(int(watchdog * 1e6))})
    freezer = Freezer()
    health = Health(Console(quiet=True), [freezer], [], notifier, every=0)
    seen = {}

    def all_sent_so_far_received(word: str) -> bool:
        """A marker sent now arrives after every datagram sent before it (a unix datagram socket keeps order)."""
        marker = SystemdNotifier({"NOTIFY_SOCKET": listener.env})
        count = len(listener.times(word)) + 1
        marker.send(word)
        marker.close()
        return listener.wait_for(word, count=count)

    def systemd_side():  # the loop runs on the main thread (it owns the signals); this watches it
        try:
            seen["ready"] = listener.wait_for("READY=1")
            seen["petted"] = listener.wait_for("WATCHDOG=1", count=4)
            pets = listener.times("WATCHDOG=1")
            seen["widest gap"] = max(b - a for a, b in zip(pets, pets[1:]))
            freezer.go.clear()  # the loop hangs in its output
            seen["frozen"] = freezer.stuck.wait(60)
            all_sent_so_far_received("X-TEST=frozen")
            before = len(listener.times("WATCHDOG=1"))
            last = listener.times("WATCHDOG=1")[-1]
            while time.monotonic() < last + 1.5 * watchdog:  # until systemd would have given up on it
                time.sleep(0.05)
            all_sent_so_far_received("X-TEST=frozen")
            seen["silent while frozen"] = len(listener.times("WATCHDOG=1")) == before and freezer.stuck.is_set()
            freezer.go.set()  # the loop comes back: petting resumes
            seen["petted again"] = listener.wait_for("WATCHDOG=1", count=before + 1)
        finally:
            freezer.go.set()
            os.kill(os.getpid(), signal.SIGTERM)  # ends the performance as systemd's stop does

    watcher = threading.Thread(target=systemd_side, daemon=True)
    watcher.start()
    try:
        perform(Show(model, [freezer], fps=30, seconds=120.0), Console(quiet=True), on_frame=health.frame)
    finally:
        watcher.join(30)
        listener.close()
    assert seen == {"ready": True, "petted": True, "widest gap": seen["widest gap"], "frozen": True,
                    "silent while frozen": True, "petted again": True}
    assert seen["widest gap"] < watchdog  # what systemd kills at: a running loop never lets its watchdog fire
    assert listener.received[0][1].startswith("READY=1")


def test_a_frozen_instrument_is_restarted_by_its_watchdog(tmp_path):
    """The test plays systemd for a real `instrument run`: notify socket (abstract, as systemd's
    own), WatchdogSec=2, and on a silent watchdog it kills and restarts the service."""
    listener = NotifyListener(tmp_path, abstract=True)
    env = dict(os.environ, NOTIFY_SOCKET=listener.env, WATCHDOG_USEC="2000000")
    starts, processes = [], []
    try:
        for attempt in range(2):
            started = time.monotonic()
            process = subprocess.Popen(RUN + ["--no-osc", "--quiet", "--normal-priority"], env=env,
                                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            processes.append(process)
            assert listener.wait_for("READY=1", after=started), "no READY=1"
            starts.append(started)
            assert listener.wait_for("WATCHDOG=1", count=3, after=started)
            if attempt == 0:
                process.send_signal(signal.SIGSTOP)  # the whole process freezes, as a deadlocked loop would
                frozen = time.monotonic()
                while time.monotonic() - listener.times("WATCHDOG=1")[-1] < 2.0:  # systemd's WatchdogSec check
                    assert time.monotonic() - frozen < 30
                    time.sleep(0.05)
                process.send_signal(signal.SIGABRT)  # what systemd sends on a watchdog timeout
                process.send_signal(signal.SIGCONT)
                assert process.wait(30) != 0  # a failure: Restart=on-failure restarts it
        last = processes[-1]
        last.terminate()
        assert last.wait(30) == 0
        assert listener.wait_for("STOPPING=1", after=starts[-1], timeout=5)
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
            process.communicate()
        listener.close()
    assert len(listener.times("READY=1")) == 2


class StatusAsker:
    """Asks an instrument's status port over real UDP, waiting generously for each reply."""

    def __init__(self, port: int):
        self.port, self.replies = port, {}
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(10)  # a busy machine may answer late: then the request is sent again

    def ask(self, request: bytes) -> bytes:
        """The reply to `request` (an OSC one starts with "/", a JSON one with "{"); a late reply
        to an earlier request that crosses it is kept as the newest of its kind."""
        wanted = b"/" if request.startswith(b"/") else b"{"
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            self.sock.sendto(request, ("127.0.0.1", self.port))
            try:
                reply = self.sock.recv(65536)
            except socket.timeout:
                continue
            except ConnectionRefusedError:  # not listening yet: the instrument is still starting
                time.sleep(0.2)
                continue
            self.replies[reply[:1]] = reply
            if reply[:1] == wanted:
                return reply
        raise AssertionError(f"no reply to {request!r} in 120 s")

    def osc(self):
        from pythonosc.osc_message import OscMessage

        return OscMessage(self.ask(b"/walk/status\0\0\0\0,\0\0\0"))  # an OSC message without arguments

    def json(self) -> dict:
        return json.loads(self.ask(b"status"))

    def close(self) -> None:
        self.sock.close()


def test_health_line_and_status_endpoint_over_udp(tmp_path):
    receiver, status_port, dead = Receiver(), free_port(), free_port()
    process = subprocess.Popen(RUN + ["--osc", f"127.0.0.1:{receiver.port}/flat", "--osc", f"127.0.0.1:{dead}/flat",
                                      "--status-port", str(status_port), "--health-every", "1", "--seconds", "60", "--quiet"],
                               stderr=subprocess.PIPE, text=True)
    asker = StatusAsker(status_port)
    try:
        wait_until(lambda: asker.json()["uptime"] >= 2.5, "2.5 s of the run's own uptime (a health line due)", every=0.2)
        osc, report = asker.osc(), asker.json()
    finally:
        process.terminate()
        stderr = process.communicate(timeout=60)[1]
        receiver.close()
        asker.close()
    assert process.returncode == 0, stderr
    frames, late, dropped, uptime, rss, files, outputs, devices = osc.params
    assert osc.address == "/walk/status" and frames > 0 and uptime > 0 and rss > 10 and files > 2
    assert f"osc 127.0.0.1:{receiver.port}/flat up" in outputs and f"osc 127.0.0.1:{dead}/flat down" in outputs
    assert report["frames"] > 0 and report["outputs"][f"osc 127.0.0.1:{dead}/flat"] == "down"
    lines = [line for line in stderr.splitlines() if line.startswith("health: ")]
    assert lines and "frames" in lines[-1] and "late" in lines[-1] and f"{dead}/flat down" in lines[-1]


def test_health_never_tells_the_console_token_and_an_unresolved_target_is_down(tmp_path):
    """The token was in every health line (the journal, systemd's STATUS=) and in the status
    port's replies, which anyone who reaches the port gets; a target whose name never resolved
    sent nothing, so nothing failed, and it was reported up."""
    receiver, status_port, listener = Receiver(), free_port(), NotifyListener(tmp_path)
    token = "s3cr3t-tok3n"
    process = subprocess.Popen(RUN + ["--console", "127.0.0.1:0", "--console-token", token, "--osc", "nowhere.invalid:9000/flat",
                                      "--osc", f"127.0.0.1:{receiver.port}/flat", "--status-port", str(status_port),
                                      "--health-every", "1", "--seconds", "60", "--quiet"],
                               stderr=subprocess.PIPE, text=True, env=dict(os.environ, NOTIFY_SOCKET=listener.env))
    stderr_lines = StderrLines(process)
    asker = StatusAsker(status_port)
    try:
        wait_until(lambda: any("STATUS=health:" in text for _, text in listener.received), "a health line to systemd")
        wait_until(lambda: any(line.startswith("health: ") for line in stderr_lines.lines), "a health line")
        osc, report = asker.osc(), asker.json()
    finally:
        process.terminate()
        process.wait(60)
        stderr_lines.thread.join(10)
        receiver.close()
        asker.close()
        listener.close()
    stderr = "".join(stderr_lines.lines)
    assert process.returncode == 0, stderr
    assert f"?token={token}" in stderr  # said once at start: the URL to open
    health = [line for line in stderr.splitlines() if line.startswith("health: ")]
    said = health + [text for _, text in listener.received] + [str(osc.params), json.dumps(report)]
    assert not [text for text in said if token in text]
    assert any("console http://127.0.0.1:" in text for text in said)  # the console is still named
    assert report["outputs"]["osc nowhere.invalid:9000/flat"] == "down"
    assert report["outputs"][f"osc 127.0.0.1:{receiver.port}/flat"] == "up"
    assert "osc nowhere.invalid:9000/flat down" in osc.params[6] and "osc nowhere.invalid:9000/flat down" in health[-1]


def test_the_generated_unit_restarts_on_failure_with_a_watchdog(tmp_path):
    show = tmp_path / "show.toml"
    show.write_text('osc = ["127.0.0.1:9000/flat"]\n')
    unit = tmp_path / "walk.service"
    result = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out", str(unit),
                             "--watchdog", "5"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    text = unit.read_text()
    # SIGTERM (or SIGINT) while a first start compiles ends run with 143 (130): a stop, not a failure
    for line in ("Type=notify", "Restart=on-failure", "SuccessExitStatus=130 143", "WatchdogSec=5", "LimitRTPRIO=5",
                 "WantedBy=multi-user.target",
                 f'ExecStart="{sys.executable}" "-m" "instrument" "run" "--config" "{show.resolve()}" "--quiet" '
                 '"--keep-recordings"'):
        assert line in text.splitlines(), line
    again = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out", str(unit)],
                           capture_output=True, text=True, timeout=60)
    assert again.returncode == 1 and "already exists" in again.stderr and unit.read_text() == text
    if shutil.which("systemd-analyze"):  # systemd's own reading of the file
        check = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, timeout=60)
        assert check.returncode == 0, check.stderr
        assert "Unknown key" not in check.stderr and "Unknown section" not in check.stderr
    user_unit = tmp_path / "user.service"
    result = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out", str(user_unit), "--user"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and "systemctl --user" in result.stdout
    assert "WantedBy=default.target" in user_unit.read_text().splitlines() and "User=" not in user_unit.read_text()
    missing = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(tmp_path / "nope.toml"), "--out",
                              str(tmp_path / "x.service")], capture_output=True, text=True, timeout=60)
    assert missing.returncode == 1 and "nope.toml" in missing.stderr and len(missing.stderr.strip().splitlines()) == 1


def test_a_restarted_service_records_beside_the_take_before_the_crash(tmp_path):
    """A restart after a crash must neither fail on the night's recording (it exists) nor write
    over it (`force = true`): the unit's own command keeps it and records NAME-2 beside it, the
    BVH and the controller log under one number."""
    show = tmp_path / "show.toml"
    show.write_text('no-osc = true\nseconds = 2\nbvh = "night.bvh"\nrecord = "night.jsonl"\n')
    unit = tmp_path / "walk.service"
    made = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out", str(unit)],
                          capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    start = next(line for line in unit.read_text().splitlines() if line.startswith("ExecStart="))
    command = shlex.split(start.removeprefix("ExecStart="))  # (no `%`, `$` or `\` in these paths to unescape)
    assert command[:3] == [sys.executable, "-m", "instrument"]
    night, log = tmp_path / "night.bvh", tmp_path / "night.jsonl"

    def frames(path) -> int:
        match = re.search(r"Frames:\s*(\d+)", path.read_text()) if path.exists() else None
        return int(match.group(1)) if match else 0

    crashed = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: frames(night) >= 10, "the first start's recording to have frames", timeout=120)
    finally:
        crashed.kill()  # a crash: systemd's Restart=on-failure starts the same command again
        crashed.communicate()
    taken, taken_log = night.read_bytes(), log.read_bytes()
    again = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out", str(unit),
                            "--force"], capture_output=True, text=True, timeout=60)
    assert again.returncode == 0, again.stderr  # the unit's check does not refuse a show whose take exists
    restarted = subprocess.run(command, capture_output=True, text=True, timeout=180)
    assert restarted.returncode == 0, restarted.stderr
    assert night.read_bytes() == taken and log.read_bytes() == taken_log  # the take before the crash, untouched
    assert read_bvh(tmp_path / "night-2.bvh").frames == 60  # the restart's 2 s at 30 fps
    assert json.loads((tmp_path / "night-2.jsonl").read_text().splitlines()[0])  # its log, under the same number
    (tmp_path / "night-2.bvh").unlink()  # a number either recording holds is taken for both
    assert kept_names(str(night), str(log)) == [str(tmp_path / "night-3.bvh"), str(tmp_path / "night-3.jsonl")]
    show.write_text(show.read_text() + "force = true\n")  # the old advice for restarts: now a contradiction
    forced = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out",
                             str(tmp_path / "forced.service")], capture_output=True, text=True, timeout=60)
    assert forced.returncode == 1 and len(forced.stderr.strip().splitlines()) == 1
    assert f"{show}:5: force: --force replaces recordings and --keep-recordings" in forced.stderr


def test_attract_drifts_when_idle_and_a_fader_takes_over_with_pickup(model):
    """A nanoKONTROL2 fader (its shipped mapping, pick-up on) through the hub: after a second
    with no input the walk tours the presets; the fader's first move ends the tour at once,
    and it takes the style only when it reaches where the tour left it."""
    state = ControlState(model.style_names, model.states)
    mapping = load_mapping(REPO / "mappings" / "korg-nanokontrol2.toml", state)
    fader = next(c for c in mapping.controls if c.target == "style/elderly" and c.message == "cc")
    low, high = fader.range
    presets = {"old": {"style/elderly": 1.0}, "young": {"style/elderly": -0.5}}
    hub = ControlHub([mapping], presets)
    console = Console(quiet=True)

    def cc(value: float) -> int:  # the 7-bit fader position for a target value
        return round((value - low) / (high - low) * 127)

    script = {15: cc(0.0), 150: cc(0.2), 160: cc(0.4), 170: cc(0.6), 180: cc(0.8), 190: cc(0.85), 200: cc(1.2)}
    frame = {"k": -1}

    def fader_source(now: float) -> list[ControlEvent]:
        k = round(now * 30)
        if k == frame["k"] or k not in script:
            return []
        frame["k"] = k
        return [ControlEvent(now, "midi:nanoKONTROL2", f"cc/{fader.channel}/{fader.number}", float(script[k]))]

    tour = preset_tour(["old", "young"], presets, morph=1.0, hold=30.0)
    attract = Attract(AttractSettings(after=1.0, score=tour), [fader_source], state, console)
    seen = []

    class Watch:
        name = "watch"

        def prepare(self, frame):
            return frame.echo["style/elderly"], attract.active

        def send(self, values):
            seen.append(values)

        def close(self):
            pass

    show = Show(model, [Watch()], fps=30, seconds=8.0, apply=hub.apply, state=state, fast=True,
                sources=[attract.poll])
    perform(show, console)
    assert not any(active for _, active in seen[:45])  # the fader was touched at frame 15: idle from then on
    assert seen[50][1] and 0.0 < seen[60][0] < 1.0 and seen[100][0] == 1.0  # the tour eased into "old"
    assert seen[149] == (1.0, True)
    assert seen[150] == (1.0, False)  # the fader's move ends the tour; pick-up: nothing jumps
    assert [seen[k][0] for k in (160, 170, 180, 190)] == [1.0] * 4  # below the parameter: not picked up
    assert seen[200][0] == pytest.approx(1.2, abs=0.03)  # crossed it: the fader has the style
    assert not any(active for _, active in seen[150:225]) and seen[235][1]  # idle again a second after the last move


def test_a_show_file_attract_mode_over_osc(tmp_path):
    """The whole path: a show file's [attract] table, an OSC surface on real UDP, the flat echo.
    Idle: the tour eases in. A performer's touches end it, and while they go on it stays off and
    the walk stays where the tour left it; when they stop, it comes back."""
    from pythonosc.udp_client import SimpleUDPClient

    control_port, receiver = free_port(), Receiver()
    show = tmp_path / "show.toml"
    show.write_text(f'osc-in = "{control_port}"\nosc = ["127.0.0.1:{receiver.port}/flat"]\nseconds = 300\n'
                    '[presets.old]\n"style/elderly" = 1.0\n[presets.young]\n"style/youthful" = 1.0\n'
                    '[attract]\nafter = 0.05\npresets = ["old", "young"]\nmorph = 0.5\nhold = 600\n')
    process = subprocess.Popen(RUN + ["--config", str(show)], stderr=subprocess.PIPE, text=True)
    stderr = StderrLines(process)
    surface = SimpleUDPClient("127.0.0.1", control_port)

    def echoed(address: str) -> list[float]:
        return [p[0] for a, p in receiver.messages() if a == address]

    def touching(condition) -> bool:  # a performer at the surface, one touch per poll (well within the 3 s idle time)
        surface.send_message("/walk/speed", 1.3)
        return condition()

    try:
        wait_until(lambda: 1.0 in echoed("/walk/style/elderly"), "the tour to reach the 'old' preset")  # idle 3 s
        wait_until(lambda: touching(lambda: stderr.count("attract mode off")), "attract mode off")
        touched = frame_count(receiver)
        wait_until(lambda: touching(lambda: frame_count(receiver) >= touched + 60), "60 more frames while touching")
        during = echoed("/walk/style/elderly")[touched:]
        on_while_touching = stderr.count("attract mode on")
        stderr.wait_for("attract mode on", times=2)  # nobody touches: the tour comes back
    finally:
        process.terminate()
        process.wait(60)
        receiver.close()
    assert process.returncode == 0, stderr.text()
    elderly = echoed("/walk/style/elderly")
    assert len(set(elderly)) > 5 and max(elderly) == 1.0  # eased in, not jumped
    assert on_while_touching == 1  # the tour stayed off while the performer played ...
    assert len(during) >= 60 and set(during) == {1.0}  # ... and the walk stayed where the tour left it
    assert 1.3 in [round(v, 3) for v in echoed("/walk/speed")]  # the performer's own move went through


def test_a_show_file_attract_mode_plays_a_score_and_an_osc_move_takes_over(tmp_path):
    """`[attract] score = "idle.toml"`: while idle the score's ramps reach the OSC output (eased,
    in order); the performer's OSC move ends it and has the target from then on."""
    from pythonosc.udp_client import SimpleUDPClient

    control_port, receiver = free_port(), Receiver()
    (tmp_path / "idle.toml").write_text('name = "night drift"\n'
                                        '[[cue]]\nramp = { "style/elderly" = 1.0 }\nover = 0.5\ncurve = "ease"\n'
                                        '[[cue]]\nramp = { speed = 1.4 }\nover = 0.5\n[[cue]]\nhold = 600\n')
    show = tmp_path / "show.toml"
    show.write_text(f'osc-in = "{control_port}"\nosc = ["127.0.0.1:{receiver.port}/flat"]\nseconds = 300\n'
                    '[attract]\nafter = 0.05\nscore = "idle.toml"\n')
    process = subprocess.Popen(RUN + ["--config", str(show)], stderr=subprocess.PIPE, text=True)
    stderr = StderrLines(process)
    surface = SimpleUDPClient("127.0.0.1", control_port)

    def echoed(address: str) -> list[float]:
        return [round(p[0], 4) for a, p in receiver.messages() if a == address]

    def touching(condition) -> bool:  # the performer holds the style at 0.3, one message per poll
        surface.send_message("/walk/style/elderly", 0.3)
        return condition()

    try:
        wait_until(lambda: 1.4 in echoed("/walk/speed"), "the score's second ramp to end")  # idle 3 s, then 1 s of ramps
        wait_until(lambda: touching(lambda: stderr.count("attract mode off")), "attract mode off")
        wait_until(lambda: touching(lambda: echoed("/walk/style/elderly")[-30:] == [0.3] * 30), "30 frames at 0.3")
    finally:
        process.terminate()
        process.wait(60)
        receiver.close()
    assert process.returncode == 0, stderr.text()
    assert "attract mode on" in stderr.text() and "playing night drift" in stderr.text()
    elderly, speed = echoed("/walk/style/elderly"), echoed("/walk/speed")
    reached = elderly.index(1.0)
    assert len(set(elderly[:reached])) > 5 and speed[:reached] == [1.0] * reached  # eased in; speed waited its turn
    assert len(set(speed)) > 5 and max(speed) == 1.4  # the second ramp, eased too
    touched = elderly.index(0.3)
    assert set(elderly[reached:touched]) == {1.0}  # held by the score until the performer came
    assert set(elderly[touched:]) == {0.3} and speed[-1] == 1.4  # the performer has the style; speed stays where it was


@pytest.mark.parametrize("table,message", [
    ('[attract]\npresets = ["calm"]\n', "show.toml:4: attract.after: missing"),
    ('[attract]\nafter = 5\npresets = ["nope"]\n', "show.toml:6: attract.presets: no preset 'nope'"),
    ('[attract]\nafter = 5\n', "attract.score: give either score"),
    ('[attract]\nafter = -1\npresets = ["calm"]\n', "show.toml:5: attract.after: expected a number of minutes above 0"),
    ('[attract]\nafter = 1\nscore = "missing.toml"\n', "missing.toml: cannot read"),
])
def test_bad_attract_tables_are_one_line_errors(tmp_path, table, message):
    show = tmp_path / "show.toml"
    show.write_text(f'osc-in = "{free_port()}"\n[presets.calm]\nspeed = 0.8\n' + table)
    result = subprocess.run(RUN + ["--config", str(show), "--seconds", "1", "--no-osc"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_the_watchdog_is_only_for_the_process_systemd_named(tmp_path):
    listener = NotifyListener(tmp_path)
    try:
        for env, interval in [({"WATCHDOG_USEC": "5000000"}, 5.0), ({"WATCHDOG_USEC": "5000000", "WATCHDOG_PID": str(os.getpid())}, 5.0),
                              ({"WATCHDOG_USEC": "5000000", "WATCHDOG_PID": "1"}, None), ({"WATCHDOG_USEC": "soon"}, None),
                              ({}, None)]:
            notifier = SystemdNotifier({"NOTIFY_SOCKET": listener.env, **env})
            assert notifier.interval == interval
            notifier.pet()
            notifier.close()
        marker = SystemdNotifier({"NOTIFY_SOCKET": listener.env})
        marker.send("X-TEST=done")  # arrives after everything sent before it (a unix datagram socket keeps order)
        marker.close()
        assert listener.wait_for("X-TEST=done", timeout=60)
        assert len(listener.times("WATCHDOG=1")) == 2  # only the two that named this process (or no one)
    finally:
        listener.close()
    quiet = SystemdNotifier({})  # outside systemd: nothing to send to, nothing fails
    assert not quiet.active and not quiet.send("READY=1")


def test_the_soak_example_runs(tmp_path):
    """examples/soak.py for 12 simulated minutes (the pad is unplugged at 9.5 and back at 10):
    no crash, every frame made, the real unplug noticed and the pad reopened from its descriptor,
    memory and file handles reported, none left open."""
    figures = tmp_path / "soak.json"
    result = subprocess.run([sys.executable, str(REPO / "examples" / "soak.py"), "--hours", "0.2", "--json", str(figures)],
                            capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr
    soak = json.loads(figures.read_text())
    assert soak["crash"] is None and soak["frames"] == round(0.2 * 3600 * 30)
    assert soak["pad_unplugs"] == 1 and soak["pad_reconnects"] == 1 and soak["pad_reports_read"] > 0
    assert 10 < soak["rss_mb_start"] and 10 < soak["rss_mb_end"]
    assert 0 < soak["open_files_end"] <= soak["open_files_start"]  # everything it opened, it closed
    assert "cannot open" not in result.stdout + result.stderr and "Traceback" not in result.stderr


SYSTEMD_ANALYZE = shutil.which("systemd-analyze")
needs_systemd_analyze = pytest.mark.skipif(SYSTEMD_ANALYZE is None, reason="systemd-analyze is not installed")


def outside_the_venv() -> dict[str, str]:
    """The environment for an interpreter symlinked outside the virtual environment (which then
    finds none of its packages): this checkout and the environment's packages on PYTHONPATH, as
    `service` checks the show with the model and its code."""
    import site

    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), *site.getsitepackages()]))


def write_unit(tmp_path, show, *options):
    unit = tmp_path / f"walk{len(list(tmp_path.glob('*.service')))}.service"
    result = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out", str(unit), *options],
                            capture_output=True, text=True, timeout=120)
    return result, unit


def exposure(unit) -> float:
    """systemd's own rating of the unit's sandbox (0 safe ... 10 unsafe)."""
    result = subprocess.run([SYSTEMD_ANALYZE, "security", "--offline=yes", str(unit)], capture_output=True, text=True, timeout=120)
    found = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", result.stdout)
    assert found, result.stdout + result.stderr
    return float(found.group(1))


@needs_systemd_analyze
@pytest.mark.parametrize("run_as", [None, "walker"])
def test_the_system_unit_runs_unprivileged_in_a_sandbox_systemd_rates_safe(tmp_path, run_as):
    show = tmp_path / "show.toml"
    show.write_text('osc = ["127.0.0.1:9000/flat"]\nbvh = "takes/tonight.bvh"\n')
    (tmp_path / "takes").mkdir()
    result, unit = write_unit(tmp_path, show, *(["--run-as", run_as] if run_as else []))
    assert result.returncode == 0, result.stderr
    lines = unit.read_text().splitlines()
    assert ("DynamicUser=yes" in lines) == (run_as is None) and (f"User={run_as}" in lines) == (run_as is not None)
    assert f'ReadWritePaths="-{tmp_path / "takes"}"' in lines  # where the show records, and nothing else of the disk
    assert exposure(unit) <= 5.0
    verify = subprocess.run([SYSTEMD_ANALYZE, "verify", str(unit)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0 and "Unknown" not in verify.stderr, verify.stderr


@needs_systemd_analyze
def test_paths_with_spaces_percent_dollar_quotes_and_backslashes_reach_systemd_whole(tmp_path):
    """The interpreter itself sits in such a folder: `systemd-analyze verify` checks the command
    systemd reads from the unit names an executable, so a path split or mangled fails here."""
    folder = tmp_path / "My Show 100% $HOME"
    (folder / '"q" \\x').mkdir(parents=True)
    show = folder / '"q" \\x' / "show file.toml"
    show.write_text('osc = ["127.0.0.1:9000/flat"]\n')
    python = folder / "python 3"  # (systemd refuses quotes and backslashes in an executable's path: tested below)
    python.symlink_to(sys.executable)
    result = subprocess.run([str(python), "-m", "instrument", "service", "--config", str(show), "--out", str(tmp_path / "walk.service")],
                            capture_output=True, text=True, timeout=120, env=outside_the_venv())
    assert result.returncode == 0, result.stderr
    verify = subprocess.run([SYSTEMD_ANALYZE, "verify", str(tmp_path / "walk.service")], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0 and verify.stderr == "", verify.stderr


def test_an_interpreter_systemd_cannot_start_is_named_in_one_line(tmp_path):
    folder = tmp_path / 'it\'s "here"'
    folder.mkdir()
    (folder / "python").symlink_to(sys.executable)
    show = tmp_path / "show.toml"
    show.write_text('osc = ["127.0.0.1:9000/flat"]\n')
    result = subprocess.run([str(folder / "python"), "-m", "instrument", "service", "--config", str(show), "--out",
                             str(tmp_path / "walk.service")], capture_output=True, text=True, timeout=120,
                            env=outside_the_venv())
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "systemd refuses an executable" in result.stderr and not (tmp_path / "walk.service").exists()


def test_a_newline_in_a_path_is_refused_not_written_as_a_second_line(tmp_path):
    folder = tmp_path / "show\nExecStartPre=!touch owned"
    folder.mkdir()
    show = folder / "show.toml"
    show.write_text('osc = ["127.0.0.1:9000/flat"]\n')
    result, unit = write_unit(tmp_path, show)
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "control character" in result.stderr and not unit.exists()


# (a show file's text, the line the verdict names, what it says); files the shows name are written
# beside them by `beside_the_show`
BAD_SHOWS = [
    ('fps = 500\n', 1, "fps: expected a number from 24 to 120"),  # out of range
    ('seconds = 1\nfps = "fast"\n', 2, "fps: expected a number from 24 to 120, not 'fast'"),  # wrong type
    ('no-osc = "yes"\n', 1, "no-osc: expected true or false"),
    ('osc = ["127.0.0.1:9000/flat", "nowhere:port"]\n', 1, "osc: "),
    ('colour = "red"\n', 1, "colour: unknown option"),  # unknown key
    ('presets = 3\n', 1, "presets: expected [presets.NAME] tables"),
    ('seconds = -4\n', 1, "seconds: expected a number above 0"),
    ('fps = ', 1, "Invalid value"),  # not TOML
    ('seconds = 1\nconsole-token = "abc"\n', 2, "console-token: --console-token means nothing without --console"),
    ('osc = ["127.0.0.1:9000/flat"]\nno-osc = true\n', 2, "no-osc: --no-osc and --osc contradict each other"),
    ('seconds = 1\nmapping = ["mine.toml", "missing.toml"]\n', 2, "mapping: "),  # a missing mapping
    ('model = "missing.npz"\n', 1, "model: "),  # a missing model
    ('model = "broken.npz"\n', 1, "broken.npz: not a model file"),  # a file that is not a model
    ('mapping = "bad-mapping.toml"\n', 1, "bad-mapping.toml:3: morph"),  # a mapping with a bad value
    ('score = "missing.toml"\n', 1, "score: "),
    ('replay = "missing.jsonl"\n', 1, "replay: "),
    ('[presets.calm]\n"style/elderly" = 50\n', 2, "presets.calm: style/elderly: 50 is out of range"),  # a preset out of range
    ('characters = 2\nbvh-character = 5\n', 2, "bvh-character: expected a character of the crowd, 0 to 1, not 5"),
    ('humanoid = "bad-bones.toml"\n', 1, "bad-bones.toml:1: Hips: unknown key (expected one of bones)"),  # its line too
    ('vmc-root = "knees"\n', 1, "vmc-root: expected one of hips, path, not 'knees'"),
    ('hid = "sony"\n', 1, "hid: 'sony': expected VVVV:PPPP"),  # the row's reader (control/options.py)
    ('midi-virtual = ["x"]\nmidi-api = "oss"\n', 2, "midi-api: expected one of alsa, jack, not 'oss'"),  # was a traceback
    ('seconds = 1\nsync = "beat"\n', 2, "sync: expected one of midi, link, not 'beat'"),  # was ignored
    ('check = true\n', 1, "check: unknown option"),  # the command line's only
    ('sync = "midi"\n', 1, "sync: --sync midi follows the clock of a MIDI input"),
    ('bvh = "no folder/take.bvh"\n', 1, "bvh: "),  # its folder does not exist
    ('bvh = "taken.bvh"\nkeep-recordings = true\nforce = true\n', 3, "force: --force replaces recordings and "
     "--keep-recordings (which a service runs a show with) keeps each under a new name: give one"),  # (a take alone:
    # `run` refuses it, a service records beside it: test_a_restarted_service_records_beside_the_take_before_the_crash)
    ('osc-in = 9000\n[attract]\nafter = -1\n', 3, "attract.after: expected a number of minutes above 0"),
    ('seconds = 1\n[presets.calm]\nspeed = 0.8\n[attract]\nafter = 5\npresets = ["calm"]\n', 4,
     "attract: needs a controller"),
    ('osc-in = 9000\n[attract]\nafter = 5\nscore = "empty.toml"\n', 2, "attract: "),  # its score is no score
]


def test_the_show_file_and_the_command_line_are_read_from_one_table():
    """Each row of control/options.py RUN is an option of `run --help` and, unless it is for the
    command line only, a key a show file takes, read as its kind says; the choices are what the
    code behind them implements."""
    import argparse

    from instrument.cli.run_cmd import add_parser
    from instrument.cli.showplan import file_value
    from instrument.control.options import RUN, RUN_BY_KEY
    from instrument.output.vmc import ROOT_CONVENTIONS

    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers())
    run = parser._subparsers._group_actions[0].choices["run"]
    flags = {flag for action in run._actions for flag in action.option_strings} - {"-h", "--help"}
    assert flags == {option.flag for option in RUN}
    assert RUN_BY_KEY["vmc-root"].choices == ROOT_CONVENTIONS
    samples = {"text": "x", "path": "x", "flag": True, "list": ["x"], "paths": ["x"]}
    for option in RUN:
        action = next(a for a in run._actions if option.flag in a.option_strings)
        assert action.help == option.help or option.flag == "--osc", option.flag
        assert (action.choices or ()) == option.choices and action.dest == option.dest
        assert (action.nargs == 0) == (option.kind == "flag") and (type(action).__name__ == "_AppendAction") == (
            option.kind in ("list", "paths"))
        value = option.choices[0] if option.choices else str(option.accepts.high) if option.accepts else samples[option.kind]
        if option.in_file:
            assert file_value(option, value, "show.toml:1") in (value, str(value)), option.flag


def beside_the_show(folder) -> None:
    """The files the bad shows name: a mapping that is fine, one that is not, a model that is not a model, a take."""
    (folder / "mine.toml").write_text('name = "mine"\n[device]\nmidi = "."\n')
    (folder / "bad-mapping.toml").write_text('name = "bad"\n\nmorph = -3\n[device]\nmidi = "."\n')
    (folder / "broken.npz").write_bytes(b"not a zip archive")
    (folder / "taken.bvh").write_text("HIERARCHY\n")
    (folder / "empty.toml").write_text("")
    (folder / "bad-bones.toml").write_text("Hips = 3\n")


def one_verdict(command: list[str], show) -> subprocess.CompletedProcess:
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, (command, result.stderr)
    return result


@pytest.mark.parametrize("show_text,line,says", BAD_SHOWS)
def test_a_show_run_refuses_gets_no_unit_and_the_same_one_line_error(tmp_path, show_text, line, says):
    """`run --check`, a start of `run` and `service` give the one verdict of cli/showplan.py,
    naming the show file's line, and no unit is written."""
    beside_the_show(tmp_path)
    show = tmp_path / "show.toml"
    show.write_text(show_text)
    checked = one_verdict(RUN + ["--config", str(show), "--check"], show)
    assert checked.stderr.startswith(f"instrument run: error: {show}:{line}: ") and says in checked.stderr, checked.stderr
    started = one_verdict(RUN + ["--config", str(show)], show)
    assert started.stderr == checked.stderr
    result, unit = write_unit(tmp_path, show)
    assert result.returncode == 1 and not unit.exists(), result.stderr
    assert result.stderr.removeprefix("instrument service: ") == checked.stderr.removeprefix("instrument run: ")


def test_a_show_whose_take_exists_is_refused_by_run_without_keep_recordings(tmp_path):
    """Without --keep-recordings (a show run by hand), a take that exists is refused at the show's
    line, by the check and by a start alike (the service runs it with --keep-recordings instead:
    test_a_restarted_service_records_beside_the_take_before_the_crash)."""
    beside_the_show(tmp_path)
    show = tmp_path / "show.toml"
    show.write_text('bvh = "taken.bvh"\n')
    checked = one_verdict(RUN + ["--config", str(show), "--check"], show)
    assert checked.stderr.startswith(f"instrument run: error: {show}:1: ") and "taken.bvh: already exists" in checked.stderr
    assert one_verdict(RUN + ["--config", str(show)], show).stderr == checked.stderr


def test_keep_recordings_numbers_past_every_take_and_what_a_killed_one_left(tmp_path):
    """A recording killed before its first frame leaves NAME.part, which a recorder will not open
    again: the number it holds is taken (counted free, a restarted service failed on every try
    until systemd gave up). Numbers go one past the highest held, so they keep the starts' order."""
    night = tmp_path / "night.bvh"
    (tmp_path / "night.bvh.part").write_text("HIERARCHY\n")
    started = subprocess.run(RUN + ["--no-osc", "--quiet", "--fast", "--seconds", "1", "--bvh", str(night),
                                    "--keep-recordings"], capture_output=True, text=True, timeout=300)
    assert started.returncode == 0, started.stderr
    assert read_bvh(tmp_path / "night-2.bvh").frames == 30 and not night.exists()
    (tmp_path / "night-2.bvh").rename(tmp_path / "night-5.bvh")  # a gap below the highest is not filled
    assert kept_names(str(night), None) == [str(tmp_path / "night-6.bvh"), None]


def test_keep_recordings_names_both_numbered_recordings_as_it_starts(tmp_path):
    """A start beside an earlier take records NAME-2 for the BVH and the controller log alike, and
    its start-up line names both (it named the BVH only: where the take's controls went was left to
    guess, and the log is what replays to the BVH)."""
    night, log = tmp_path / "night.bvh", tmp_path / "night.jsonl"
    command = RUN + ["--no-osc", "--fast", "--seconds", "1", "--bvh", str(night), "--record", str(log), "--keep-recordings"]
    first = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0 and night.exists() and log.exists(), first.stderr
    second = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert second.returncode == 0, second.stderr
    started = [line for line in second.stderr.splitlines() if line.startswith("model ")]
    numbered_bvh, numbered_log = tmp_path / "night-2.bvh", tmp_path / "night-2.jsonl"
    assert len(started) == 1 and f"recording {numbered_bvh}" in started[0] and str(numbered_log) in started[0], second.stderr
    assert read_bvh(numbered_bvh).frames == 30 and json.loads(numbered_log.read_text().splitlines()[0])


@pytest.mark.parametrize("console", [[], ["--console", "0"]])
def test_the_show_file_given_as_its_own_presets_is_refused_by_a_check(tmp_path, console):
    """--presets naming the show itself (a save would replace the show with its presets): one line at
    the check, before anything opens (with the console: before its server starts)."""
    show = tmp_path / "show.toml"
    show.write_text('seconds = 1\n\n[presets.calm]\nspeed = 0.8\n')
    checked = one_verdict(RUN + ["--config", str(show), "--presets", str(show), "--check", *console], show)
    assert f"{show}:1: seconds: unknown key" in checked.stderr  # a presets file holds [presets] only


def test_a_good_show_is_checked_without_opening_anything_and_gets_a_unit(tmp_path):
    beside_the_show(tmp_path)
    (tmp_path / "takes").mkdir()
    show = tmp_path / "show.toml"
    show.write_text('seconds = 60\nosc = ["127.0.0.1:9000/flat"]\nmapping = "mine.toml"\nmidi = ["nanoKONTROL"]\n'
                    'bvh = "takes/tonight.bvh"\nrecord = "takes/tonight.jsonl"\n\n[presets.calm]\nspeed = 0.8\n')
    checked = subprocess.run(RUN + ["--config", str(show), "--check"], capture_output=True, text=True, timeout=300)
    assert checked.returncode == 0 and "the show is fine" in checked.stdout, checked.stderr
    assert not list((tmp_path / "takes").iterdir())  # nothing recorded, nothing left behind
    result, unit = write_unit(tmp_path, show)
    assert result.returncode == 0 and unit.exists(), result.stderr
    assert f'ReadWritePaths="-{(tmp_path / "takes").resolve()}"' in unit.read_text()
