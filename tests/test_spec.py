"""One spec, one verdict: the same bad value is refused alike by every path into the control state.

The values of BAD go through every input: OSC over a real UDP socket, a controller log replayed,
the console's message decoder, and the files (a presets file, a show file's [presets], a
mapping's [presets] and its controls' ranges, a score's [presets] and ramps). Each must refuse
with the kind given here; each file must name itself, the line of the bad key (after a comment
on line 1 that mentions the same key, which must not be taken for it) and the key.
"""

from __future__ import annotations

import argparse
import json
import math
import socket
import time
from pathlib import Path

import pytest
from pythonosc.osc_message_builder import OscMessageBuilder

from conftest import REPO
from instrument.cli import showplan
from instrument.console.messages import Refused, parse
from instrument.control.checks import ACTION, NOT_A_NUMBER, OUT_OF_RANGE, UNKNOWN, refusal
from instrument.control.devices import OscInput
from instrument.control.events import LogReplay, read_log
from instrument.control.hub import ControlHub
from instrument.control.mapping import load_mapping
from instrument.control.presetfile import model_of, read_presets, read_presets_file
from instrument.control.score import load_score
from instrument.control.spec import TABLE, markdown_table
from instrument.control.state import ControlState
from instrument.control.values import all_values
from instrument.errors import UserError
from instrument.terminal import Console
from instrument.tomlfile import key_lines

HUGE = 10 ** 400  # an integer no float holds
# (target, value, the kind of refusal every path must give)
BAD = [
    ("style/elderly", 50, OUT_OF_RANGE),
    ("speed", 99, OUT_OF_RANGE),
    ("turn", -3.5, OUT_OF_RANGE),
    ("phase/1", 0.0, OUT_OF_RANGE),
    ("style/nobody", 1.0, UNKNOWN),
    ("part/elderly/tail", 1.0, UNKNOWN),
    ("sped", 1.0, UNKNOWN),
    ("turn", "left", NOT_A_NUMBER),
    ("gait", "sprint", NOT_A_NUMBER),  # a name the row lacks (stand, walk, run)
    ("gait", "Run", NOT_A_NUMBER),  # names as written, as a style's are (two styles may differ only in case)
    ("gait", 3, OUT_OF_RANGE),
    ("speed", True, NOT_A_NUMBER),
    ("speed", math.nan, NOT_A_NUMBER),
    ("liveliness", math.inf, NOT_A_NUMBER),
    ("speed", HUGE, NOT_A_NUMBER),
]
IDS = [f"{t}={v if v != HUGE else '10**400'}" for t, v, _ in BAD]


@pytest.fixture(scope="module")
def state_of(model):
    return lambda: ControlState(model.style_names, model.states)


def toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return json.dumps(value)


def entry(target: str, value: object) -> str:
    return f"{json.dumps(target)} = {toml_value(value)}"


def comment(target: str) -> str:
    """A first line that mentions the bad key: a line finder that searches the text would stop here."""
    return f'# {json.dumps(target)} = 1.0 was the old value; {target} presets calm ramp\n'


# --- each file kind: write a file with the bad entry (after a comment naming it), read it -------

def presets_file(tmp_path: Path, state: ControlState, target: str, value: object) -> None:
    path = tmp_path / "mine.toml"
    path.write_text(comment(target) + '[presets.calm]\nspread = 0.5\n' + entry(target, value) + "\n")
    read_presets_file(path, model_of(state))


def show_file(tmp_path: Path, state: ControlState, target: str, value: object) -> None:
    path = tmp_path / "show.toml"
    path.write_text(comment(target) + 'seconds = 1\n\n[presets.calm]\nspread = 0.5\n' + entry(target, value) + "\n")
    args = argparse.Namespace(config=str(path), run=None, command=None, seconds=None)
    read_presets(showplan.apply_show_file(args), model_of(state))


def mapping_presets(tmp_path: Path, state: ControlState, target: str, value: object) -> None:
    path = tmp_path / "m.toml"
    path.write_text(comment(target) + '[device]\nmidi = "x"\n\n[presets.calm]\n' + entry(target, value) + "\n")
    load_mapping(path, state, strict_styles=True)


