"""The browser console end to end: the page in Debian's headless chromium (Selenium with the
system chromedriver), the instrument as a real process, the flat OSC stream over real UDP,
MIDI through JACK, and page messages over a real WebSocket."""

from __future__ import annotations

import asyncio
import filecmp
import io
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time

import mido
import numpy as np
import pytest

from conftest import REPO
from instrument.motion.bvh import read_bvh
from oscrecv import Receiver
from waiting import wait_until

RUN = [sys.executable, "-m", "instrument", "run"]
NANO = str(REPO / "mappings" / "korg-nanokontrol2.toml")
CHROMIUM, CHROMEDRIVER = shutil.which("chromium") or "/usr/bin/chromium", shutil.which("chromedriver") or "/usr/bin/chromedriver"
needs_browser = pytest.mark.skipif(not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)),
                                   reason="chromium and chromium-driver are not installed (apt-get install chromium "
                                          "chromium-driver)")


class Instrument:
    """`instrument run --console ...` as a process; its stderr is read as it comes."""

    def __init__(self, *args: str):
        self.process = subprocess.Popen(RUN + list(args), stderr=subprocess.PIPE, text=True)
        self.lines: list[str] = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        self.url = self.wait_for(r"console: (http://\S+)").group(1)

    def _read(self) -> None:
        for line in self.process.stderr:
            self.lines.append(line)

    def wait_for(self, pattern: str, timeout: float = 60.0) -> re.Match:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if found := re.search(pattern, line):
                    return found
            if self.process.poll() is not None and not self.reader.is_alive():
                break
            time.sleep(0.05)
        raise AssertionError(f"never said {pattern!r}:\n{''.join(self.lines)}")

    def stop(self) -> str:
        if self.process.poll() is None:
            self.process.terminate()  # a clean stop, like Ctrl-C
        self.process.wait(60)
        self.reader.join(10)
        return "".join(self.lines)


def echoed(receiver: Receiver, address: str) -> list[float]:
    return [params[0] for a, params in receiver.messages() if a == address]


