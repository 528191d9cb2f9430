"""`instrument bench`: the speed figures the project promises, measured on this machine."""

from __future__ import annotations

import argparse
import json

from .arguments import check_needs, checked


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="measure parsing and synthesis speed on this machine")
    p.add_argument("--model", help="model file (default: the shipped default model)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--repeat", type=checked("bench --repeat"), default=15, help="timed repetitions per figure (the median is reported)")
    p.add_argument("--pacing", type=checked("bench --pacing"), metavar="SECONDS",
                   help="instead: run the live loop this long (demo, both OSC profiles to 127.0.0.1) and measure "
                        "how far each frame's send time is from its deadline")
    p.add_argument("--fps", type=checked("bench --fps"), default=60.0, help="frame rate for --pacing (default 60)")
    p.add_argument("--console", metavar="[HOST:]PORT", help="for --pacing: serve the browser console meanwhile")
    p.add_argument("--console-pages", type=checked("bench --console-pages"), metavar="N",
                   help="for --pacing with --console: wait until N pages are open before measuring")
    p.add_argument("--crowd", action="store_true",
                   help="instead: only the live crowd's figures (each stage's cost per character, the largest crowd "
                        "keeping 30 fps)")
    p.add_argument("--startup", action="store_true",
                   help="instead: how long `instrument --version`, `--help` and each `COMMAND --help` take to start, "
                        "against `python -c pass` in the same run")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    check_needs("bench", args)
    if args.startup:
        from .startup import measure_startup

        figures = measure_startup(max(1, args.repeat))
        if args.json:
            print(json.dumps(figures, indent=1))
        for line, f in figures.items() if not args.json else ():
            print(f"{line:32s} {f['seconds']:6.2f} s  (python -c pass {f['bare_seconds']:.2f} s: x{f['ratio']:.1f})")
        return 0
    # what is measured (numpy, scipy, numba): loaded when run, not for --help nor --startup
    from .benchmarks import BATCH, measure, measure_crowd, measure_pacing

    if args.pacing:
        f = measure_pacing(args.model, args.pacing, args.fps, args.console, args.console_pages or 0)
        if args.json:
            print(json.dumps(f, indent=1))
        else:
            with_console = f", the console with {f['pacing_console_pages']} pages" if args.console else ""
            print(f"live loop at {f['pacing_fps']:g} fps for {f['pacing_seconds']:g} s ({f['pacing_frames']} frames, "
                  f"2 OSC outputs{with_console}, {f['pacing_scheduling']} scheduling):")
            print(f"send time minus deadline: p50 {f['pacing_p50_ms']:.3f} ms, p99 {f['pacing_p99_ms']:.3f} ms, "
                  f"max {f['pacing_max_ms']:.3f} ms; late frames {f['pacing_late_frames']}, dropped {f['pacing_dropped_frames']}")
        return 0
    if args.crowd:
        f = measure_crowd(args.model)
        if args.json:
            print(json.dumps(f, indent=1))
        else:
            m = f["machine"]
            load = f", load {m['load_1min']:.1f}" if m["load_1min"] is not None else ""
            print(f"machine: {m['cores']} cores, {m['cpu']}{load}")
            _print_crowd(f)
        return 0
    f = measure(args.model, max(1, args.repeat))
    if args.json:
        print(json.dumps(f, indent=1))
        return 0
    print(f"BVH parse, 500 frames x 22 joints:      {f['bvh_parse_ms_500x22']:8.1f} ms")
    print(f"feature extraction, same file:          {f['features_ms_500x22']:8.1f} ms")
    m = f["machine"]
    load = f", load {m['load_1min']:.1f}" if m["load_1min"] is not None else ""
    print(f"machine: {m['cores']} cores, {m['cpu']}{load} (1-minute average at the MLPG figures)")
    print(f"full MLPG, {f['mlpg_frames']} frames x {f['dimension']} dims:  {f['mlpg_frames_per_s']:8.0f} frames/s "
          f"on {f['mlpg_threads']} thread{'s' if f['mlpg_threads'] > 1 else ''} ({f['mlpg_one_thread_frames_per_s']:.0f} on one)")
    if f["nnmnkwii_frames_per_s"]:
        print(f"nnmnkwii MLPG, same input, turn about:  {f['nnmnkwii_frames_per_s']:8.0f} frames/s "
              f"(ours x{f['mlpg_speedup_over_nnmnkwii']:.2f}, on one thread x{f['mlpg_one_thread_speedup_over_nnmnkwii']:.2f}; "
              "medians of per-turn ratios)")
    else:
        print("nnmnkwii MLPG:                          not installed (pip install nnmnkwii)")
    print(f"one window's bare solve ({2 + f['lookahead'] + 1} frames):    {f['window_solve_us']:8.1f} us (the yardstick below: "
          f"each ratio the median of {f['yardstick_turns']} turns timing the figure and the solve)")
    print(f"streaming, one character:               {f['stream_us_per_frame']:8.1f} us/frame "
          f"(x{f['stream_to_window_solve']:.2f} the window solve; look-ahead {f['lookahead']})")
    if f["widen_us_per_frame"] is not None:
        print(f"widen filter, one character:            {f['widen_us_per_frame']:8.1f} us/frame "
              f"(x{f['widen_to_window_solve']:.2f} the window solve)")
    if f["pose_us_per_frame"] is not None:
        print(f"pose with planted feet, one character:  {f['pose_us_per_frame']:8.1f} us/frame "
              f"(x{f['pose_to_window_solve']:.2f} the window solve; planting the feet {f['contact_us_per_frame']:.1f} us of it)")
        print(f"pose, per character in a crowd of {BATCH}:  {f['pose_us_per_character_batch']:8.1f} us/frame "
              f"(x{f['pose_batch_to_window_solve']:.2f} the window solve)")
    if f["gesture_stream_us_per_frame"] is not None:
        print(f"streaming, one character, a {f['gesture_name']} playing: {f['gesture_stream_us_per_frame']:6.1f} us/frame "
              f"(x{f['gesture_stream_to_window_solve']:.2f} the window solve; the gesture stage alone "
              f"x{f['gesture_stage_to_window_solve']:.2f})")
        print(f"engine frame before posing, one character: {f['engine_us_per_frame']:5.1f} us "
              f"(x{f['engine_to_window_solve']:.2f} the window solve), a {f['gesture_name']} playing "
              f"{f['gesture_engine_us_per_frame']:.1f} us (x{f['gesture_engine_to_window_solve']:.2f})")
    print(f"streaming, per character in a crowd of {BATCH}: {f['stream_us_per_frame_batch']:6.1f} us/frame "
          f"(x{f['stream_batch_to_window_solve']:.2f} the window solve)")
    print(f"characters in realtime on one core:     {f['characters_at_30fps']} at 30 fps, {f['characters_at_60fps']} at 60 fps")
    _print_crowd(f)
    return 0


def _print_crowd(f: dict) -> None:
    from .crowd_bench import LATENESS_P99_MS, STAGES

    print(f"live crowd of {f['crowd_size_for_cost']}, per character:     {f['stream_us_per_character']:8.1f} us/frame "
          f"(x{f['stream_per_character_to_window_solve']:.2f} the window solve: engine {f['crowd_engine_us_per_character']:.1f}, "
          f"pose {f['crowd_pose_us_per_character']:.1f}, finite check {f['crowd_finite_us_per_character']:.1f}, "
          f"flat OSC {f['crowd_flat_us_per_character']:.1f})")
    print("  its stages, per character (x the window solve): " + ", ".join(
        f"{stage} {f[f'crowd_{stage}_us_per_character']:.1f} (x{f[f'crowd_{stage}_to_window_solve']:.2f})" for stage in STAGES))
    print(f"largest live crowd at 30 fps:           {f['largest_crowd_30fps']:8d} characters (p99 lateness under "
          f"{LATENESS_P99_MS:g} ms, flat OSC to 127.0.0.1, {f['largest_crowd_scheduling']} scheduling; "
          f"tried {f['largest_crowd_tried']} in {f['largest_crowd_search_s']:.0f} s)")
