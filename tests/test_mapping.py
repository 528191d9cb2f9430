"""Mapping files and the decoding of every message kind, mode and takeover rule."""

import math

import pytest

from instrument.control.events import ControlEvent
from instrument.control.hub import ControlHub
from instrument.control.mapping import Mapper, load_mapping, preset_problems
from instrument.control.state import ControlState
from instrument.errors import UserError
from conftest import REPO, play_mapped

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]


def state() -> ControlState:
    return ControlState(STYLES, 5)


def mapper(tmp_path, controls: str, extra: str = "") -> Mapper:
    path = tmp_path / "m.toml"
    path.write_text(f'{extra}\n[device]\nmidi = "test"\n{controls}')
    return Mapper(load_mapping(path, state()))


def send(m: Mapper, s: ControlState, control: str, value: float, t: float = 0.0) -> bool:
    return play_mapped(m, s, ControlEvent(t, "midi:test", control, value))


def test_absolute_cc_with_range_and_clamping(tmp_path):
    m = mapper(tmp_path, '[[control]]\nmessage = "cc"\nnumber = 7\ntarget = "style/elderly"\nrange = [-1.0, 2.0]\n')
    s = state()
    assert send(m, s, "cc/1/7", 127)
    assert s.get("style/elderly") == pytest.approx(2.0)
    send(m, s, "cc/1/7", 0)
    assert s.get("style/elderly") == pytest.approx(-1.0)
    send(m, s, "cc/1/7", 500)  # out of range: clamped
    assert s.get("style/elderly") == pytest.approx(2.0)
    assert not send(m, s, "cc/1/8", 64)  # unknown messages are ignored
    assert not send(m, s, "cc/2/7", 64)  # other channel


def test_fourteen_bit_pairs_reset_the_lsb_on_a_new_msb(tmp_path):
    m = mapper(tmp_path, '[[control]]\nmessage = "cc14"\nnumber = 1\ntarget = "speed"\nrange = [0.25, 4.0]\n')
    s = state()
    send(m, s, "cc/1/1", 64)  # MSB
    assert s.speed == pytest.approx(0.25 + 3.75 * 64 * 128 / 16383)
    send(m, s, "cc/1/33", 100)  # LSB
    assert s.speed == pytest.approx(0.25 + 3.75 * (64 * 128 + 100) / 16383)
    send(m, s, "cc/1/1", 65)  # a new MSB: LSB back to 0
    assert s.speed == pytest.approx(0.25 + 3.75 * 65 * 128 / 16383)


def test_nrpn_data_entry_and_increments(tmp_path):
    m = mapper(tmp_path, '[[control]]\nmessage = "nrpn"\nnumber = 300\ntarget = "turn"\nrange = [-1.0, 1.0]\nstep = 0.1\n')
    s = state()
    for cc, v in ((99, 2), (98, 44), (6, 127), (38, 127)):  # parameter 2*128+44 = 300
        send(m, s, f"cc/1/{cc}", v)
    assert s.turn == pytest.approx(1.0)
    send(m, s, "cc/1/6", 64)
    send(m, s, "cc/1/38", 0)
    assert s.turn == pytest.approx(-1 + 2 * 64 * 128 / 16383)
    before = s.turn
    send(m, s, "cc/1/97", 0)  # decrement
    assert s.turn == pytest.approx(before - 0.1)
    send(m, s, "cc/1/99", 0)  # another parameter selected: data entry no longer reaches turn
    send(m, s, "cc/1/98", 1)
    send(m, s, "cc/1/6", 0)
    assert s.turn == pytest.approx(before - 0.1)