@pytest.fixture(scope="module")
def chromium(tmp_path_factory):
    """One headless chromium for the whole module (each start costs seconds); tests share it
    through `browser`, which leaves it as it found it."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--window-size=1400,900",
                 f"--user-data-dir={tmp_path_factory.mktemp('chromium')}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()


@pytest.fixture
def browser(chromium):
    """The shared chromium; afterwards one window again, on a blank page, without touch emulation."""
    yield chromium
    for handle in chromium.window_handles[1:]:
        chromium.switch_to.window(handle)
        chromium.close()
    chromium.switch_to.window(chromium.window_handles[0])
    chromium.execute_cdp_cmd("Emulation.setTouchEmulationEnabled", {"enabled": False})
    chromium.get("about:blank")


def open_page(driver, url: str) -> None:
    driver.get(url)
    wait_until(lambda: frame_number(driver) > 5, "frames on the page", timeout=60)


def frame_number(driver) -> int:
    text = driver.find_element("id", "frame").text
    return int(text.split()[-1]) if text.split()[-1].isdigit() else -1


def slider_value(driver, target: str) -> float:
    return float(driver.execute_script(f"return document.querySelector('[data-target=\"{target}\"] input[type=range]').value"))


def press(driver, key: str) -> None:
    """A key pressed on the page itself (not into a field)."""
    from selenium.webdriver.common.action_chains import ActionChains

    driver.execute_script("document.activeElement && document.activeElement.blur()")
    ActionChains(driver).send_keys(key).perform()


def slider(driver, target: str):
    return driver.find_element("css selector", f'[data-target="{target}"] input[type=range]')


@needs_browser
def test_a_slider_and_the_keys_move_the_walk_in_the_osc_stream_and_replay_exactly(browser, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    receiver = Receiver()
    log, live_bvh, replay_bvh = tmp_path / "take.jsonl", tmp_path / "live.bvh", tmp_path / "replay.bvh"
    show = Instrument("--console", "0", "--osc", f"127.0.0.1:{receiver.port}/flat", "--quiet", "--record", str(log),
                      "--bvh", str(live_bvh))
    try:
        open_page(browser, show.url)
        elderly = slider(browser, "style/elderly")
        # a real pointer press at 80 % of the slider's width (the travel is -2 .. 4)
        ActionChains(browser).move_to_element_with_offset(elderly, int(elderly.size["width"] * 0.3), 0).click().perform()
        wanted = slider_value(browser, "style/elderly")
        assert wanted > 1.5  # the click landed in the exaggerated part of the slider
        wait_until(lambda: echoed(receiver, "/walk/style/elderly")[-1:] == [pytest.approx(wanted, abs=1e-6)],
                   what="the weight in OSC")
        press(browser, Keys.ARROW_UP)  # a step faster
        wait_until(lambda: echoed(receiver, "/walk/speed")[-1:] == [pytest.approx(1.1)], what="the speed in OSC")
    finally:
        stderr = show.stop()
        receiver.close()
    assert show.process.returncode == 0, stderr
    header, *recorded, end = [json.loads(line) for line in log.read_text().splitlines()]
    assert "instrument_log" in header  # what a replay needs comes first (control.loghead)
    assert list(end) == ["end"]  # and where the run stopped, last
    assert {e["source"] for e in recorded} == {"console"}
    assert {"style/elderly", "speed"} <= {e["control"] for e in recorded}
    # the page's events, recorded like any controller's, replay to the same frames byte for byte
    frames = read_bvh(live_bvh).frames
    result = subprocess.run(RUN + ["--replay", str(log), "--no-osc", "--fast", "--seconds", repr(frames / 30), "--quiet",
                                   "--bvh", str(replay_bvh)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert filecmp.cmp(live_bvh, replay_bvh, shallow=False)


@needs_browser
def test_a_midi_fader_moves_the_slider_on_every_page_and_pages_stay_in_sync(jack, browser):
    show = Instrument("--console", "0", "--midi-virtual", "instr-console", "--midi-api", "jack", "--mapping", NANO, "--no-osc",
                      "--quiet", "--no-feedback")
    try:
        names = wait_until(lambda: [n for n in jack.get_output_names() if "instr-console" in n], "the virtual MIDI port",
                           timeout=30)
        fader = jack.open_output(names[0])
        open_page(browser, show.url)
        first = browser.current_window_handle
        browser.switch_to.new_window("window")
        open_page(browser, show.url)
        second = browser.current_window_handle

        def cc(value):
            fader.send(mido.Message("control_change", channel=0, control=1, value=value))  # the elderly fader

        expected = 100 / 127 * 3 - 1  # the mapping's range -1 .. 2

        def followed() -> bool:
            return abs(slider_value(browser, "style/elderly") - expected) < 0.006

        for attempt in range(3):  # a connection made while the JACK dummy server stalls can come to nothing: again
            browser.switch_to.window(first)
            start = round((slider_value(browser, "style/elderly") + 1) / 3 * 127)  # where the fader picks the parameter up
            for value in range(start, 101, 4 if start < 100 else 1):
                cc(value)
                time.sleep(0.01)
            cc(100)
            try:
                wait_until(followed, "the slider to follow the fader", timeout=10)
                break
            except AssertionError:
                fader.close()
                fader = jack.open_output(names[0])
        for window in (first, second):
            browser.switch_to.window(window)
            wait_until(followed, what="the slider to follow the fader on every page")
        # one page's move shows on the other
        browser.switch_to.window(first)
        browser.execute_script("const box = document.querySelector('[data-target=\"turn\"] input[type=number]');"
                               "box.value = '-0.75'; box.dispatchEvent(new Event('change'));")
        browser.switch_to.window(second)
        wait_until(lambda: slider_value(browser, "turn") == -0.75, what="the other page to follow")
        fader.close()
    finally:
        stderr = show.stop()
    assert show.process.returncode == 0, stderr
    assert stderr.count("a page connected") == 2


@needs_browser
def test_store_recall_and_save_presets_that_the_cli_reads(browser, tmp_path):
    from selenium.webdriver.common.keys import Keys

    receiver = Receiver()
    saved = tmp_path / "saved.toml"  # does not exist yet: the console's Save writes it
    show = Instrument("--console", "0", "--osc", f"127.0.0.1:{receiver.port}/flat", "--quiet", "--presets", str(saved))
    try:
        open_page(browser, show.url)
        box = browser.find_element("css selector", '[data-target="style/feminine"] input[type=number]')
        box.click()
        box.send_keys(Keys.CONTROL, "a")
        box.send_keys("1.25", Keys.ENTER)  # typed over the whole value
        wait_until(lambda: echoed(receiver, "/walk/style/feminine")[-1:] == [pytest.approx(1.25)], what="the typed weight")
        browser.find_element("id", "store-name").send_keys("graceful", Keys.ENTER)
        button = wait_until(lambda: browser.find_elements("css selector", '[data-preset="graceful"]'),
                            what="the stored preset's button")[0]
        browser.find_element("id", "reset").click()
        wait_until(lambda: echoed(receiver, "/walk/style/feminine")[-1:] == [0.0], what="the reset")
        button.click()
        wait_until(lambda: echoed(receiver, "/walk/style/feminine")[-1:] == [pytest.approx(1.25)], what="the recalled preset")
        browser.find_element("id", "reset").click()
        wait_until(lambda: echoed(receiver, "/walk/style/feminine")[-1:] == [0.0], what="the second reset")
        press(browser, "1")  # number keys recall presets
        wait_until(lambda: echoed(receiver, "/walk/style/feminine")[-1:] == [pytest.approx(1.25)], what="the preset by key")
        browser.find_element("id", "save").click()
        wait_until(lambda: "saved 1 presets" in browser.find_element("id", "saved").text, what="the save")
    finally:
        stderr = show.stop()
        receiver.close()
    assert show.process.returncode == 0, stderr
    # the saved file is a preset file the CLI reads: a cue recalls the preset in a new run
    cue = tmp_path / "cue.jsonl"
    cue.write_text('{"t": 0.2, "source": "cue", "control": "preset/graceful", "value": 1}\n')
    again = Receiver()
    result = subprocess.run(RUN + ["--presets", str(saved), "--replay", str(cue), "--seconds", "1", "--fast", "--quiet",
                                   "--osc", f"127.0.0.1:{again.port}/flat"], capture_output=True, text=True, timeout=60)
    wait_until(lambda: len(echoed(again, "/walk/style/feminine")) == 30, what="the second run's frames")
    again.close()
    assert result.returncode == 0, result.stderr
    assert echoed(again, "/walk/style/feminine")[-1] == pytest.approx(1.25)


@needs_browser
def test_the_xy_pad_blends_the_chosen_styles(browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.support.ui import Select

    receiver = Receiver()
    show = Instrument("--console", "0", "--osc", f"127.0.0.1:{receiver.port}/flat", "--quiet")
    try:
        open_page(browser, show.url)
        first, second, third = (Select(e) for e in browser.find_elements("css selector", "#pad-styles select"))
        first.select_by_value("normal")
        second.select_by_value("youthful")
        third.select_by_value("")  # two styles: across blends, up is the amount
        pad = browser.find_element("id", "pad")
        # the right edge, half way up: all the second style, at its own weight
        ActionChains(browser).move_to_element_with_offset(pad, pad.size["width"] // 2 - 2, 0).click().perform()
        wait_until(lambda: echoed(receiver, "/walk/style/youthful")[-1:] == [pytest.approx(1.0, abs=0.02)]
                   and echoed(receiver, "/walk/style/normal")[-1:] == [pytest.approx(0.0, abs=0.02)], what="the pad's blend")
        third.select_by_value("elderly")  # three styles: a triangle, the first at the top, the third bottom right
        ActionChains(browser).move_to_element_with_offset(pad, 0, -pad.size["height"] // 2 + 3).click().perform()
        wait_until(lambda: echoed(receiver, "/walk/style/normal")[-1:] == [pytest.approx(1.0, abs=0.02)]
                   and echoed(receiver, "/walk/style/elderly")[-1:] == [pytest.approx(0.0, abs=0.02)], what="the triangle's top")
        corner = (pad.size["width"] // 2 - 2, pad.size["height"] // 2 - 2)
        ActionChains(browser).move_to_element_with_offset(pad, *corner).click().perform()
        wait_until(lambda: echoed(receiver, "/walk/style/elderly")[-1:] == [pytest.approx(1.0, abs=0.02)]
                   and echoed(receiver, "/walk/style/normal")[-1:] == [pytest.approx(0.0, abs=0.02)],
                   what="the bottom right corner")
    finally:
        stderr = show.stop()
        receiver.close()
    assert show.process.returncode == 0, stderr


def screenshot(element) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(element.screenshot_as_png)).convert("RGB")).astype(float)


@needs_browser
def test_the_view_draws_the_walking_figure(browser):
    show = Instrument("--console", "0", "--no-osc", "--quiet")
    try:
        open_page(browser, show.url)
        view = browser.find_element("id", "view")
        first = screenshot(view)
        start = frame_number(browser)
        wait_until(lambda: frame_number(browser) > start + 15, what="half a second of frames")
        second = screenshot(view)
        if os.environ.get("INSTRUMENT_DOCS_SCREENSHOT"):  # the docs' picture: INSTRUMENT_DOCS_SCREENSHOT=1 pytest ...
            browser.save_screenshot(str(REPO / "docs" / "console.png"))
    finally:
        stderr = show.stop()
    assert show.process.returncode == 0, stderr
    assert first.shape[0] > 200 and first.shape[1] > 200
    # not blank: the sky is a smooth gradient; the figure and the grid add many distinct colours
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 500
    # a lit figure is drawn: bright pixels (the head, lit limbs) far above the dark background
    assert (first.max(axis=2) > 180).sum() > 100
    # the figure moves: many pixels differ between two screenshots half a second apart
    assert (np.abs(first - second).max(axis=2) > 40).sum() > 200


@needs_browser
def test_the_view_draws_a_crowd_and_follows_its_first_character(browser):
    show = Instrument("--console", "0", "--no-osc", "--quiet", "--characters", "3", "--spacing", "1.5")
    try:
        open_page(browser, show.url)
        start = frame_number(browser)
        wait_until(lambda: browser.execute_script("return figure.others.length") == 2, what="the crowd on the page")

        def roots():
            return np.array(browser.execute_script(
                "const r = Math.max(figure.first, 0); return [figure.positions[r], ...figure.others.map((p) => p[r])]"))

        before = roots()
        wait_until(lambda: frame_number(browser) > start + 30, what="a second of frames")
        after = roots()
        followed = browser.execute_script("return figure.camera.follow")
    finally:
        stderr = show.stop()
    assert show.process.returncode == 0, stderr
    assert before.shape == (3, 3)
    apart = [np.hypot(*(before[a] - before[b])[[0, 2]]) for a, b in ((0, 1), (1, 2), (0, 2))]
    assert min(apart) > 100  # three walkers, spaced on the floor (1.5 m; the shipped model is in cm)
    assert np.all(np.hypot(*(after - before)[:, [0, 2]].T) > 30)  # and every one of them walks
    assert followed


# ---- the other controls of the page, on one show shared by these tests ------------------------

class FlatFrames:
    """The flat OSC stream as whole frames (address -> arguments), parsed as they come in (not
    all over again at each look: a shared show sends thousands of frames)."""

    def __init__(self, receiver: Receiver):
        self.receiver, self.read, self.frames, self.current = receiver, 0, [], {}

    def update(self) -> list[dict[str, list]]:
        from pythonosc.osc_bundle import OscBundle
        from pythonosc.osc_message import OscMessage

        new = self.receiver.datagrams[self.read:]
        self.read += len(new)
        for datagram in new:
            parts = OscBundle(datagram) if OscBundle.dgram_is_bundle(datagram) else [OscMessage(datagram)]
            for message in parts:
                self.current[message.address] = list(message.params)
                if message.address == "/walk/frame":  # sent last in each frame
                    self.frames.append(self.current)
                    self.current = {}
        return self.frames

    def last(self, address: str) -> float | None:
        frames = self.update()
        return frames[-1][address][0] if frames else None

    def after(self, count: int) -> list[dict[str, list]]:
        """The next `count` frames from now."""
        start = len(self.update())
        return wait_until(lambda: self.update()[start:start + count] if len(self.update()) >= start + count else None,
                          f"{count} more frames", timeout=60)


def head_above_hips(frames: list[dict[str, list]]) -> float:
    """How high the head is above the hips, on average (the upper body's posture)."""
    return float(np.mean([f["/walk/bone/Head/pos"][1] - f["/walk/bone/Hips/pos"][1] for f in frames]))


def step_frames(frames: list[dict[str, list]]) -> int:
    """Frames of one step: the first peak of the autocorrelation of the hips' height."""
    height = np.array([f["/walk/bone/Hips/pos"][1] for f in frames])
    height -= height.mean()
    correlation = np.correlate(height, height, "full")[len(height) - 1:]
    return int(np.argmax(correlation[8:60]) + 8)


@pytest.fixture(scope="module")
def mixer(tmp_path_factory):
    """One show for the tests of the page's controls: the flat OSC stream and a preset file."""
    presets = tmp_path_factory.mktemp("mixer") / "presets.toml"
    presets.write_text('[presets.far]\n"style/elderly" = 3.0\n')
    receiver = Receiver()
    show = Instrument("--console", "0", "--osc", f"127.0.0.1:{receiver.port}/flat", "--quiet", "--presets", str(presets))
    yield show, FlatFrames(receiver)
    stderr = show.stop()
    receiver.close()
    assert show.process.returncode == 0, stderr
    assert "Traceback" not in stderr


def fresh_page(driver, show: Instrument, stream: FlatFrames) -> None:
    """The page open, the show reset to the average walk (the shared show's earlier tests undone)."""
    open_page(driver, show.url)
    driver.find_element("id", "reset").click()
    wait_until(lambda: stream.last("/walk/liveliness") == 0.0 and stream.last("/walk/style/elderly") == 0.0
               and slider_value(driver, "liveliness") == 0.0, what="the reset")


def click_at(driver, element, share: float) -> None:
    """A real pointer click at `share` (0 left end .. 1 right end) of an element's width."""
    from selenium.webdriver.common.action_chains import ActionChains

    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", element)
    offset = int(element.size["width"] * (share - 0.5))
    ActionChains(driver).move_to_element_with_offset(element, offset, 0).click().perform()


@needs_browser
def test_part_weight_phase_stretch_and_liveliness_sliders_reach_the_walk(browser, mixer):
    show, stream = mixer
    fresh_page(browser, show, stream)
    stream.after(60)  # the reset walked through the look-ahead
    average = stream.after(90)
    posture, step = head_above_hips(average), step_frames(average)
    # a body-part weight: the elderly style's upper body, exaggerated to the slider's end, bends the back
    browser.find_element("css selector", "#parts-box summary").click()
    click_at(browser, slider(browser, "part/elderly/upper"), 0.99)
    assert slider_value(browser, "part/elderly/upper") > 3.5
    wait_until(lambda: head_above_hips(stream.update()[-30:]) < posture - 5, what="the upper body to follow its weight")
    # a per-state phase stretch: state 2 of every step drawn out to the slider's end makes the step longer
    browser.find_element("id", "reset").click()
    wait_until(lambda: abs(head_above_hips(stream.update()[-30:]) - posture) < 1, what="the posture back after the reset")
    browser.find_element("css selector", "#phases-box summary").click()
    click_at(browser, slider(browser, "phase/2"), 0.99)
    assert slider_value(browser, "phase/2") > 3.5
    wait_until(lambda: step_frames(stream.update()[-90:]) > step + 3, what="longer steps")
    # liveliness, echoed in the stream
    click_at(browser, slider(browser, "liveliness"), 0.7)
    wanted = slider_value(browser, "liveliness")
    assert 0.5 < wanted < 0.9
    wait_until(lambda: stream.last("/walk/liveliness") == pytest.approx(wanted, abs=1e-6), what="the liveliness in OSC")


def pressed(driver, target: str) -> list[str]:
    """The names of the buttons of a target with named values that the page shows pressed."""
    return driver.execute_script(f"return [...document.querySelectorAll('[data-target=\"{target}\"] button')]"
                                 ".filter((b) => b.getAttribute('aria-pressed') === 'true').map((b) => b.textContent)")


@needs_browser
def test_the_gait_buttons_set_the_gait_and_light_what_the_instrument_echoes(browser, mixer):
    """stand / walk / run: a click reaches /walk/gait; the lit button is the instrument's value, so
    another page's change (by name, over its own WebSocket) and a reset light theirs."""
    show, stream = mixer
    fresh_page(browser, show, stream)
    gait = lambda: browser.find_elements("css selector", '[data-target="gait"] button')  # noqa: E731
    assert [b.text for b in gait()] == ["stand", "walk", "run"]
    wait_until(lambda: stream.last("/walk/gait") == 1.0 and pressed(browser, "gait") == ["walk"], what="walk at the start")
    gait()[2].click()
    wait_until(lambda: stream.last("/walk/gait") == 2.0, what="run in the OSC stream")
    wait_until(lambda: pressed(browser, "gait") == ["run"], what="run lit")
    asyncio.run(talk(show.url, [json.dumps({"set": "gait", "value": "stand"})]))  # another page, by name
    wait_until(lambda: stream.last("/walk/gait") == 0.0, what="stand in the OSC stream")
    wait_until(lambda: pressed(browser, "gait") == ["stand"], what="stand lit by another page's change")
    browser.find_element("id", "reset").click()
    wait_until(lambda: stream.last("/walk/gait") == 1.0 and pressed(browser, "gait") == ["walk"], what="walk after a reset")


def hands_over_head(frame: dict[str, list]) -> float:
    """How far the higher hand is above the head, in the flat stream's bone positions."""
    return max(frame[f"/walk/bone/Hand_{side}/pos"][1] for side in "RL") - frame["/walk/bone/Head/pos"][1]


@needs_browser
def test_a_gesture_button_held_raises_the_hands_until_let_go(browser, mixer):
    """wave, held down with a real pointer: the hands go over the head in the OSC stream's bones
    and the button is lit; let go, the hands come down (the gesture lowers on release)."""
    from selenium.webdriver.common.action_chains import ActionChains

    show, stream = mixer
    fresh_page(browser, show, stream)
    buttons = browser.find_elements("css selector", '[data-target^="gesture/"] button')
    assert [b.text for b in buttons] == ["wave", "raise"]
    assert max(hands_over_head(f) for f in stream.after(30)) < 0  # walking: the hands below the head
    browser.execute_script("arguments[0].scrollIntoView({block: 'center'})", buttons[0])
    ActionChains(browser).click_and_hold(buttons[0]).perform()
    wait_until(lambda: buttons[0].get_attribute("aria-pressed") == "true", what="wave lit while held")
    wait_until(lambda: hands_over_head(stream.update()[-1]) > 0, what="the hands over the head")
    ActionChains(browser).release().perform()
    wait_until(lambda: buttons[0].get_attribute("aria-pressed") == "false", what="wave unlit on release")
    wait_until(lambda: max(hands_over_head(f) for f in stream.update()[-30:]) < 0, "the hands down after the release", timeout=60)


@needs_browser
def test_the_arrow_keys_steer_while_held(browser, mixer):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    show, stream = mixer
    fresh_page(browser, show, stream)
    browser.execute_script("document.activeElement && document.activeElement.blur()")
    for key, turn in ((Keys.ARROW_LEFT, 1.0), (Keys.ARROW_RIGHT, -1.0)):  # positive turns left
        ActionChains(browser).key_down(key).perform()
        wait_until(lambda: stream.last("/walk/turn") == turn, what=f"the turn {turn} while the key is held")
        ActionChains(browser).key_up(key).perform()
        wait_until(lambda: stream.last("/walk/turn") == 0.0, what="the turn back to 0 on release")


@needs_browser
def test_a_preset_recall_morphs_over_the_time_the_page_shows(browser, mixer):
    show, stream = mixer
    fresh_page(browser, show, stream)
    click_at(browser, slider(browser, "morph"), 0.2)  # the morph time, set on the page
    box = browser.find_element("css selector", '[data-target="morph"] input[type=number]')
    wait_until(lambda: browser.execute_script("return latest.v.morph") == slider_value(browser, "morph") > 0,
               what="the instrument to take the morph time")
    shown = float(wait_until(lambda: box.get_attribute("value"), what="the morph time shown"))
    assert 1.0 < shown < 4.0
    start = len(stream.update())
    browser.find_element("css selector", '[data-preset="far"]').click()  # style/elderly 0 -> 3
    wait_until(lambda: stream.last("/walk/style/elderly") == 3.0, what="the preset's value")
    frames = stream.update()[start:]
    path = [(f["/walk/frame"][1], f["/walk/style/elderly"][0]) for f in frames]
    moving = [(t, v) for t, v in path if 0 < v < 3.0]
    assert len(moving) > 10  # in-between values on the way, not a jump
    assert [v for _, v in moving] == sorted(v for _, v in moving)
    began = next(t for t, v in path if v > 0)
    arrived = next(t for t, v in path if v == 3.0)
    # the morph takes the time the page shows, in performance time (a frame either way)
    assert arrived - began == pytest.approx(shown, abs=2 / 30 + 0.01)


def touch_drag(driver, element, start: tuple[float, float], end: tuple[float, float], steps: int = 12) -> None:
    """One finger put down, moved and lifted, in shares of the element's box (Chrome DevTools touch events)."""
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", element)
    left, top, width, height = driver.execute_script("const r = arguments[0].getBoundingClientRect();"
                                                     "return [r.left, r.top, r.width, r.height]", element)

    def point(share):
        return [{"x": left + width * share[0], "y": top + height * share[1]}]

    driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchStart", "touchPoints": point(start)})
    for k in range(1, steps + 1):
        at = [a + (b - a) * k / steps for a, b in zip(start, end)]
        driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchMove", "touchPoints": point(at)})
    driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})


