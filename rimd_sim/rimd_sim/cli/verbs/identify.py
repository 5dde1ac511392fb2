"""``rimd identify REC --out DIR``: make the twin the recorded rig.

The library: :mod:`rimd_sim.analysis.identification.identify`.

Writes into DIR: ``identified.yaml`` (the base parameter file with the identified values replaced, runnable by
``rimd rig --config`` and ``--params-file``), ``identification.json`` (estimates, standard errors, 95 %
intervals, sources, the verdict, the windows left out, residuals), ``validation.csv`` and ``validation.png``
(the recording against the twin re-run under the recorded schedule, read as ``rimd analyze`` reads it).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rimd_sim.cli import nonnegative_float, positive_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd identify``."""
    parser.add_argument("recording", type=Path, help="a recording directory or one .mcap file")
    parser.add_argument("--out", type=Path, default=Path("identification"),
                        help="output directory (default: identification)")
    parser.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                        help="hold a parameter at a value instead of identifying it (repeatable), "
                             "e.g. --fix mass=0.15")
    parser.add_argument("--config", type=Path, default=None,
                        help="base parameter file: the values not identified, and the file identified.yaml "
                             "is written from (default config/rimd.yaml)")
    parser.add_argument("--threshold", type=positive_float("--threshold", "N"), default=2.0,
                        help="force (N) above which a run of force samples is an impact (default 2.0)")
    parser.add_argument("--settle", type=nonnegative_float("--settle", "s"), default=2.0,
                        help="seconds discarded after the motor reached each setpoint, for the validation's "
                             "steady windows (default 2.0, as rimd analyze)")


def main(args: argparse.Namespace) -> int:
    """Parse, identify, write the files, print the estimates, the verdict and the validation."""
    from rimd_sim.cli.verbs._analysis_io import VerbClock, check_positive

    clock = VerbClock()
    from rimd_sim.analysis.identification.identify import identify
    from rimd_sim.analysis.identification.report import format_identification, parse_fix, write_outputs
    from rimd_sim.settings.config import find_config_file, load_config

    check_positive("--threshold", args.threshold)
    check_positive("--settle", args.settle, inclusive=True)
    fixed = parse_fix(args.fix)
    base_path = args.config or find_config_file()
    base = load_config(base_path, fixed)
    start = time.perf_counter()
    result = identify(args.recording, base, fixed, threshold=args.threshold, settle=args.settle,
                      log=lambda text: print(f"rimd identify: {text}", file=sys.stderr, flush=True))
    identified = time.perf_counter() - start
    clock.writing()
    write_outputs(result, base_path, args.out, args.recording, identified)
    for line in format_identification(result, base):
        print(line)
    print(clock.times(f"identified in {identified:.1f} s") + f"; results in {args.out}")
    return 0
