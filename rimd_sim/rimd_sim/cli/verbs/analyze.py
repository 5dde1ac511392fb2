"""``rimd analyze REC --out DIR``: analyse a recording alone (the library: :mod:`rimd_sim.analysis.recordings.report`).

Writes into DIR the impact tables, the step table (``steps.csv``), the left-out windows, the Poincare points, the
acceleration spectrum, the figures (not with ``--no-plot``) and ``summary.json``. A damaged recording is analysed
as far as it is readable and the loss is reported; a file that is not a recording is refused in one line (exit 1).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rimd_sim.cli import nonnegative_float, positive_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd analyze``."""
    parser.add_argument("recording", type=Path, help="a recording directory or one .mcap file")
    parser.add_argument("--out", type=Path, default=Path("analysis"), help="output directory (default: analysis)")
    parser.add_argument("--settle", type=nonnegative_float("--settle", "s"), default=2.0,
                        help="seconds discarded at the start of each dwell step, after the motor reached its "
                             "setpoint (default 2.0)")
    parser.add_argument("--threshold", type=positive_float("--threshold", "N"), default=2.0,
                        help="force threshold (N) above which a run of force samples is one impact (default 2.0)")
    parser.add_argument("--peak", choices=("onset-fit", "sample"), default="onset-fit",
                        help="peak of each sampled impact: 'onset-fit' fits the spring-dashpot contact pulse "
                             "(when the recording's rig parameters give that law) and reads its peak; 'sample' "
                             "takes the largest sample (the paper's raw reading). Default onset-fit")
    parser.add_argument("--no-plot", action="store_true",
                        help="tables and summary.json only, no figure (an earlier run's figures in --out are "
                             "removed)")


def main(args: argparse.Namespace) -> int:
    """Parse, analyse, print the report."""
    from rimd_sim.analysis.recordings.report import analyze, format_report
    summary = analyze(args.recording, args.out, settle=args.settle, threshold=args.threshold, peak=args.peak,
                      figures=not args.no_plot,
                      log=lambda text: print(f"rimd analyze: {text}", file=sys.stderr, flush=True))
    for line in format_report(summary):
        print(line)
    print(f"results in {args.out}")
    return 0


def __getattr__(name: str):  # noqa: ANN202 - names callers import from this module
    """``analyze`` and ``print_report`` of :mod:`rimd_sim.analysis.recordings.report` (imported on first use)."""
    if name == "analyze":
        from rimd_sim.analysis.recordings.report import analyze

        return analyze
    if name == "print_report":
        from rimd_sim.analysis.recordings.report import format_report

        return lambda summary: print("\n".join(format_report(summary)))
    raise AttributeError(name)