@needs_browser
def test_touch_on_a_tablet_moves_a_slider_and_the_pad(browser, mixer):
    from selenium.webdriver.support.ui import Select

    show, stream = mixer
    browser.execute_cdp_cmd("Emulation.setTouchEmulationEnabled", {"enabled": True, "maxTouchPoints": 5})
    fresh_page(browser, show, stream)
    assert browser.execute_script("return navigator.maxTouchPoints") == 5  # a touch screen, as on a tablet
    touch_drag(browser, slider(browser, "liveliness"), (0.02, 0.5), (0.75, 0.5))
    wanted = slider_value(browser, "liveliness")
    assert 0.5 < wanted < 0.9
    wait_until(lambda: stream.last("/walk/liveliness") == pytest.approx(wanted, abs=1e-6), what="the dragged liveliness in OSC")
    first, second, third = (Select(e) for e in browser.find_elements("css selector", "#pad-styles select"))
    first.select_by_value("normal")
    second.select_by_value("youthful")
    third.select_by_value("")
    # a finger across the pad at half height, from the first style to the second
    touch_drag(browser, browser.find_element("id", "pad"), (0.05, 0.5), (0.99, 0.5))
    wait_until(lambda: stream.last("/walk/style/youthful") == pytest.approx(1.0, abs=0.02)
               and stream.last("/walk/style/normal") == pytest.approx(0.0, abs=0.02), what="the pad's blend by touch")