def mapping_range(tmp_path: Path, state: ControlState, target: str, value: object) -> None:
    """A fader whose range reaches the bad value would send it: refused when the mapping is read."""
    path = tmp_path / "m.toml"
    path.write_text(comment(target) + '[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 7\n'
                    f'target = {json.dumps(target)}\nrange = [{toml_value(value)}, 0.5]\n')
    load_mapping(path, state, strict_styles=True)


def score_presets(tmp_path: Path, state: ControlState, target: str, value: object) -> None:
    path = tmp_path / "s.toml"
    path.write_text(comment(target) + '[presets.calm]\nspread = 0.5\n' + entry(target, value)
                    + '\n\n[[cue]]\npreset = "calm"\n')
    load_score(path, state)


def score_ramp(tmp_path: Path, state: ControlState, target: str, value: object) -> None:
    path = tmp_path / "s.toml"
    path.write_text(comment(target) + '[[cue]]\nhold = 1\n\n[[cue]]\nover = 2\nramp = { spread = 0.5, '
                    + entry(target, value) + " }\n")
    load_score(path, state)


FILES = [presets_file, show_file, mapping_presets, mapping_range, score_presets, score_ramp]


def written_line(path: Path, wanted: str) -> int:
    """The line of `path` holding `wanted`, comments aside (what the error must name)."""
    lines = path.read_text().splitlines()
    return next(k for k, text in enumerate(lines, 1) if wanted in text and not text.startswith("#"))


@pytest.mark.parametrize("target,value,kind", BAD, ids=IDS)
@pytest.mark.parametrize("read", FILES, ids=[f.__name__ for f in FILES])
def test_every_file_kind_refuses_a_bad_value_naming_file_line_and_key(tmp_path, state_of, read, target, value, kind):
    state = state_of()
    expected = refusal(target, value, state.style_index, state.states)
    assert expected is not None and expected.kind == kind
    if read is mapping_range and kind == NOT_A_NUMBER:
        pytest.skip("a range is two numbers by the mapping's schema, before any target is asked")
    with pytest.raises(UserError) as error:
        read(tmp_path, state, target, value)
    path = next(p for p in tmp_path.iterdir() if p.suffix == ".toml")
    if read is mapping_range:
        wanted = f"target = {json.dumps(target)}" if kind == UNKNOWN else "range = "
    else:
        wanted = entry(target, value)
    assert str(error.value).startswith(f"{path}:{written_line(path, wanted)}: "), str(error.value)
    assert str(error.value).endswith(expected.text), str(error.value)


def test_the_elderly_preset_of_the_issue_is_refused_by_all_four_file_kinds_and_the_page(tmp_path, state_of):
    """`"style/elderly" = 50`: a presets file, a show file's [presets], a mapping's [presets] and a
    score, each naming its file and the line; the page refuses the same value."""
    state = state_of()
    for read, line in ((presets_file, 4), (show_file, 6), (mapping_presets, 6), (score_presets, 4)):
        with pytest.raises(UserError) as error:
            read(tmp_path, state, "style/elderly", 50)
        path = next(p for p in tmp_path.iterdir() if p.suffix == ".toml")
        assert str(error.value).startswith(f"{path}:{line}: "), str(error.value)
        assert "style/elderly: 50 is out of range (-10 to 10)" in str(error.value)
        path.unlink()
    with pytest.raises(Refused, match=r"style/elderly: 50 is out of range \(-10 to 10\)"):
        parse('{"set": "style/elderly", "value": 50}', frozenset(state.targets()))


# --- the live paths -----------------------------------------------------------------------------

def osc_packet(address: str, value: object) -> bytes | None:
    """`value` as an OSC argument (a double for floats), or None when OSC cannot carry it."""
    builder = OscMessageBuilder(address)
    if isinstance(value, bool):
        builder.add_arg(value)
    elif isinstance(value, str):
        builder.add_arg(value, "s")
    elif isinstance(value, int) and abs(value) >= 2 ** 63:
        return None
    else:
        builder.add_arg(float(value), "d")
    return builder.build().dgram


