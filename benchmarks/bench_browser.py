"""Does a real browser keep up with ``make run``'s live Rerun view? A screenshot of the web viewer after a minute.

What it runs: ``rimd rig`` as ``make run`` starts it (the default configuration at real time, the Rerun bridge with
its default sink serve_web and its default display stream), on a ROS domain of its own, recording into a temporary
directory (bench_soak's ``RigRun``). Once the bridge logs its web viewer's URL, headless Chromium (Debian's
``/usr/bin/chromium``, software rendering: no GPU) opens it through Playwright and keeps it open; from ``--seconds``
(default 60) after the rig runs from sample 0, the first frame the page paints is taken from the DevTools screencast
with the wall-clock time it was painted, hence the rig's simulation time then (the wall clock less the stamp of the
run's start, which the simulator logs: the rig stamps in wall-clock time at real time).

The viewer's time cursor (the box at the right end of the timeline, e.g. ``+64.767 500s``) is read off that frame
with tesseract. The lag is the rig's simulation time when the frame was painted less the cursor it shows: what a
user looking at the screen sees. Recorded: the lag, target at most 2 s.
Without tesseract, or when the box cannot be read, it prints where the PNG is and records nothing.

Needs, besides the project environment: ``apt-get install chromium tesseract-ocr`` and ``pip install playwright``
(its Python package only: the browser is Debian's, so ``playwright install`` is not needed). ``--full-rate`` runs
the rig with ``--rerun-full-rate`` for comparison (printed, not recorded).

Run (after ``source env.sh``, from the repository root; the machine otherwise idle):
    python benchmarks/bench_browser.py [--seconds 60] [--full-rate] [--out shot.png]
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _figures import record  # noqa: E402
from bench_soak import RigRun  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
#: The flags of a headless Chromium on a machine without network access and without a GPU.
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--enable-unsafe-swiftshader"]
VIEWER_URL = re.compile(r"rerun bridge ready: sink serve_web -> (http://\S+?);")
#: The time cursor's box: ``+64.767 500s`` (digits grouped by three after the point).
CURSOR = re.compile(r"\+?\s*(\d+)\s*[.,]\s*([\d ]+?)\s*s")
#: Where the box is in a 1600 x 900 screenshot (left, top, right, bottom): the timeline's right end.
CURSOR_BOX = (1412, 872, 1598, 898)
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


def read_cursor(png: Path) -> float | None:
    """The time cursor (s) of a screenshot of the viewer, read by tesseract; None when it cannot be read."""
    if shutil.which("tesseract") is None:
        return None
    from PIL import Image

    box = Image.open(png).convert("L").crop(CURSOR_BOX)
    box = box.resize((box.width * 4, box.height * 4), Image.LANCZOS)   # tesseract reads 30-pixel glyphs best
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cursor.png"
        box.save(path)
        text = subprocess.run(["tesseract", str(path), "-", "--psm", "7"], capture_output=True, text=True,
                              timeout=60).stdout
    match = CURSOR.search(text)
    return None if match is None else float(f"{match.group(1)}.{match.group(2).replace(' ', '')}")


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
        frame = _frame_after(page, due_ns)
        browser.close()
    if frame is None:
        raise SystemExit("bench_browser: the page painted no frame within 60 s of the due time")
    shown_ns, png = frame
    args.out.write_bytes(png)
    sim = t0 + (shown_ns - stamp0_ns) / 1e9
    wall = datetime.fromtimestamp(shown_ns / 1e9, UTC).strftime("%H:%M:%S.%f")[:-3]
    stream = "full rate" if args.full_rate else "display stream"
    print(f"bench_browser: {stream}; {args.out}: the first frame painted from {args.seconds:g} s on, at the rig's "
          f"simulation time {sim:.2f} s (wall clock {wall} UTC)")
    cursor = read_cursor(args.out)
    if cursor is None:
        print("bench_browser: the time cursor could not be read (tesseract-ocr missing?): read it off the PNG; "
              "the viewer keeps up when it is within 2 s of that time")
        return
    print(f"bench_browser: the viewer's time cursor reads {cursor:.3f} s: {sim - cursor:.2f} s behind the rig")
    if not args.full_rate:
        record("rerun", "web viewer's lag 60 s into `make run`", sim - cursor, "s", "<= 2")


def _frame_after(page, due_ns: int, timeout: float = 60.0) -> tuple[int, bytes] | None:
    """The first frame the page paints at or after ``due_ns`` (wall clock, ns): its paint time and PNG.

    Through the DevTools screencast (``Page.startScreencast``), whose frames carry the time they were painted:
    a screenshot would instead paint a frame of its own, which in a software-rasterised page takes seconds, so
    that the time it shows could not be placed to better than those seconds.
    """
    import base64

    frames: list[tuple[int, bytes]] = []
    cdp = page.context.new_cdp_session(page)

    def on_frame(event: dict) -> None:
        cdp.send("Page.screencastFrameAck", {"sessionId": event["sessionId"]})
        painted = round(float(event["metadata"]["timestamp"]) * 1e9)
        if painted >= due_ns and not frames:
            frames.append((painted, base64.b64decode(event["data"])))

    cdp.on("Page.screencastFrame", on_frame)
    while (left := (due_ns - time.time_ns()) / 1e9) > 2.0:
        page.wait_for_timeout(min(left - 2.0, 1.0) * 1000)
    cdp.send("Page.startScreencast", {"format": "png", "everyNthFrame": 1})
    deadline = time.monotonic() + (due_ns - time.time_ns()) / 1e9 + timeout
    while not frames and time.monotonic() < deadline:
        page.wait_for_timeout(100)
    cdp.send("Page.stopScreencast")
    return frames[0] if frames else None


if __name__ == "__main__":
    main()