@needs_browser
def test_orbit_and_the_follow_camera_change_the_view(browser, mixer):
    from selenium.webdriver.common.action_chains import ActionChains

    show, stream = mixer
    fresh_page(browser, show, stream)
    view = browser.find_element("id", "view")

    def camera() -> dict:
        return browser.execute_script("return {...figure.camera, target: [...figure.camera.target]}")

    def root() -> list[float]:
        return browser.execute_script("return figure.positions[Math.max(figure.first, 0)]")

    def apart() -> float:  # the character from the camera's target, on the floor
        c, r = camera(), root()
        return float(np.hypot(c["target"][0] - r[0], c["target"][2] - r[2]))

    wait_until(lambda: apart() < 50, what="the camera on the character")  # so the held camera still sees it
    browser.find_element("id", "follow").click()  # the camera held still, so only the orbit changes the picture
    drawn = "return !figure.dirty && !!figure.positions && figure.positions.length > 0"
    wait_until(lambda: browser.execute_script(drawn), what="the view drawn")
    before, picture = camera(), screenshot(view)
    ActionChains(browser).click_and_hold(view).move_by_offset(150, 60).release().perform()  # orbit
    after = camera()
    assert abs(after["yaw"] - before["yaw"]) > 0.5 and after["pitch"] > before["pitch"] + 0.1
    wait_until(lambda: (np.abs(screenshot(view) - picture).max(axis=2) > 40).sum() > 2000, timeout=60.0,
               what="the orbited view drawn")
    browser.find_element("id", "follow").click()
    # follow off: the camera stays where it is while the character walks away
    browser.find_element("id", "follow").click()
    assert browser.find_element("id", "follow").get_attribute("aria-pressed") == "false"
    fixed = camera()["target"]
    wait_until(lambda: apart() > 150, what="the character to walk out of the centre")
    assert camera()["target"] == fixed
    # follow on: the camera catches up with the character
    browser.find_element("id", "follow").click()
    assert browser.find_element("id", "follow").get_attribute("aria-pressed") == "true"
    wait_until(lambda: apart() < 50, what="the camera to follow")  # it eases after the walking character: a little behind
    browser.find_element("id", "home").click()  # "view": the camera back to its start
    home = camera()
    assert (home["yaw"], home["pitch"]) == (before["yaw"], before["pitch"])


