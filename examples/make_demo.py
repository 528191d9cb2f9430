"""Writes examples/demo/demo.jsonl, the built-in demo performance of `instrument run`.

A minute of a virtual performer on a "demo" source whose controls are the targets themselves:
faders swept at 10 events a second through the styles, the speed, an exaggeration (feminine
at 2), an inversion (exhausted at -1), a turn, and back to the average walk, so the loop joins.

    python examples/make_demo.py
"""

from __future__ import annotations

from pathlib import Path

from instrument.control.events import ControlEvent

# (start, end, target, from, to): linear fader moves
MOVES = [
    (4, 8, "style/elderly", 0.0, 1.0),
    (12, 15, "style/elderly", 1.0, 0.0),
    (12, 15, "style/youthful", 0.0, 1.0),
    (18, 22, "style/youthful", 1.0, 0.0),
    (18, 22, "style/feminine", 0.0, 2.0),
    (26, 29, "style/feminine", 2.0, 0.0),
    (26, 29, "style/masculine", 0.0, 1.0),
    (26, 29, "speed", 1.0, 1.4),
    (32, 35, "style/masculine", 1.0, 0.0),
    (32, 35, "style/exhausted", 0.0, -1.0),
    (32, 35, "speed", 1.4, 1.0),
    (38, 41, "style/exhausted", -1.0, 1.0),
    (38, 41, "speed", 1.0, 0.7),
    (44, 46, "style/exhausted", 1.0, 0.0),
    (44, 46, "style/active", 0.0, 1.5),
    (44, 46, "speed", 0.7, 1.0),
    (46, 48, "turn", 0.0, 0.5),
    (52, 54, "turn", 0.5, 0.0),
    (54, 58, "style/active", 1.5, 0.0),
]
RATE = 10  # events per second while a fader moves


def events() -> list[ControlEvent]:
    out = []
    for start, end, target, first, last in MOVES:
        count = int((end - start) * RATE)
        for k in range(count + 1):
            out.append(ControlEvent(start + k / RATE, "demo", target, round(first + (last - first) * k / count, 4)))
    return sorted(out, key=lambda e: e.time)


def main() -> None:
    path = Path(__file__).with_name("demo") / "demo.jsonl"
    path.write_text("".join(e.to_json() + "\n" for e in events()) + "")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
