"""Frame pacing of the live loop with and without browser consoles open (docs/console.md).

Runs `instrument bench --pacing` three times in the same session: without the console, with
the console serving no page, and with the console and N pages open in headless chromium
(separate browser processes on this machine, so the pages' own drawing competes for the CPU:
the worst case; pages on a tablet cost this machine only the sending).

    python examples/console_pacing.py [--seconds 30] [--fps 60] [--pages 5]
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile

FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--window-size=1280,800"]


def bench(seconds: float, fps: float, pages: int | None) -> dict:
    command = [sys.executable, "-m", "instrument", "bench", "--json", "--pacing", str(seconds), "--fps", str(fps)]
    if pages is not None:
        command += ["--console", "0", "--console-pages", str(pages)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    browsers = []
    try:
        if pages:
            url = None
            for line in process.stderr:
                if found := re.search(r"console: (http://\S+)", line):
                    url = found.group(1)
                    break
            chromium = shutil.which("chromium") or "/usr/bin/chromium"
            for _ in range(pages):
                profile = tempfile.mkdtemp(prefix="console-pacing-")
                browsers.append(subprocess.Popen([chromium, *FLAGS, f"--user-data-dir={profile}", url],
                                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        out, err = process.communicate(timeout=seconds + 600)
    finally:
        for browser in browsers:
            browser.terminate()
            browser.wait(30)
    if process.returncode != 0:
        raise SystemExit(f"bench failed: {err}")
    return json.loads(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--fps", type=float, default=60.0)
    parser.add_argument("--pages", type=int, default=5)
    args = parser.parse_args()
    runs = {"no console": bench(args.seconds, args.fps, None), "console, no page": bench(args.seconds, args.fps, 0),
            f"console, {args.pages} pages": bench(args.seconds, args.fps, args.pages)}
    reference = runs["no console"]
    print(f"{'':20s} {'frames':>7s} {'late':>5s} {'dropped':>7s} {'p50 ms':>7s} {'p99 ms':>7s} {'max ms':>7s}  p99 / no console")
    for name, f in runs.items():
        print(f"{name:20s} {f['pacing_frames']:7d} {f['pacing_late_frames']:5d} {f['pacing_dropped_frames']:7d} "
              f"{f['pacing_p50_ms']:7.3f} {f['pacing_p99_ms']:7.3f} {f['pacing_max_ms']:7.3f}  "
              f"x{f['pacing_p99_ms'] / reference['pacing_p99_ms']:.2f}")
    print(json.dumps(runs, indent=1), file=sys.stderr)


if __name__ == "__main__":
    main()