# ---- the WebSocket itself, without a browser: tokens, validation, slow pages --------------------

def socket_url(page_url: str) -> str:
    """The WebSocket address of a page's URL (its token kept)."""
    base, _, query = page_url.partition("?")
    return base.replace("http://", "ws://") + "ws" + (f"?{query}" if query else "")


async def talk(url: str, messages: list[str], origin: str | None = None, wait_for: int = 0) -> list[dict]:
    """Connect to a console's WebSocket, send `messages`, collect replies until `wait_for` refusals."""
    import aiohttp

    replies = []
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(socket_url(url), headers={"Origin": origin} if origin else None) as ws:
            replies.append(json.loads((await ws.receive()).data))
            for text in messages:
                await ws.send_str(text)
            deadline = time.monotonic() + 30
            while sum(r["type"] == "refused" for r in replies) < wait_for and time.monotonic() < deadline:
                message = await ws.receive(timeout=30)
                replies.append(json.loads(message.data))
    return replies


def status_of(url: str, origin: str | None = None) -> int:
    async def get():
        import aiohttp

        try:
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(socket_url(url), headers={"Origin": origin} if origin else None):
                    return 101
        except aiohttp.WSServerHandshakeError as error:
            return error.status

    return asyncio.run(get())


@needs_browser
def test_the_page_offers_only_the_controls_that_do_something_in_this_run(browser):
    """The page builds its controls from the table of targets the hello message carries: a run
    without --sync showed the tempo lock's buttons and steps per beat, and one character the
    crowd's spread, which moved nothing. The rows say what they need; the run says what it has."""
    from instrument.cli.main import build_parser
    from instrument.cli.showplan import plan_show

    def offered(url: str) -> set[str]:
        open_page(browser, url)
        return set(browser.execute_script("return [...document.querySelectorAll('[data-target]')].map(e => e.dataset.target)"))

    for characters, unused, used in (("1", {"sync", "steps-per-beat", "spread"}, {"speed", "gait", "turn"}),
                                      ("2", {"sync", "steps-per-beat"}, {"spread", "speed"})):
        show = Instrument("--console", "127.0.0.1:0", "--no-osc", "--quiet", "--characters", characters)
        try:
            targets = offered(show.url)
            rows = {row["pattern"] for row in asyncio.run(talk(show.url, []))[0]["rows"]}
        finally:
            show.stop()
        assert used <= targets and not unused & targets, targets
        assert not unused & rows and used <= rows
    synced = build_parser("run").parse_args(["run", "--sync", "midi", "--midi-virtual", "x", "--no-osc", "--check"])
    assert plan_show(synced).has() == {"sync"}  # where the lock's controls are offered (test_tempo.py: their rows)