@pytest.mark.parametrize("target,value,kind", BAD, ids=IDS)
def test_osc_over_udp_refuses_alike(state_of, target, value, kind):
    packet = osc_packet("/walk/" + target, value)
    if packet is None:
        pytest.skip("OSC has no argument type for an integer this large")
    state, console = state_of(), Console(quiet=True)
    before = all_values(state)
    osc = OscInput(console, "127.0.0.1:0")
    hub = ControlHub([], console=console)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.sendto(packet, osc.sock.getsockname())
            sender.sendto(osc_packet("/walk/spread", 0.5), osc.sock.getsockname())  # a good one after it
            deadline = time.monotonic() + 30
            while state.spread != 0.5 and time.monotonic() < deadline:
                for event in osc.poll(0.0):
                    hub.apply(state, event)
                time.sleep(0.01)
    finally:
        osc.close()
    assert state.spread == 0.5, "the good message after the bad one never arrived"
    refused = {**hub.refused, **osc.refused}
    # a non-number the OSC reader cannot read as one is refused there (type tag), the rest by the one check
    # (a string for a target with named values is read: a name it lacks gets the one check's verdict)
    by_tag = isinstance(value, bool) or (isinstance(value, str) and not TABLE[target].choices)
    assert refused == ({"argument": 1} if kind == NOT_A_NUMBER and by_tag else {kind: 1}), refused
    assert _same(all_values(state), {**before, "spread": 0.5})  # nothing but the good message changed anything


def _same(a: dict, b: dict) -> bool:
    """Equal values, NaN (a part weight following its style) equal to NaN."""
    return a.keys() == b.keys() and all(x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(a.values(), b.values()))


@pytest.mark.parametrize("target,value,kind", BAD, ids=IDS)
def test_a_replayed_log_refuses_alike(tmp_path, state_of, target, value, kind):
    state, console = state_of(), Console(quiet=True)
    before = all_values(state)
    log = tmp_path / "take.jsonl"
    bad = json.dumps({"t": 0.5, "source": "osc", "control": target, "value": value})
    log.write_text(json.dumps({"t": 0.1, "source": "osc", "control": "spread", "value": 0.5}) + "\n" + bad + "\n")
    if kind == NOT_A_NUMBER:  # a log line whose value is no number is a broken log: refused naming the line
        with pytest.raises(UserError, match=f"^{log}:2: .*finite numbers"):
            read_log(log)
        return
    hub = ControlHub([], console=console)
    for event in LogReplay(read_log(log)).due(1.0):
        hub.apply(state, event)
    assert hub.refused == {kind: 1}
    assert _same(all_values(state), {**before, "spread": 0.5})


@pytest.mark.parametrize("target,value,kind", BAD, ids=IDS)
def test_the_console_page_refuses_alike(state_of, target, value, kind):
    state = state_of()
    expected = refusal(target, value, state.style_index, state.states)
    with pytest.raises(Refused) as refused:
        parse(json.dumps({"set": target, "value": value}), frozenset(state.targets()))
    assert str(refused.value) == expected.text


@pytest.mark.parametrize("name", ["Run", "STAND", "Walk"])
def test_a_gait_name_in_another_case_is_refused_in_one_line_naming_the_control_and_its_names(state_of, name):
    """Enumerated values are taken as written, as style names are (`style/Elderly` is unknown): the
    refusal every input gives (the table above runs it through each) names gait and lists its names."""
    state = state_of()
    assert refusal("style/" + state.style_names[0].upper(), 1.0, state.style_index, state.states).kind == UNKNOWN
    refused = refusal("gait", name, state.style_index, state.states)
    assert refused.kind == NOT_A_NUMBER and "\n" not in refused.text
    assert refused.text.startswith("gait: ") and "stand, walk, run" in refused.text and repr(name) in refused.text


