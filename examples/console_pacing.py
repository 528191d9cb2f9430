"""Frame pacing of the live loop with and without console pages open (docs/console.md).

Runs `instrument bench --pacing` four times in the same session: without the console; with
the console serving no page; with N pages that only receive (WebSocket clients in another
process: what the instrument's machine pays when the pages run on tablets); and with N pages
in headless chromium on this machine (their drawing competes for the same CPU: the worst case).

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


def read_pages(url: str, pages: int) -> None:
    """N pages that take every frame and draw nothing (run in its own process)."""
    import asyncio

    import aiohttp

    async def page(session):
        async with session.ws_connect(url.replace("http://", "ws://") + "ws") as ws:
            async for _ in ws:
                pass

    async def all_pages():
        async with aiohttp.ClientSession() as session:
            await asyncio.gather(*(page(session) for _ in range(pages)), return_exceptions=True)

    asyncio.run(all_pages())


def bench(seconds: float, fps: float, pages: int | None, browsers: bool = True) -> dict:
    command = [sys.executable, "-m", "instrument", "bench", "--json", "--pacing", str(seconds), "--fps", str(fps)]
    if pages is not None:
        command += ["--console", "0", "--console-pages", str(pages)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    clients, profiles = [], []
    try:
        if pages:
            url = None
            for line in process.stderr:
                if found := re.search(r"console: (http://\S+)", line):
                    url = found.group(1)
                    break
            if browsers:
                chromium = shutil.which("chromium") or "/usr/bin/chromium"
                for _ in range(pages):
                    profile = tempfile.mkdtemp(prefix="console-pacing-")
                    profiles.append(profile)
                    clients.append(subprocess.Popen([chromium, *FLAGS, f"--user-data-dir={profile}", url],
                                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            else:
                clients.append(subprocess.Popen([sys.executable, __file__, "--read", url, "--pages", str(pages)]))
        out, err = process.communicate(timeout=seconds + 600)
    finally:
        for client in clients:
            client.terminate()
            client.wait(30)
        for profile in profiles:
            shutil.rmtree(profile, ignore_errors=True)
    if process.returncode != 0:
        raise SystemExit(f"bench failed: {err}")
    return json.loads(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--fps", type=float, default=60.0)
    parser.add_argument("--pages", type=int, default=5)
    parser.add_argument("--read", metavar="URL", help=argparse.SUPPRESS)  # internal: be the receiving pages
    args = parser.parse_args()
    if args.read:
        read_pages(args.read, args.pages)
        return
    runs = {"no console": bench(args.seconds, args.fps, None), "console, no page": bench(args.seconds, args.fps, 0),
            f"{args.pages} receiving pages": bench(args.seconds, args.fps, args.pages, browsers=False),
            f"{args.pages} chromium pages": bench(args.seconds, args.fps, args.pages)}
    reference = runs["no console"]
    print(f"{'':22s} {'frames':>7s} {'late':>5s} {'dropped':>7s} {'p50 ms':>7s} {'p99 ms':>7s} {'max ms':>7s}  p99 / no console")
    for name, f in runs.items():
        print(f"{name:22s} {f['pacing_frames']:7d} {f['pacing_late_frames']:5d} {f['pacing_dropped_frames']:7d} "
              f"{f['pacing_p50_ms']:7.3f} {f['pacing_p99_ms']:7.3f} {f['pacing_max_ms']:7.3f}  "
              f"x{f['pacing_p99_ms'] / reference['pacing_p99_ms']:.2f}")
    print(json.dumps(runs, indent=1), file=sys.stderr)


if __name__ == "__main__":
    main()