def test_a_named_host_needs_the_token_and_bad_messages_never_stop_the_show(tmp_path):
    import urllib.error
    import urllib.request

    receiver = Receiver()
    show_file = tmp_path / "show.toml"
    show_file.write_text(f'console = "127.0.0.1:0"\nconsole-token = "tok3n"\nquiet = true\n'
                         f'osc = ["127.0.0.1:{receiver.port}/flat"]\n')
    show = Instrument("--config", str(show_file))
    try:
        assert show.url.endswith("?token=tok3n")
        bare = show.url.split("?")[0]
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(bare, timeout=30)
        assert refused.value.code == 403
        assert urllib.request.urlopen(show.url, timeout=30).status == 200
        assert status_of(bare) == 403  # the WebSocket without the token
        assert status_of(show.url.replace("tok3n", "guess")) == 403
        assert status_of(show.url, origin="http://evil.example") == 403  # another site's page in the user's browser
        assert status_of(show.url) == 101
        bad = ["not json", "[1, 2]", '{"set": "style/sleepy", "value": 1}', '{"set": "speed", "value": "fast"}',
               '{"set": "speed", "value": true}', '{"set": "speed", "value": NaN}', '{"set": "speed"}',
               '{"preset": "../../etc"}', '{"store": ""}', '{"save": 1}', '{"launch": "rockets"}', '{"set": 7, "value": 1}',
               '{"set": "speed", "value": 100}']  # out of range: refused, as a file or OSC would (control/checks.py)
        good = ['{"set": "speed", "value": 4}', '{"set": "style/youthful", "value": -0.5}']
        replies = asyncio.run(talk(show.url, bad + good, wait_for=len(bad)))
        assert replies[0]["type"] == "hello" and "youthful" in replies[0]["styles"]
        assert sum(r["type"] == "refused" for r in replies) == len(bad)
        wait_until(lambda: echoed(receiver, "/walk/speed")[-1:] == [4.0], what="the speed at the top of its range")
        wait_until(lambda: echoed(receiver, "/walk/style/youthful")[-1:] == [-0.5], what="the good message")
        frames = len(echoed(receiver, "/walk/speed"))
        wait_until(lambda: len(echoed(receiver, "/walk/speed")) > frames + 10, what="the show to go on")
    finally:
        stderr = show.stop()
        receiver.close()
    assert show.process.returncode == 0, stderr
    assert "console: refused a page's message" in stderr
    assert "Traceback" not in stderr


def test_a_flood_of_page_messages_never_stops_the_show():
    receiver = Receiver()
    show = Instrument("--console", "0", "--quiet", "--osc", f"127.0.0.1:{receiver.port}/flat")
    try:
        flood = [json.dumps({"set": "speed", "value": 1 + (k % 100) / 100}) for k in range(20000)]
        asyncio.run(talk(show.url, flood))  # as fast as the socket takes them; some may be refused, none is fatal

        def taken() -> bool:  # a page's message after the flood: refused while the queue is still full, taken once it drains
            asyncio.run(talk(show.url, ['{"set": "style/active", "value": 0.7}']))
            try:
                return wait_until(lambda: echoed(receiver, "/walk/style/active")[-1:] == [pytest.approx(0.7)], "the message",
                                  timeout=2.0)
            except AssertionError:
                return False

        wait_until(taken, timeout=120.0, what="a message after the flood")
    finally:
        stderr = show.stop()
        receiver.close()
    assert show.process.returncode == 0, stderr
    assert "Traceback" not in stderr