@pytest.mark.parametrize("value", ["run", 2, 2.0])
def test_a_named_value_is_taken_for_its_number_by_every_file_and_the_page(tmp_path, state_of, value):
    """gait = "run" is gait = 2 in a presets file, a show's, a mapping's and a score's [presets],
    a score's ramp and a page's message (OSC: test_controllers.py)."""
    state = state_of()
    path = tmp_path / "mine.toml"
    path.write_text(f'[presets.calm]\n{entry("gait", value)}\n')
    assert read_presets_file(path, model_of(state)) == {"calm": {"gait": 2.0}}
    path = tmp_path / "s.toml"
    path.write_text(f'[presets.calm]\n{entry("gait", value)}\n\n[[cue]]\npreset = "calm"\n\n[[cue]]\n'
                    f'ramp = {{ {entry("gait", value)} }}\n')
    assert [cue.ramp for cue in load_score(path, state).cues] == [{"gait": 2.0}, {"gait": 2.0}]
    path = tmp_path / "m.toml"
    path.write_text(f'[device]\nmidi = "x"\n\n[presets.calm]\n{entry("gait", value)}\n')
    assert load_mapping(path, state, strict_styles=True).presets == {"calm": {"gait": 2.0}}
    assert parse(json.dumps({"set": "gait", "value": value}), frozenset(state.targets())) == ("event", "gait", 2.0)
    assert state.set("gait", value) and state.gait == 2.0 and state.snapshot().gait == 2


def test_a_presets_file_holds_presets_and_nothing_else(tmp_path, state_of):
    path = tmp_path / "mine.toml"
    path.write_text('# saved\n[preset.calm]\nspeed = 1.0\n')  # [preset...] for [presets...]: not silently ignored
    with pytest.raises(UserError, match=f"^{path}:2: preset: unknown key"):
        read_presets_file(path, model_of(state_of()))


def test_actions_are_pressed_not_held(tmp_path, state_of):
    """reset, cue and preset/<name> are actions: a preset or a ramp holding one is refused."""
    state = state_of()
    with pytest.raises(UserError, match=f"^{tmp_path / 'mine.toml'}:4: presets.calm: reset: {ACTION}"):
        presets_file(tmp_path, state, "reset", 1.0)


# --- the line finder ----------------------------------------------------------------------------

def test_a_keys_line_is_found_by_parsing_not_by_searching_the_text():
    text = ('# fps = 30 is the usual\nname = "fps = 1"  # fps\nml = """\nfps = 2\n"""\nfps = 500\n'
            'osc = [\n  "a:1",  # x\n  "b:2",\n]\n[presets."odd.name"]\n"style/elderly" = 50\n'
            '[[cue]]\nhold = 1\n[[cue]]\nramp = { speed = 1, "phase/1" = 2 }\n')
    lines = key_lines(text)
    assert lines[("fps",)] == 6
    assert lines[("osc", 1)] == 9
    assert lines[("presets", "odd.name", "style/elderly")] == 12
    assert lines[("cue", 1, "ramp", "phase/1")] == 16
    assert lines[("cue", 0, "hold")] == 14


def test_the_show_file_comment_case_names_line_4(tmp_path):
    path = tmp_path / "show.toml"
    path.write_text("# fps: 500 is too fast for this projector\nseconds = 1\n\nfps = 500\n")
    args = argparse.Namespace(config=str(path), run=None, command=None, seconds=None, fps=None)
    with pytest.raises(UserError, match=f"^{path}:4: fps: expected a number from 24 to 120"):
        showplan.apply_show_file(args)


# --- what is derived from the rows --------------------------------------------------------------

def test_the_docs_table_is_the_rows():
    assert markdown_table() in (REPO / "docs" / "controls.md").read_text()


def test_command_line_options_that_set_targets_take_the_rows_range(capsys):
    from instrument.control.options import OPTIONS

    for option, kind in (("synth --speed", "speed"), ("synth --liveliness", "liveliness"), ("synth --style", "style"),
                         ("run --morph", "morph")):
        accepts = OPTIONS[option]
        assert (accepts.low, accepts.high) == (TABLE[kind].low, TABLE[kind].high), option
        with pytest.raises(ValueError):
            accepts.read(str(TABLE[kind].high * 2 + 1))


