"""Private JACK servers for the tests that stop and start one mid-show (the shared server is never
killed): start one, free the registry slots dead servers left behind, list a client's port.

JACK (jack2) keeps the names of running servers in a registry of 8 slots in shared memory
(/dev/shm/jack-shm-registry). A server that is killed rather than stopped keeps its slot after
death, and once all 8 are taken no server starts ("Too many servers already active"), on this
machine and every later run on it. jackd itself frees a dead server's slot when a server of the
same name starts; so the tests use fixed names, and before starting one they free every dead slot
by starting and cleanly stopping a server of its name.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

REGISTRY = Path("/dev/shm/jack-shm-registry")
# a slot: the server's pid (a native int) just before its "jack-<uid>:<name>:" prefix
SLOT = re.compile(rb"jack-\d+:([^:\x00]+):\x00")


def registered_servers() -> dict[str, int]:
    """The registry's server names and the pid each was registered by ({} without a registry)."""
    try:
        header = REGISTRY.read_bytes()[:8192]  # the server slots are in the header, before the segments
    except OSError:
        return {}
    servers = {}
    for slot in SLOT.finditer(header):
        if slot.start() >= 4:
            pid = int.from_bytes(header[slot.start() - 4:slot.start()], sys.byteorder, signed=True)
            servers[slot.group(1).decode(errors="replace")] = pid
    return servers


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return pid > 0


def free_dead_slots(log: Path) -> list[str]:
    """Free the registry slot of every dead server (see the module's text); the names freed."""
    freed = []
    for name, pid in registered_servers().items():
        if alive(pid):
            continue
        with log.open("a") as sink:
            server = subprocess.Popen(["jackd", "--no-realtime", "-n", name, "-d", "dummy", "-r", "48000", "-p", "1024"],
                                      stdout=sink, stderr=subprocess.STDOUT)
        until = time.monotonic() + 30
        while server.poll() is None and time.monotonic() < until and registered_servers().get(name) != server.pid:
            time.sleep(0.1)
        server.terminate()  # a clean stop gives the slot back
        try:
            server.wait(30)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait(30)
        if name not in registered_servers():
            freed.append(name)
    return freed


def start_private_jack(rtmidi, name: str, log: Path) -> subprocess.Popen:
    """A running private JACK server NAME; a start that fails (a stale socket from the one just
    killed can refuse it on a busy machine) is tried again: the server's restart is not under test."""
    free_dead_slots(log)
    until = time.monotonic() + 90
    while True:
        with log.open("a") as sink:
            # a long period and client timeout: on a loaded machine a short one makes the server
            # drop notifications and time clients out, which is the machine's failure, not the show's
            server = subprocess.Popen(["jackd", "--no-realtime", "-n", name, "-t", "5000", "-d", "dummy",
                                       "-r", "48000", "-p", "1024"], stdout=sink, stderr=subprocess.STDOUT)
        while server.poll() is None and time.monotonic() < until:
            if server_up(rtmidi):
                return server
            time.sleep(0.1)
        server.kill()
        server.wait(30)
        assert time.monotonic() < until, (f"the private JACK server never started (servers registered: "
                                          f"{registered_servers()}): {log.read_text()[-2000:]}")
        time.sleep(0.2)  # a short back-off before the next start (the loop's deadline bounds the whole wait)


def stop_private_jack(server: subprocess.Popen) -> None:
    """Stop a private server cleanly, so its registry slot is given back; killed only if it hangs
    (waiting on a client the test killed), and then its slot is freed at the next start."""
    server.terminate()
    try:
        server.wait(30)
    except subprocess.TimeoutExpired:
        server.kill()
        server.wait(30)


def server_up(rtmidi) -> bool:
    """Whether the server JACK_DEFAULT_SERVER names takes a client."""
    try:
        probe = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name="fault-probe")
    except Exception:
        return False
    probe.delete()
    return True


def jack_port_listed(rtmidi, part: str, readable: bool = False) -> str | None:
    """The JACK MIDI port whose name holds `part`, or None: one a MIDI output can send to, or with
    `readable` one a MIDI input can read from."""
    try:
        probe = (rtmidi.MidiIn if readable else rtmidi.MidiOut)(rtmidi.API_UNIX_JACK, name="fault-probe")
    except Exception:
        return None
    try:
        return next((n for n in probe.get_ports() if part in n), None)
    finally:
        probe.delete()
