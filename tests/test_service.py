"""Unattended operation: systemd's notify protocol with the test as the listener (READY=1, the
frame loop petting the watchdog, a frozen loop caught and restarted), the health line and the
status endpoint over real UDP, the generated unit, and attract mode with pick-up."""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from conftest import REPO
from instrument.control.attract import Attract, AttractSettings
from instrument.control.events import ControlEvent
from instrument.control.hub import ControlHub
from instrument.control.mapping import load_mapping
from instrument.control.score import preset_tour
from instrument.control.state import ControlState
from instrument.runtime.console import Console
from instrument.runtime.health import Health
from instrument.runtime.notify import SystemdNotifier
from instrument.runtime.performance import perform
from oscrecv import Receiver, free_port

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
        self.frames = 0

    def prepare(self, pose, echo):
        return pose.index

    def send(self, index):
        self.frames += 1
        self.go.wait()

    def close(self):
        pass


def test_the_frame_loop_pets_the_watchdog_and_a_frozen_loop_stops(model, tmp_path):
    listener = NotifyListener(tmp_path)
    notifier = SystemdNotifier({"NOTIFY_SOCKET": listener.env, "WATCHDOG_USEC": "300000"})  # WatchdogSec=0.3
    freezer = Freezer()
    health = Health(Console(quiet=True), [freezer], [], notifier, every=0)
    seen = {}

    def systemd_side():  # the loop runs on the main thread (it owns the signals); this watches it
        try:
            seen["ready"] = listener.wait_for("READY=1")
            seen["petted"] = listener.wait_for("WATCHDOG=1", count=5)
            pets = listener.times("WATCHDOG=1")
            seen["widest gap"] = max(b - a for a, b in zip(pets, pets[1:]))
            freezer.go.clear()  # the loop hangs in its output
            deadline = time.monotonic() + 30
            while listener.times("WATCHDOG=1")[-1] > time.monotonic() - 1.0 and time.monotonic() < deadline:
                time.sleep(0.05)
            stopped = listener.times("WATCHDOG=1")[-1]
            time.sleep(0.6)  # two more watchdog intervals
            seen["silent while frozen"] = listener.times("WATCHDOG=1")[-1] == stopped and time.monotonic() < deadline
            freezer.go.set()  # the loop comes back: petting resumes
            seen["petted again"] = listener.wait_for("WATCHDOG=1", after=time.monotonic())
        finally:
            freezer.go.set()
            os.kill(os.getpid(), signal.SIGTERM)  # ends the performance as systemd's stop does

    watcher = threading.Thread(target=systemd_side, daemon=True)
    watcher.start()
    try:
        perform(model, [freezer], Console(quiet=True), fps=30, seconds=120.0, on_frame=health.frame)
    finally:
        watcher.join(30)
        listener.close()
    assert seen == {"ready": True, "petted": True, "widest gap": seen["widest gap"], "silent while frozen": True,
                    "petted again": True}
    assert seen["widest gap"] < 0.3  # well inside WatchdogSec
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


def test_health_line_and_status_endpoint_over_udp(tmp_path):
    receiver, status_port, dead = Receiver(), free_port(), free_port()
    process = subprocess.Popen(RUN + ["--osc", f"127.0.0.1:{receiver.port}/flat", "--osc", f"127.0.0.1:{dead}/flat",
                                      "--status-port", str(status_port), "--health-every", "1", "--seconds", "60", "--quiet"],
                               stderr=subprocess.PIPE, text=True)
    asker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    asker.settimeout(0.2)
    replies = {}
    try:
        from pythonosc.osc_message import OscMessage

        def running_for(seconds: float) -> bool:  # the run's own uptime, so a health line is due
            return b"s" in replies and json.loads(replies[b"s"])["uptime"] >= seconds

        deadline = time.monotonic() + 120
        while not (b"/" in replies and running_for(2.5)) and time.monotonic() < deadline:
            for request in (b"/walk/status\0\0\0\0,\0\0\0", b"status"):  # an OSC message without arguments, then plain text
                asker.sendto(request, ("127.0.0.1", status_port))
                try:
                    reply = asker.recv(65536)
                except (socket.timeout, ConnectionRefusedError):
                    continue
                replies[b"/" if reply.startswith(b"/") else b"s"] = reply  # by what came back: a late reply may cross a request
            time.sleep(0.2)
    finally:
        process.terminate()
        stderr = process.communicate(timeout=60)[1]
        receiver.close()
        asker.close()
    assert process.returncode == 0, stderr
    osc = OscMessage(replies[b"/"])
    frames, late, dropped, uptime, rss, files, outputs, devices = osc.params
    assert osc.address == "/walk/status" and frames > 0 and uptime > 0 and rss > 10 and files > 2
    assert f"osc 127.0.0.1:{receiver.port}/flat up" in outputs and f"osc 127.0.0.1:{dead}/flat down" in outputs
    report = json.loads(replies[b"s"])
    assert report["frames"] > 0 and report["outputs"][f"osc 127.0.0.1:{dead}/flat"] == "down"
    lines = [line for line in stderr.splitlines() if line.startswith("health: ")]
    assert lines and "frames" in lines[-1] and "late" in lines[-1] and f"{dead}/flat down" in lines[-1]