def test_a_page_that_stops_reading_is_dropped_and_the_others_go_on():
    import base64
    import socket

    show = Instrument("--console", "0", "--no-osc", "--quiet")
    stuck = socket.socket()
    try:
        stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # a page that takes nothing: its window fills at once
        port = int(show.url.rsplit(":", 1)[1].strip("/"))
        stuck.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        stuck.sendall(f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                      f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
        show.wait_for("a page connected")
        replies = []

        async def reading_page():  # a page that keeps up, meanwhile
            import aiohttp

            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(socket_url(show.url)) as ws:
                    deadline = time.monotonic() + 90
                    while time.monotonic() < deadline and not any("dropped a page" in line for line in show.lines):
                        message = json.loads((await ws.receive(timeout=30)).data)
                        if message["type"] == "frame":
                            replies.append(message["frame"])
                    for _ in range(30):  # and frames keep coming after the drop
                        message = json.loads((await ws.receive(timeout=30)).data)
                        replies.append(message["frame"])

        asyncio.run(reading_page())
    finally:
        stuck.close()
        stderr = show.stop()
    assert show.process.returncode == 0, stderr
    assert "dropped a page that took no frame" in stderr
    assert len(replies) > 60 and replies == sorted(replies)


def test_every_interface_prints_an_address_a_tablet_can_open():
    import ipaddress
    import urllib.request

    show = Instrument("--console", "0.0.0.0:0", "--no-osc", "--quiet")
    try:
        lines = [line for line in show.lines if line.startswith("console: http")]
        host = ipaddress.ip_address(show.url.split("/")[2].rsplit(":", 1)[0])
        assert not host.is_unspecified
        if host.is_loopback:  # a machine without a network: said so, not a URL that cannot work
            assert "this machine has no network address" in lines[0]
        else:
            assert "open this on a tablet or computer on the network" in lines[0]
            assert urllib.request.urlopen(show.url, timeout=30).status == 200  # served at that address, token included
            loopback = show.wait_for(r"console: (http://127\.0\.0\.1:\S+) \(on this machine\)").group(1)
            assert urllib.request.urlopen(loopback, timeout=30).status == 200
        assert not any("0.0.0.0" in line for line in lines)
    finally:
        stderr = show.stop()
    assert show.process.returncode == 0, stderr


@pytest.mark.parametrize("address,message", [("nowhere:abc", "--console 'nowhere:abc': expected [HOST:]PORT"),
                                             ("70000", "port: expected a whole number from 0 to 65535")])
def test_bad_console_addresses_are_one_line_errors(address, message):
    result = subprocess.run(RUN + ["--console", address, "--no-osc", "--seconds", "1"], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_a_taken_port_is_a_one_line_error():
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run(RUN + ["--console", str(port), "--no-osc", "--seconds", "1"], capture_output=True, text=True,
                                timeout=60)
    assert result.returncode == 1
    assert f"--console '{port}': cannot listen" in result.stderr and len(result.stderr.strip().splitlines()) == 1


# ---- what a peer can make the console hold, and what it must never do --------------------------

def console_port(url: str) -> int:
    return int(url.split("?")[0].rstrip("/").rsplit(":", 1)[1])


def handshake(port: int, host: str, origin: str | None = None, path: str = "/ws") -> int:
    """The HTTP status a WebSocket handshake gets with these Host and Origin headers (a raw socket:
    what a browser whose page was served from another name sends)."""
    import base64
    import socket

    key = base64.b64encode(os.urandom(16)).decode()
    request = (f"GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n" + (f"Origin: {origin}\r\n" if origin else "")
               + "\r\n")
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(request.encode())
        status = b""
        while b"\r\n" not in status:
            chunk = sock.recv(1024)
            if not chunk:
                break
            status += chunk
    return int(status.split()[1])


class Page:
    """A page as a plain WebSocket client in a thread of its own: sends what it is given, keeps
    everything it is sent (the presets' names, frames, refusals, saves)."""

    def __init__(self, url: str):
        self.url, self.replies, self.outbox = url, [], None
        self.loop = asyncio.new_event_loop()
        self.ready = threading.Event()
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(self._run(),), daemon=True)
        self.thread.start()
        assert self.ready.wait(60), "the page never connected"

    async def _run(self) -> None:
        import aiohttp

        self.outbox = asyncio.Queue()
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(socket_url(self.url)) as ws:
                self.ready.set()

                async def sender():
                    while (text := await self.outbox.get()) is not None:
                        await ws.send_str(text)
                    await ws.close()

                task = asyncio.ensure_future(sender())
                async for message in ws:
                    if message.type == aiohttp.WSMsgType.TEXT:
                        self.replies.append(json.loads(message.data))
                await task

    def send(self, *items: dict) -> None:
        for item in items:
            self.loop.call_soon_threadsafe(self.outbox.put_nowait, json.dumps(item))

    def presets(self) -> list[str]:
        """The names the instrument last told this page (with its hello, then as they change)."""
        told = [r["presets"] for r in self.replies if r["type"] in ("hello", "presets")]
        return told[-1] if told else []

    def frames(self) -> int:
        return sum(r["type"] == "frame" for r in self.replies)

    def of(self, kind: str) -> list[dict]:
        return [r for r in self.replies if r["type"] == kind]

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.outbox.put_nowait, None)
        self.thread.join(30)


def test_hundreds_of_presets_stored_from_a_page_keep_the_console_alive():
    """Once the preset table outgrew one packet of the link (~620 presets) the link closed without
    a word: frames stopped, controls did nothing. Now it goes in parts."""
    receiver = Receiver()
    show = Instrument("--console", "0", "--quiet", "--osc", f"127.0.0.1:{receiver.port}/flat")
    try:
        page = Page(show.url)
        names = [f"look-{k:03d}" for k in range(700)]
        for start in range(0, 700, 50):  # in batches the link's queue holds (a flood is refused: another test)
            for k in range(start, start + 50):
                page.send({"set": "speed", "value": 0.5 + k / 1000}, {"store": names[k]})
            wait_until(lambda: page.presets() == names[: start + 50], f"{start + 50} presets on the page", timeout=120)
        frames = page.frames()
        wait_until(lambda: page.frames() > frames + 30, "frames after the presets", timeout=60)
        page.send({"set": "style/active", "value": 0.7})  # the controls still work
        wait_until(lambda: echoed(receiver, "/walk/style/active")[-1:] == [pytest.approx(0.7)], what="a control after")
        later = Page(show.url)  # and a page opened now is told them all
        wait_until(lambda: later.presets() == names, "the presets on a new page", timeout=60)
        later.close()
        page.send({"preset": "look-650"})  # a preset stored late recalls what it stored
        wait_until(lambda: echoed(receiver, "/walk/speed")[-1:] == [pytest.approx(1.15, abs=1e-4)], what="look-650 recalled")
        page.close()
    finally:
        stderr = show.stop()
        receiver.close()
    assert show.process.returncode == 0, stderr
    assert "console gone" not in stderr and "server process stopped" not in stderr and "Traceback" not in stderr


def test_presets_stored_over_osc_and_from_pages_stop_at_the_documented_maximum():
    """Each new name over /walk/store/<name> kept another preset for ever (+1.25 kB a message)."""
    from pythonosc.udp_client import SimpleUDPClient

    from instrument.control.hub import MAX_PRESETS
    from oscrecv import free_port

    control_port = free_port()
    show = Instrument("--console", "0", "--quiet", "--no-osc", "--osc-in", str(control_port))
    client = SimpleUDPClient("127.0.0.1", control_port)
    try:
        page = Page(show.url)
        sent = 0
        while sent < MAX_PRESETS + 50:  # in batches the UDP buffer holds, each seen on the page before the next
            for k in range(sent, sent + 100):
                client.send_message(f"/walk/store/osc-{k:05d}", 1.0)
            sent += 100
            wait_until(lambda: len(page.presets()) >= min(sent, MAX_PRESETS), f"{min(sent, MAX_PRESETS)} presets", timeout=120)
        show.wait_for(f"already {MAX_PRESETS} presets, the most a show holds")
        page.send({"store": "one-more"})  # the page is told why
        wait_until(lambda: any("the most a show holds" in r["reason"] for r in page.of("refused")), what="the refusal")
        page.send({"set": "speed", "value": 1.5}, {"store": "osc-00007"})  # an existing name is stored over
        page.close()
        later = Page(show.url)
        wait_until(lambda: later.presets(), what="the presets on a new page")
        assert len(later.presets()) == MAX_PRESETS and "one-more" not in later.presets()
        assert later.presets()[-1] == f"osc-{MAX_PRESETS - 1:05d}"
        later.close()
    finally:
        stderr = show.stop()
    assert show.process.returncode == 0, stderr
    assert "Traceback" not in stderr