@pytest.mark.parametrize("mode,up,down", [
    ("relative-twos", 1, 127), ("relative-signed", 1, 65), ("relative-signed2", 65, 1), ("relative-offset", 65, 63),
])
def test_relative_encoders_in_every_encoding(tmp_path, mode, up, down):
    m = mapper(tmp_path, f'[[control]]\nmessage = "cc"\nnumber = 5\nmode = "{mode}"\ntarget = "liveliness"\nstep = 0.1\n')
    s = state()
    for _ in range(3):
        send(m, s, "cc/1/5", up)
    assert s.liveliness == pytest.approx(0.3)
    send(m, s, "cc/1/5", down)
    assert s.liveliness == pytest.approx(0.2)
    for _ in range(10):
        send(m, s, "cc/1/5", down)
    assert s.liveliness == 0.0  # clamped to the range


def test_buttons_toggle_and_momentary_and_pitch_bend(tmp_path):
    m = mapper(tmp_path, '[[control]]\nmessage = "note"\nnumber = 36\nmode = "toggle"\ntarget = "style/active"\n'
                         '[[control]]\nmessage = "note"\nnumber = 37\nmode = "momentary"\ntarget = "style/normal"\n'
                         '[[control]]\nmessage = "pitchbend"\nnumber = 0\ntarget = "speed"\nrange = [0.5, 2.0]\n')
    s = state()
    send(m, s, "note/1/36", 100)
    send(m, s, "note/1/36", 0)
    assert s.get("style/active") == 1.0
    send(m, s, "note/1/36", 90)
    assert s.get("style/active") == 0.0
    send(m, s, "note/1/37", 100)
    assert s.get("style/normal") == 1.0
    send(m, s, "note/1/37", 0)
    assert s.get("style/normal") == 0.0
    send(m, s, "pitchbend/1/0", 16383)
    assert s.speed == pytest.approx(2.0)


def test_a_button_in_mode_set_sets_its_fixed_value_and_its_release_keeps_it(tmp_path):
    """Three buttons for the gait (a name or a number), a cc button for the speed: a press sets,
    a release (velocity 0) changes nothing."""
    m = mapper(tmp_path, '[[control]]\nmessage = "note"\nnumber = 3\nmode = "set"\ntarget = "gait"\nvalue = "stand"\n'
                         '[[control]]\nmessage = "note"\nnumber = 6\nmode = "set"\ntarget = "gait"\nvalue = 1\n'
                         '[[control]]\nmessage = "note"\nnumber = 9\nmode = "set"\ntarget = "gait"\nvalue = "run"\n'
                         '[[control]]\nmessage = "cc"\nnumber = 41\nmode = "set"\ntarget = "speed"\nvalue = 1.5\n')
    s = state()
    assert s.gait == 1.0
    for note, gait in ((9, 2.0), (3, 0.0), (6, 1.0), (9, 2.0)):
        send(m, s, f"note/1/{note}", 100)
        assert s.gait == gait
        send(m, s, f"note/1/{note}", 0)  # let go
        assert s.gait == gait
    send(m, s, "cc/1/41", 127)
    send(m, s, "cc/1/41", 0)
    assert s.speed == 1.5


def test_midi_feedback_lights_the_set_button_of_the_nearest_gait(tmp_path):
    from instrument.control.feedback import raw_values

    m = mapper(tmp_path, "".join(f'[[control]]\nmessage = "note"\nnumber = {n}\nmode = "set"\ntarget = "gait"\nvalue = {v}\n'
                                 for n, v in ((3, 0), (6, 1), (9, 2))))
    lit = lambda gait: [raw_values(c, gait)[0][2] for c in m.mapping.controls]  # noqa: E731
    assert lit(2.0) == [0, 0, 127] and lit(0.0) == [127, 0, 0] and lit(1.4) == [0, 127, 0]