def test_the_generated_unit_restarts_on_failure_with_a_watchdog(tmp_path):
    show = tmp_path / "show.toml"
    show.write_text('osc = ["127.0.0.1:9000/flat"]\n')
    unit = tmp_path / "walk.service"
    result = subprocess.run([sys.executable, "-m", "instrument", "service", "--config", str(show), "--out", str(unit),
                             "--watchdog", "5"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    text = unit.read_text()
    for line in ("Type=notify", "Restart=on-failure", "WatchdogSec=5", "LimitRTPRIO=5", "WantedBy=multi-user.target",
                 f"ExecStart={sys.executable} -m instrument run --config {show.resolve()} --quiet"):
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

        def prepare(self, pose, echo):
            return echo["style/elderly"], attract.active

        def send(self, values):
            seen.append(values)

        def close(self):
            pass

    perform(model, [Watch()], console, fps=30, seconds=8.0, live_sources=[attract.poll], apply=hub.apply, state=state, fast=True)
    assert not any(active for _, active in seen[:45])  # the fader was touched at frame 15: idle from then on
    assert seen[50][1] and 0.0 < seen[60][0] < 1.0 and seen[100][0] == 1.0  # the tour eased into "old"
    assert seen[149] == (1.0, True)
    assert seen[150] == (1.0, False)  # the fader's move ends the tour; pick-up: nothing jumps
    assert [seen[k][0] for k in (160, 170, 180, 190)] == [1.0] * 4  # below the parameter: not picked up
    assert seen[200][0] == pytest.approx(1.2, abs=0.03)  # crossed it: the fader has the style
    assert not any(active for _, active in seen[150:225]) and seen[235][1]  # idle again a second after the last move


def test_a_show_file_attract_mode_over_osc(tmp_path):
    """The whole path: a show file's [attract] table, an OSC surface on real UDP, the flat echo."""
    from pythonosc.udp_client import SimpleUDPClient

    control_port, receiver = free_port(), Receiver()
    show = tmp_path / "show.toml"
    show.write_text(f'osc-in = "{control_port}"\nosc = ["127.0.0.1:{receiver.port}/flat"]\nseconds = 120\n'
                    '[presets.old]\n"style/elderly" = 1.0\n[presets.young]\n"style/youthful" = 1.0\n'
                    '[attract]\nafter = 0.02\npresets = ["old", "young"]\nmorph = 0.5\nhold = 600\n')
    process = subprocess.Popen(RUN + ["--config", str(show)], stderr=subprocess.PIPE, text=True)
    surface = SimpleUDPClient("127.0.0.1", control_port)

    def echoed(address: str) -> list[float]:
        return [p[0] for a, p in receiver.messages() if a == address]

    try:
        deadline = time.monotonic() + 90
        while 1.0 not in echoed("/walk/style/elderly") and time.monotonic() < deadline:  # idle 1.2 s: the tour begins
            time.sleep(0.05)
        surface.send_message("/walk/speed", 1.3)  # a performer
        while 1.3 not in [round(v, 3) for v in echoed("/walk/speed")] and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
        after_touch = len(echoed("/walk/style/elderly"))
        time.sleep(0.6)  # less than the idle time: the tour stays off
    finally:
        process.terminate()
        stderr = process.communicate(timeout=60)[1]
        receiver.close()
    assert process.returncode == 0, stderr
    assert "attract mode on" in stderr and "attract mode off" in stderr
    elderly = echoed("/walk/style/elderly")
    assert len(set(elderly)) > 5 and max(elderly) == 1.0  # eased in, not jumped
    assert set(elderly[after_touch:]) == {1.0} and set(echoed("/walk/style/youthful")) == {0.0}


@pytest.mark.parametrize("table,message", [
    ('[attract]\npresets = ["calm"]\n', "show.toml:4: attract.after: missing"),
    ('[attract]\nafter = 5\npresets = ["nope"]\n', "show.toml:6: attract.presets: no preset 'nope'"),
    ('[attract]\nafter = 5\n', "attract.score: give either score"),
    ('[attract]\nafter = -1\npresets = ["calm"]\n', "show.toml:5: attract.after: expected a positive number of minutes"),
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
        assert listener.wait_for("WATCHDOG=1", count=2, timeout=10)
        time.sleep(0.3)
        assert len(listener.times("WATCHDOG=1")) == 2  # only the two that named this process (or no one)
    finally:
        listener.close()
    quiet = SystemdNotifier({})  # outside systemd: nothing to send to, nothing fails
    assert not quiet.active and not quiet.send("READY=1")
