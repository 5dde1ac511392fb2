"""Screenshot of the Rerun viewer showing an ``.rrd`` with its blueprint, without a display.

The viewer runs headless (``rerun --headless``: an offscreen harness) and needs a Vulkan adapter; on a machine
without a GPU, Mesa's software rasterizer does it (Debian: ``apt-get install mesa-vulkan-drivers``).
Rerun's usage reporting stays off (the bridge's private Rerun configuration).

Run: python scripts/rerun_screenshot.py REC.rrd OUT.png [--size 1920x1080]   (after `source env.sh`)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def main() -> int:
    """Spawn a headless viewer, open the file, save the screenshot, quit the viewer."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rrd", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--port", type=int, default=19877)
    parser.add_argument("--settle", type=float, default=5.0, help="s to let the viewer load and lay out")
    args = parser.parse_args()

    from rimd_sim.viz.sinks import analytics_off_environment

    os.environ.update(analytics_off_environment())
    os.environ["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
    from rerun.experimental import ViewerClient

    client = ViewerClient.spawn(headless=True, port=args.port, hide_welcome_screen=True, detach_process=False)
    try:
        client.open(str(args.rrd.resolve()))
        time.sleep(args.settle)
        client.save_screenshot(str(args.out.resolve()))
    finally:
        client.quit()
    print(f"{args.out}: screenshot of {args.rrd}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