def test_pickup_follows_mixxx(tmp_path):
    m = mapper(tmp_path, '[[control]]\nmessage = "cc"\nnumber = 0\ntarget = "style/elderly"\nrange = [-1.0, 2.0]\ntakeover = "pickup"\n')
    s = state()  # elderly is 0, which is fader position 127/3 = 42.3
    send(m, s, "cc/1/0", 120, t=0.0)  # the first value after enabling is ignored
    assert s.get("style/elderly") == 0.0
    send(m, s, "cc/1/0", 110, t=1.0)  # far from the parameter, not crossing it: ignored
    assert s.get("style/elderly") == 0.0
    assert len(m.awaiting) == 1  # feedback tells the surface where the parameter is
    send(m, s, "cc/1/0", 43, t=2.0)  # near: picked up
    assert s.get("style/elderly") == pytest.approx(43 / 127 * 3 - 1)
    assert not m.awaiting
    send(m, s, "cc/1/0", 90, t=2.02)  # a fast sweep: within 50 ms of the last accepted value
    assert s.get("style/elderly") == pytest.approx(90 / 127 * 3 - 1)
    s.set("style/elderly", 0.0)  # something else moved the parameter (a preset)
    send(m, s, "cc/1/0", 100, t=3.0)  # the fader is far away now: ignored
    assert s.get("style/elderly") == 0.0
    send(m, s, "cc/1/0", 30, t=4.0)  # it crossed the parameter (from above to below): picked up
    assert s.get("style/elderly") == pytest.approx(30 / 127 * 3 - 1)


def test_a_picked_up_fader_moved_in_coarse_slow_steps_keeps_its_parameter(tmp_path):
    """Once a fader has its parameter, each move is taken however far it jumps and however long
    after the last (Mixxx: the previous position was at the parameter). A brisk move of a fader
    sends steps of 8 in 50 ms, timed by the frame that polls them (33 or 67 ms apart); the fader
    lost its parameter after the step that picked it up, leaving elderly at 0.13 of 1.83."""
    m = mapper(tmp_path, '[[control]]\nmessage = "cc"\nnumber = 0\ntarget = "style/elderly"\nrange = [-1.0, 2.0]\ntakeover = "pickup"\n')
    s = state()  # elderly is 0, which is fader position 127/3 = 42.3
    for index, position in enumerate(range(0, 128, 8)):
        send(m, s, "cc/1/0", position, t=index * 0.067)
    assert s.get("style/elderly") == pytest.approx(120 / 127 * 3 - 1)
    s.set("style/elderly", 0.0)  # a preset moves the parameter away from the fader (at 120)
    send(m, s, "cc/1/0", 112, t=5.0)  # the fader was far from the parameter: still ignored
    assert s.get("style/elderly") == 0.0


def test_value_scaling_converges_at_the_end_of_travel(tmp_path):
    m = mapper(tmp_path, '[[control]]\nmessage = "cc"\nnumber = 0\ntarget = "liveliness"\ntakeover = "scale"\n')
    s = state()
    s.set("liveliness", 0.8)
    send(m, s, "cc/1/0", 0, t=0)  # hardware at the bottom, parameter at 0.8
    send(m, s, "cc/1/0", 64, t=1)
    assert 0.8 < s.liveliness < 64 / 127 + 0.8  # it moved up, less than a jump would
    send(m, s, "cc/1/0", 127, t=2)
    assert s.liveliness == pytest.approx(1.0)  # both reach the end together


def test_hid_sticks_have_deadzones(tmp_path):
    path = tmp_path / "pad.toml"
    path.write_text('[device]\nhid = "054c:09cc"\n[[control]]\nmessage = "hid"\ninput = "lx"\ntarget = "turn"\nrange = [-1.0, 1.0]\ndeadzone = 0.1\n')
    m, s = Mapper(load_mapping(path, state())), state()
    for raw in (128, 135, 121):  # within the deadzone around the centre
        play_mapped(m, s, ControlEvent(0, "hid:054c:09cc", "lx", raw))
        assert s.turn == 0.0
    play_mapped(m, s, ControlEvent(0, "hid:054c:09cc", "lx", 255))
    assert s.turn == pytest.approx(1.0)
    play_mapped(m, s, ControlEvent(0, "hid:054c:09cc", "lx", 0))
    assert s.turn == pytest.approx(-1.0)