def test_a_page_served_from_another_name_is_refused_dns_rebinding():
    """Without a host given there is no token: the Host header must name this console, or another
    site whose name now points at 127.0.0.1 could drive it."""
    import urllib.error
    import urllib.request

    receiver = Receiver()
    show = Instrument("--console", "0", "--quiet", "--osc", f"127.0.0.1:{receiver.port}/flat")
    try:
        port = console_port(show.url)
        evil = f"rebind.evil.example:{port}"
        assert handshake(port, evil, origin=f"http://{evil}") == 403
        assert handshake(port, evil) == 403
        assert handshake(port, "127.0.0.1:1") == 403  # another port of this machine: another site
        for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}", f"LOCALHOST:{port}"):
            assert handshake(port, host, origin=f"http://{host}") == 101, host
        request = urllib.request.Request(show.url, headers={"Host": evil})
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=30)
        assert refused.value.code == 403
        assert urllib.request.urlopen(show.url, timeout=30).status == 200
        show.wait_for("refused a request for host 'rebind.evil.example")
    finally:
        stderr = show.stop()
        receiver.close()
    assert show.process.returncode == 0, stderr


def test_saving_first_thing_keeps_every_preset_and_the_names_read_back(tmp_path):
    """A save that came before the first frame after a page connected wrote "saved 0 presets"
    over the file. (A name beyond U+FFFF was written as JSON's surrogate pair, which TOML refuses:
    names are now the one rule's, control/spec.PRESET_NAME, in a file as from a page.)"""
    import tomllib

    saved = tmp_path / "presets.toml"
    saved.write_text('[presets."walk.1"]\n"style/elderly" = 1.5\n\n[presets.say-hi_back]\nspeed = 1.25\n',
                     encoding="utf-8")
    before = tomllib.loads(saved.read_text(encoding="utf-8"))["presets"]
    show = Instrument("--console", "0", "--quiet", "--no-osc", "--presets", str(saved))
    try:
        page = Page(show.url)
        page.send({"save": True})  # the very first thing the page does
        wait_until(lambda: page.of("saved"), what="the save")
        assert page.of("saved")[0].get("text", "").startswith("saved 2 presets"), page.of("saved")
        page.close()
    finally:
        stderr = show.stop()
    assert show.process.returncode == 0, stderr
    after = tomllib.loads(saved.read_text(encoding="utf-8"))["presets"]
    assert after == before
    result = subprocess.run(RUN + ["--presets", str(saved), "--no-osc", "--seconds", "0.5", "--fast", "--quiet"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_presets_that_would_replace_a_show_file_are_refused(tmp_path):
    show_file = tmp_path / "show.toml"
    show_file.write_text('no-osc = true\nseconds = 1\n\n[presets.calm]\n"style/elderly" = 0.5\n')
    before = show_file.read_bytes()
    result = subprocess.run(RUN + ["--config", str(show_file), "--console", "0", "--presets", str(show_file)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert f"{show_file}:1: no-osc: unknown key" in result.stderr  # a presets file holds [presets] only
    assert len(result.stderr.strip().splitlines()) == 1
    assert show_file.read_bytes() == before


def test_pages_beyond_the_maximum_are_refused_and_the_others_go_on():
    from instrument.console.server import MAX_PAGES

    show = Instrument("--console", "0", "--quiet", "--no-osc")
    pages = []
    try:
        pages = [Page(show.url) for _ in range(MAX_PAGES)]
        wait_until(lambda: all(page.frames() for page in pages), "frames on every page", timeout=120)
        assert status_of(show.url) == 503
        show.wait_for(f"already {MAX_PAGES} open")
        pages.pop().close()
        wait_until(lambda: status_of(show.url) == 101, "room for one page again", timeout=60)
    finally:
        for page in pages:
            page.close()
        stderr = show.stop()
    assert show.process.returncode == 0, stderr


def test_a_stopped_console_server_is_said_and_shown_down_in_health():
    import signal
    import socket

    from oscrecv import free_port

    status_port = free_port()
    show = Instrument("--console", "0", "--quiet", "--no-osc", "--status-port", str(status_port))
    asker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    asker.settimeout(30)

    def report() -> dict:
        asker.sendto(b"status", ("127.0.0.1", status_port))
        return json.loads(asker.recv(65536))

    try:
        wait_until(lambda: report()["outputs"].get("console") == "up", "the console up", timeout=60)
        children = open(f"/proc/{show.process.pid}/task/{show.process.pid}/children").read().split()
        servers = [int(c) for c in children if "instrument.console.server" in open(f"/proc/{c}/cmdline").read()]
        assert len(servers) == 1
        os.kill(servers[0], signal.SIGKILL)
        show.wait_for("console: the server process stopped; the show goes on without it")
        down = wait_until(lambda: (r := report())["outputs"]["console"] == "down" and r, "the console down", timeout=60)
        assert any("stopped" in d for d in down["devices"] if d.startswith("console"))
        frames = down["frames"]
        wait_until(lambda: report()["frames"] > frames + 30, "the show to go on", timeout=60)
    finally:
        asker.close()
        stderr = show.stop()
    assert show.process.returncode == 0, stderr


def test_a_presets_file_of_hundreds_reaches_the_pages_and_saves_whole(tmp_path):
    """The table a presets file brings at start is larger than the link's queue: it goes over in
    parts across frames, and a save waits for them all."""
    import tomllib

    styles = ("active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful")
    whole = "".join(f'"style/{s}" = 0.25\n' + "".join(f'"part/{s}/{g}" = 0.5\n' for g in ("root", "legs", "upper"))
                    for s in styles) + "speed = 1.5\nliveliness = 0.5\n"  # every target a preset keeps: ~1 kB
    saved = tmp_path / "many.toml"
    saved.write_text("".join(f'[presets.p{k:03d}]\n"phase/1" = {1 + k / 1000}\n{whole}\n' for k in range(900)))
    show = Instrument("--console", "0", "--quiet", "--no-osc", "--presets", str(saved))
    try:
        page = Page(show.url)
        wait_until(lambda: len(page.presets()) == 900, "900 presets on the page", timeout=120)
        page.send({"save": True})
        wait_until(lambda: page.of("saved"), "the save", timeout=60)
        assert page.of("saved")[0].get("text", "").startswith("saved 900 presets"), page.of("saved")
        page.close()
    finally:
        stderr = show.stop()
    assert show.process.returncode == 0, stderr
    presets = tomllib.loads(saved.read_text())["presets"]
    assert len(presets) == 900 and presets["p123"]["phase/1"] == 1.123 and presets["p899"]["part/youthful/upper"] == 0.5
