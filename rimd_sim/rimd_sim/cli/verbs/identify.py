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
    from rimd_sim.analysis.identification.identify import IdentificationError, identify
    from rimd_sim.analysis.identification.report import format_identification, parse_fix, write_outputs
    from rimd_sim.analysis.outputs import FileFormatError
    from rimd_sim.cli import CommandError
    from rimd_sim.cli.verbs._analysis_io import check_positive
    from rimd_sim.errors import ConfigError
    from rimd_sim.io.reader import RecordingError
    from rimd_sim.settings.config import find_config_file, load_config

    check_positive("--threshold", args.threshold)
    check_positive("--settle", args.settle, inclusive=True)
    try:
        fixed = parse_fix(args.fix)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    base_path = args.config or find_config_file()
    try:
        base = load_config(base_path, fixed)
    except ConfigError as exc:
        raise CommandError(str(exc)) from None
    start = time.perf_counter()
    try:
        result = identify(args.recording, base, fixed, threshold=args.threshold, settle=args.settle,
                          log=lambda text: print(f"rimd identify: {text}", file=sys.stderr, flush=True))
        write_outputs(result, base_path, args.out, args.recording, time.perf_counter() - start)
    except (IdentificationError, RecordingError, FileFormatError) as exc:
        raise CommandError(str(exc)) from None
    for line in format_identification(result, base):
        print(line)
    print(f"results in {args.out} ({time.perf_counter() - start:.1f} s)")
    return 0