def test_presets_recall_and_morph_by_performance_time(tmp_path):
    m = mapper(tmp_path, '[[control]]\nmessage = "note"\nnumber = 1\nmode = "momentary"\ntarget = "preset/bold"\n',
               'morph = 2.0\n[presets.bold]\n"style/feminine" = 2.0\nspeed = 1.5\n')
    s = state()
    ControlHub([m.mapping]).start(s)  # the mapping's morph time is the state's at the start
    assert s.get("morph") == 2.0
    send(m, s, "note/1/1", 127, t=10.0)
    s.advance(10.0)
    assert s.get("style/feminine") == 0.0
    s.advance(11.0)
    assert s.get("style/feminine") == pytest.approx(1.0) and s.speed == pytest.approx(1.25)
    s.advance(12.5)
    assert s.get("style/feminine") == pytest.approx(2.0) and s.morph is None
    s.set("morph", 0.5)  # the morph time is a target: a later recall takes the new time
    s.set("reset", 1)
    assert s.get("morph") == 0.5  # a reset keeps it
    send(m, s, "note/1/1", 0, t=20.0)
    send(m, s, "note/1/1", 127, t=20.0)
    s.advance(20.25)
    assert s.get("style/feminine") == pytest.approx(1.0)
    s.advance(20.5)
    assert s.get("style/feminine") == pytest.approx(2.0) and s.morph is None


def test_every_shipped_mapping_loads_and_names_the_default_styles():
    from instrument.control.mapping import style_problems

    files = sorted((REPO / "mappings").glob("*.toml"))
    assert {f.stem for f in files} >= {"korg-nanokontrol2", "akai-midimix", "novation-launch-control-xl",
                                       "behringer-x-touch-mini", "sony-dualshock4", "generic-8-faders"}
    for f in files:
        mapping = load_mapping(f, state())
        assert not style_problems(mapping, state()), f
        styles = {c.target for c in mapping.controls if c.target.startswith("style/")}
        assert len(styles) == 7 or mapping.hid or mapping.hid_usages, f  # a gamepad has too few controls for all seven
        assert any(c.target == "speed" for c in mapping.controls), f


def test_the_readmes_mapping_example_is_a_mapping_that_plays(tmp_path):
    """The user's manual shows a mapping file: it loads, and its fader and gait button do what it says."""
    readme = (REPO / "README.md").read_text()
    start = readme.index('    name = "My fader box"')
    block = readme[start:readme.index("\n\n`instrument run", start)]
    path = tmp_path / "readme.toml"
    path.write_text("\n".join(line[4:] for line in block.splitlines()) + "\n")
    m, s = Mapper(load_mapping(path, state())), state()
    send(m, s, "cc/1/0", 43, t=0.0)  # pick-up: the first value only says where the fader is
    send(m, s, "cc/1/0", 43, t=1.0)  # at the parameter (0 is 42.3 of 127): picked up
    send(m, s, "cc/1/0", 127, t=1.02)  # and swept to the top
    assert s.get("style/elderly") == pytest.approx(2.0)
    send(m, s, "note/1/41", 100)
    assert s.get("gait") == 2.0


def test_a_style_the_model_lacks_is_reported_not_fatal(tmp_path):
    from instrument.control.mapping import style_problems

    path = tmp_path / "m.toml"
    path.write_text('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "style/sleepy"\n')
    assert style_problems(load_mapping(path, state()), state()) == ["style/sleepy"]