def test_every_key_of_the_shipped_toml_files_is_found_on_its_own_line():
    """The line finder against every TOML file the project ships (mappings, the demo score, show
    examples): each key of the parsed data is found, on a line that names it."""
    import tomllib

    def paths(data: object, prefix: tuple = ()):
        items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, list) else ()
        for key, value in items:
            yield prefix + (key,)
            yield from paths(value, prefix + (key,))

    files = sorted(REPO.glob("mappings/*.toml")) + sorted(REPO.glob("examples/**/*.toml"))
    assert len(files) >= 10
    for path in files:
        text = path.read_text()
        lines, written = key_lines(text), text.splitlines()
        for key in paths(tomllib.loads(text)):
            assert key in lines, (path, key)
            if isinstance(key[-1], str):
                assert key[-1] in written[lines[key] - 1], (path, key, lines[key])


def test_a_shipped_mapping_may_name_styles_another_model_lacks_but_not_bad_values(tmp_path, state_of):
    """A mapping the user names refuses a style the model lacks; one read for another model (shipped,
    or from a log) keeps it for `style_problems` to warn about. A value out of range is refused by both."""
    state = state_of()
    path = tmp_path / "m.toml"
    path.write_text('[device]\nmidi = "x"\n[presets.calm]\n"style/nobody" = 1.0\n')
    assert load_mapping(path, state).presets == {"calm": {"style/nobody": 1.0}}
    with pytest.raises(UserError, match=f"^{path}:4: presets.calm: style/nobody: {UNKNOWN}"):
        load_mapping(path, state, strict_styles=True)
    path.write_text('[device]\nmidi = "x"\n[presets.calm]\n"style/nobody" = 11.0\n')
    with pytest.raises(UserError, match=f"^{path}:4: presets.calm: style/nobody: 11.0 is {OUT_OF_RANGE}"):
        load_mapping(path, state)


def test_every_shipped_mapping_fits_the_rows_for_the_default_model(state_of):
    """Each shipped control's range and preset lies inside its target's row: nothing a shipped
    controller sends is refused as out of range."""
    from instrument.shipped import shipped_mappings

    for path in shipped_mappings():
        mapping = load_mapping(path, state_of(), strict_styles=True)
        for control in mapping.controls:
            row = TABLE[control.target.split("/")[0]]
            assert row.low <= min(control.range) and max(control.range) <= row.high, (path, control.target)


@pytest.mark.parametrize("target", ["speed", "phase/1", "style/elderly", "liveliness", "turn", "morph", "reset"])
def test_what_learn_writes_for_a_button_loads(tmp_path, state_of, target):
    """A button learned onto any target gives a mapping the one check accepts (a button sends 0
    and 1, which speed or a phase would refuse: learn gives them the row's fader range)."""
    from instrument.control.learn import Learned

    block = Learned("note", 1, 36, "toggle").toml(target, TABLE[target.split("/")[0]].fader)
    path = tmp_path / "learned.toml"
    path.write_text('[device]\nmidi = "x"\n' + block)
    (control,) = load_mapping(path, state_of(), strict_styles=True).controls
    assert refusal(target, control.range[0], state_of().style_index, state_of().states) is None


def test_a_score_recalls_a_shipped_mappings_preset_without_the_styles_the_model_lacks(tmp_path, state_of):
    """A mapping read for another model keeps a preset's unknown style (for a warning); a score's
    preset cue ramps only what the model has, rather than failing when it plays."""
    from instrument.control.score import ScorePlayer

    state = state_of()
    mapping = tmp_path / "m.toml"
    mapping.write_text('[device]\nmidi = "x"\n[presets.calm]\n"style/nobody" = 1.0\n"style/elderly" = 0.5\n')
    presets = load_mapping(mapping, state).presets
    score = tmp_path / "s.toml"
    score.write_text('[[cue]]\npreset = "calm"\nover = 1\n')
    player = ScorePlayer(load_score(score, state, presets), state)
    events = player.due(0.0) + player.due(2.0)
    assert {e.control for e in events} == {"style/elderly"} and events[-1].value == 0.5


