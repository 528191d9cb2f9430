"""A crowd in the realtime live loop for a minute: does it keep 30 fps?

    python examples/crowd_soak.py [--characters 200] [--seconds 60]

Runs what `instrument bench`'s `largest_crowd_30fps` tries for 3 seconds, for as long as asked:
the demo score looping, spread 0.5, flat OSC of every character to a local UDP socket, realtime
scheduling where allowed; prints the frames, the late ones (sent over 0.1 ms after their
deadline), the p99 lateness and whether it kept time (no frame dropped, p99 under 1 ms)."""

from __future__ import annotations

import argparse

from instrument.cli.crowd_bench import keeps_time
from instrument.models.modelfile import default_model_path, load_model
from instrument.runtime.priority import realtime_scheduling


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--characters", type=int, default=200)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    refused = realtime_scheduling()
    kept, p99, late = keeps_time(load_model(default_model_path()), args.characters, args.seconds)
    print(f"{args.characters} characters for {args.seconds:g} s at 30 fps: {'kept time' if kept else 'did NOT keep time'}; "
          f"p99 lateness {p99:.3f} ms, late frames {late}; scheduling "
          f"{'realtime' if refused is None else 'normal (' + refused + ')'}")


if __name__ == "__main__":
    main()