@pytest.mark.parametrize("body,line,key", [
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "sped"\n', 6, "target"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 300\ntarget = "speed"\n', 5, "number"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "sysex"\ntarget = "speed"\n', 4, "message"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\nmode = "spin"\n', 7, "mode"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\nrange = [1, 1]\n', 7, "range"),
    ('[device]\nmidi = "x"\n\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\ncolour = "red"\n', 8, "colour"),
    ('[device]\nhid = "sony"\n', 2, "hid"),
    # a key also written elsewhere: the error names [device]'s, not the first one of its name (line 1)
    ('name = "pad"\n[device]\nmidi = "x"\nname = "pad"\n', 4, "name"),
    ('morph = 1.0\n[device]\nmorph = 1.0\n', 3, "morph"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\ntarget = "speed"\n', 3, "number"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\nrange = [nan, 1]\n', 7, "range"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\nrange = [0, inf]\n', 7, "range"),
    ('[device]\nhid = "054c:09cc"\n[[control]]\nmessage = "hid"\ninput = "X"\ntarget = "turn"\ndeadzone = 5\n', 7, "deadzone"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\nmode = "relative-twos"\nstep = -1\n',
     8, "step"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\ntarget = "preset/no such"\n', 6, "target"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\nmode = "set"\ntarget = "gait"\nvalue = "sprint"\n',
     8, "value"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\nmode = "set"\ntarget = "gait"\nvalue = 3\n', 8, "value"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\nmode = "set"\ntarget = "gait"\n', 3, "value"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\ntarget = "gait"\nvalue = 2\n', 7, "value"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "pitchbend"\nmode = "set"\ntarget = "gait"\nvalue = 2\n', 5, "mode"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\nmode = "set"\ntarget = "reset"\nvalue = 1\n', 6, "mode"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\nmode = "set"\ntarget = "gait"\nvalue = 2\n'
     'range = [0, 2]\n', 9, "range"),
    ('[device]\nmidi = "x"\n[[control]]\nmessage = "note"\nnumber = 1\nmode = "set"\ntarget = "gait"\nvalue = true\n', 8, "value"),
])
def test_mapping_errors_name_file_line_and_key(tmp_path, body, line, key):
    path = tmp_path / "bad.toml"
    path.write_text(body)
    with pytest.raises(UserError) as error:
        load_mapping(path, state())
    text = str(error.value)
    assert text.startswith(f"{path}:{line}: {key}:"), text
    assert "\n" not in text


def test_a_control_written_as_one_table_says_to_write_each_as_its_own(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[device]\nmidi = "x"\n\n[control]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\n')
    with pytest.raises(UserError) as error:
        load_mapping(path, state())
    assert str(error.value) == f"{path}:4: control: write each control as [[control]] (a table of its own), not [control]"


def test_broken_toml_is_one_line(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[device\nmidi = 'x'\n")
    with pytest.raises(UserError, match=f"^{path}:1: .*line 1"):
        load_mapping(path, state())


def test_state_ignores_non_numbers_and_unknown_targets():
    s = state()
    assert not s.set("style/elderly", math.nan)
    assert not s.set("nonsense", 1.0)
    assert not s.set("speed", 99.0) and s.speed == 1.0  # out of range: refused (control/checks.py), not clamped


def test_a_preset_button_with_no_such_preset_is_refused_at_start(tmp_path, capsys):
    """A button whose preset nobody defines would do nothing on stage: `run` refuses it, naming the file and line."""
    from instrument.cli.main import main

    path = tmp_path / "m.toml"
    path.write_text('[device]\nmidi = "x"\n# target = "preset/nosuch" once\n[[control]]\nmessage = "note"\nnumber = 1\n'
                    'target = "preset/nosuch"\n')
    assert preset_problems(load_mapping(path, state()), {}) == ["preset/nosuch"]
    assert preset_problems(load_mapping(path, state()), {"nosuch": {"speed": 1.0}}) == []
    assert main(["run", "--mapping", str(path), "--no-osc", "--quiet", "--seconds", "0.1", "--normal-priority"]) == 1
    error = capsys.readouterr().err.strip()
    assert error.startswith(f"instrument run: error: {path}:7: target 'preset/nosuch': no such preset")
    assert "\n" not in error


def test_a_mapper_returns_target_events_and_sets_nothing_itself(tmp_path):
    """Typed edges: the Mapper turns a raw event into the TargetEvents it asks for; only the hub's
    one check-and-apply path (ControlHub.apply_target, as for OSC and the console) changes the state."""
    from instrument.control.events import TargetEvent

    m = mapper(tmp_path, '[[control]]\nmessage = "cc"\nnumber = 7\ntarget = "speed"\nrange = [0.5, 2.0]\n'
                         '[[control]]\nmessage = "note"\nnumber = 1\nmode = "momentary"\ntarget = "preset/calm"\n',
               '[presets.calm]\nspeed = 0.8\n')
    s = state()
    assert m.decode(s, ControlEvent(1.0, "midi:test", "cc/1/7", 127)) == [TargetEvent(1.0, "speed", 2.0)]
    assert s.speed == 1.0  # decoded, not applied
    assert m.decode(s, ControlEvent(2.0, "midi:test", "note/1/1", 127)) == [TargetEvent(2.0, "preset/calm", 1.0)]
    assert m.decode(s, ControlEvent(2.5, "midi:test", "note/1/1", 0)) == []  # let go: nothing asked
    assert m.decode(s, ControlEvent(3.0, "midi:test", "cc/1/9", 64)) is None  # not the mapping's
    assert play_mapped(m, s, ControlEvent(4.0, "midi:test", "cc/1/7", 127)) and s.speed == 2.0


@pytest.mark.parametrize("message,number,limit", [("cc", "0.5", 127), ("cc", "128", 127), ("note", '"x"', 127),
                                                   ("cc14", "1.5", 127), ("nrpn", "20000", 16383), ("nrpn", "0.5", 16383)])
def test_a_bad_number_is_told_the_range_of_its_message(tmp_path, message, number, limit):
    """Every wrong `number` of a message hears one range, that message's: a fraction on a cc was
    told the widest (0 to 16383, an NRPN's) and 128 the cc's."""
    path = tmp_path / "bad.toml"
    path.write_text(f'[device]\nmidi = "x"\n[[control]]\nmessage = "{message}"\nnumber = {number}\ntarget = "speed"\n')
    with pytest.raises(UserError) as error:
        load_mapping(path, state())
    assert str(error.value) == f"{path}:5: number: expected a whole number from 0 to {limit}"


@pytest.mark.parametrize("file, control", [("generic-8-faders.toml", "cc/1/16"), ("behringer-x-touch-mini.toml", "cc/11/10"),
                                           ("novation-launch-control-xl.toml", "cc/9/20")])
def test_a_fader_on_the_gait_stands_walks_and_runs_in_its_thirds(file, control):
    """The docs and the shipped mappings give the gait a fader's thirds; a linear [0, 2] read
    by the nearest whole value gave a quarter, a half and a quarter (CC 40 of 127, past the first
    third, stood; CC 90, past the second, walked). Its feedback stands it in the zone it set."""
    from instrument.control.feedback import raw_values

    state = ControlState(["active", "elderly"], 5)
    mapper = Mapper(load_mapping(REPO / "mappings" / file, state))
    spec = next(s for s in mapper.mapping.controls if s.target == "gait")
    channel, number = int(control.split("/")[1]), int(control.split("/")[2])
    assert (spec.channel, spec.number) == (channel, number)
    play_mapped(mapper, state, ControlEvent(0.0, "midi:x", control, 64))  # pick-up learns where it is: at walk
    for k, cc in enumerate(range(64, -1, -1), 1):  # slowly down to the bottom, then up to the top
        play_mapped(mapper, state, ControlEvent(k, "midi:x", control, cc))
        assert state.snapshot().gait == min(cc * 3 // 127, 2), cc
    for k, cc in enumerate(range(128), 100):
        play_mapped(mapper, state, ControlEvent(k, "midi:x", control, cc))
        assert state.snapshot().gait == min(cc * 3 // 127, 2), cc
        sent = raw_values(spec, state.get("gait"))[0][2]  # what its feedback would send back
        assert min(sent * 3 // 127, 2) == state.snapshot().gait, (cc, sent)
