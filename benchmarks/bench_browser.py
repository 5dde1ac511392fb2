"""Does a real browser keep up with ``make run``'s live Rerun view? A screenshot of the web viewer after a minute.

What it runs: ``rimd rig`` as ``make run`` starts it (the default configuration at real time, the Rerun bridge with
its default sink serve_web and its default display stream), on a ROS domain of its own, recording into a temporary
directory (bench_soak's ``RigRun``). Once the bridge logs its web viewer's URL, headless Chromium (Debian's
``/usr/bin/chromium``, software rendering: no GPU) opens it through Playwright and keeps it open; ``--seconds``
(default 60) after the rig runs from sample 0 it takes a screenshot and, at the same instant, reads the rig's
simulation time (the wall clock less the stamp of the run's start, which the simulator logs: the rig stamps in
wall-clock time at real time) and the wall clock.

Printed: the rig's simulation time and the UTC wall time at the screenshot, and where the PNG is. The viewer keeps
up when the time cursor in the screenshot (the timeline at the bottom) is within 2 s of those: read it off the
picture (the viewer draws on a canvas; its time is not in the page's text).

Needs, besides the project environment: ``apt-get install chromium`` and ``pip install playwright`` (its Python
package only: the browser is Debian's, so ``playwright install`` is not needed). ``--full-rate`` runs the rig with
``--rerun-full-rate`` for comparison.

Run (after ``source env.sh``, from the repository root; the machine otherwise idle):
    python benchmarks/bench_browser.py [--seconds 60] [--full-rate] [--out shot.png]
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_soak import RigRun  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
#: The flags of a headless Chromium on a machine without network access and without a GPU.
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--enable-unsafe-swiftshader"]
VIEWER_URL = re.compile(r"rerun bridge ready: sink serve_web -> (http://\S+?);")
RUN_STAMP = re.compile(r"run \w+ \(start, session 0\) from simulation time ([0-9.]+) s, stamp ([0-9]+)\.([0-9]{9})")


def _wait_for(log: Path, pattern: re.Pattern, timeout: float) -> re.Match:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        match = pattern.search(log.read_text(errors="replace"))
        if match:
            return match
        time.sleep(0.2)
    raise SystemExit(f"bench_browser: '{pattern.pattern}' not in {log} within {timeout:.0f} s:\n"
                     f"{log.read_text(errors='replace')[-3000:]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="s from sample 0 to the screenshot (default 60)")
    parser.add_argument("--full-rate", action="store_true", help="the rig with --rerun-full-rate")
    parser.add_argument("--out", type=Path, default=Path("bench_browser.png"), help="the screenshot (PNG)")
    parser.add_argument("--startup-timeout", type=float, default=180.0)
    args = parser.parse_args()
    if not Path(CHROMIUM).exists():
        raise SystemExit(f"bench_browser: no {CHROMIUM}: apt-get install chromium")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise SystemExit("bench_browser: pip install playwright (its Python package; the browser is Debian's)") \
            from None

    options = ("--rerun-full-rate",) if args.full_rate else ()
    with RigRun.open("bench_browser_", keep=False) as run, sync_playwright() as pw:
        run.start(args.seconds + 120, args.startup_timeout, options)
        log = run.tmp / "rig.log"
        url = _wait_for(log, VIEWER_URL, 60).group(1)
        start = _wait_for(log, RUN_STAMP, 60)
        t0 = float(start.group(1))
        stamp0_ns = int(start.group(2)) * 1_000_000_000 + int(start.group(3))
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=FLAGS)
        page = browser.new_page(viewport={"width": 1600, "height": 900})
        page.goto(url)
        due_ns = stamp0_ns + round(args.seconds * 1e9)
        while (left := (due_ns - time.time_ns()) / 1e9) > 0:
            page.wait_for_timeout(min(left, 1.0) * 1000)
        page.screenshot(path=str(args.out))
        now_ns = time.time_ns()
        sim = t0 + (now_ns - stamp0_ns) / 1e9
        browser.close()
    wall = datetime.fromtimestamp(now_ns / 1e9, UTC).strftime("%H:%M:%S.%f")[:-3]
    stream = "full rate" if args.full_rate else "display stream"
    print(f"bench_browser: {stream}; screenshot {args.out} at the rig's simulation time {sim:.2f} s "
          f"(wall clock {wall} UTC); the viewer keeps up when its time cursor reads within 2 s of it")


if __name__ == "__main__":
    main()