def test_the_states_values_and_echo_are_made_again_exactly_when_a_value_changes():
    """The live loop hands every frame the state's values and echo; they are kept between changes
    (a frame with no change makes neither again) and always say what the state holds."""
    from instrument.control.state import ControlState
    from instrument.control.values import all_values

    state = ControlState(["elderly", "youthful"], 5)
    values, echo = all_values(state), state.echo()
    assert all_values(state) is values and state.echo() is echo  # nothing changed: kept
    assert not state.set("style/elderly", 50.0)  # refused: nothing changes
    assert all_values(state) is values
    assert state.set("style/elderly", 0.7)
    assert all_values(state)["style/elderly"] == 0.7 and state.echo()["style/elderly"] == 0.7
    assert values["style/elderly"] == 0.0  # the dict a frame before holds that frame's values
    state.set("speed", 1.5)
    state.set("reset", 1.0)
    assert all_values(state)["style/elderly"] == 0.0 and all_values(state)["speed"] == 1.0
    made = all_values(state)
    assert list(made) == state.value_targets
    assert all(made[t] == state.get(t) or (math.isnan(made[t]) and math.isnan(state.get(t))) for t in made)


@pytest.mark.parametrize("target, hint", [
    ("style/sleepy", "(this model's styles: elderly, youthful)"),
    ("part/sleepy/legs", "(this model's styles: elderly, youthful)"),
    ("part/elderly/arms", "(the parts are root, legs, upper)"),  # the style is right: it named the styles
    ("phase/0", "(phase/1 to phase/5: the states of this model's step)"),  # it listed every kind of target
    ("phase/6", "(phase/1 to phase/5: the states of this model's step)"),
    ("gesture/dance", "(gestures: wave, raise)"),
])
def test_an_unknown_target_says_what_its_kind_takes(tmp_path, target, hint):
    """The refusal names what a target of its kind may be, by the check and in a mapping's line
    (a mapping may name a style the model lacks: it is then left out, not refused)."""
    refused = refusal(target, 1.0, ["elderly", "youthful"], 5)
    assert refused.kind == UNKNOWN and refused.text == f"{target}: unknown target {hint}"
    if "styles" in hint:
        return
    mapping = tmp_path / "m.toml"
    mapping.write_text(f'name = "m"\n[device]\nmidi = "x"\n\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "{target}"\n')
    with pytest.raises(UserError) as error:
        load_mapping(mapping, ControlState(["elderly", "youthful"], 5))
    assert str(error.value) == f"{mapping}:8: target: {target}: unknown target {hint}"


def test_an_osc_action_without_an_argument_is_a_press(state_of):
    """Max, QLab and TouchOSC buttons send an address alone: for an action (a preset's recall,
    reset) that is a press; for a target that holds a value it is refused, nothing changed."""
    from pythonosc.osc_message_builder import OscMessageBuilder

    state, console = state_of(), Console(quiet=True)
    osc = OscInput(console, "127.0.0.1:0")
    hub = ControlHub([], console=console)
    taken: list[tuple[str, float]] = []
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for address in ("/walk/reset", "/walk/speed", "/walk/preset/calm"):
                sender.sendto(OscMessageBuilder(address).build().dgram, osc.sock.getsockname())
            sender.sendto(osc_packet("/walk/spread", 0.5), osc.sock.getsockname())  # the last one
            deadline = time.monotonic() + 30
            while state.spread != 0.5 and time.monotonic() < deadline:
                for event in osc.poll(0.0):
                    taken.append((event.control, event.value))
                    hub.apply(state, event)
                time.sleep(0.01)
    finally:
        osc.close()
    assert taken == [("reset", 1.0), ("preset/calm", 1.0), ("spread", 0.5)]
    assert osc.refused == {"argument": 1}  # /walk/speed alone
