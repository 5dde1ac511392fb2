"""``rimd pulse``: one impact at a given velocity, force and acceleration at 1 MHz (docs/physics.md).

Writes ``DIR/pulse.png`` (force and acceleration over time), ``DIR/pulse.csv`` (the samples) and
``DIR/summary.json`` (``peak_force_n``, ``second_peak_force_n``, ``duration_s``, ``ring_frequency_hz`` and
more). With ``config/structural.yaml`` the pulse shows the structural model's double peak and ringing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rimd_sim.cli import number
from rimd_sim.cli.verbs._analysis_io import add_accept_invalid_argument, add_config_arguments, read_config


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``rimd pulse``."""
    add_config_arguments(parser)
    parser.add_argument("--velocity", type=number("--velocity", "m/s", gt=0, le=10), required=True,
                        help="impact velocity (m/s, > 0, <= 10); the structural preset's at 3.75 Hz, gap 0: 0.066")
    parser.add_argument("--rate", type=number("--rate", "Hz", ge=1e3, le=1e6), default=1e6,
                        help="sample rate (Hz), default 1e6 (1 MHz)")
    parser.add_argument("--out", type=Path, default=Path("out/pulse"), help="output directory")
    add_accept_invalid_argument(parser)


def main(args: argparse.Namespace) -> int:
    """Simulate the pulse and write its files."""
    import numpy as np

    from rimd_sim.analysis.dynamics.pulse import plot_pulse, pulse
    from rimd_sim.cli.verbs._analysis_io import validity_exit, write_summary
    from rimd_sim.model.validity import Verdict, domain

    config = read_config(args)
    result = pulse(config, args.velocity, rate=args.rate)
    args.out.mkdir(parents=True, exist_ok=True)
    np.savetxt(args.out / "pulse.csv", np.column_stack([result.t, result.force, result.acceleration]),
               delimiter=",", header="t_from_contact_s,impact_force_n,rimd_acceleration_m_s2", comments="",
               fmt="%.9g")
    write_summary(args.out, result.summary)
    plot_pulse(result, args.out / "pulse.png")
    s = result.summary
    print(f"peak {s['peak_force_n']:.2f} N, second peak {s['second_peak_force_n']:.2f} N, duration "
          f"{s['duration_s'] * 1e3:.3f} ms, ringing {s['ring_frequency_hz']:.0f} Hz; files in {args.out}",
          file=sys.stdout)
    sentence = domain(config).sentence([Verdict.of(s["invalid_rule"])], "pulses")
    return validity_exit("pulse", sentence, args.accept_invalid, f"invalid_rule in {args.out / 'summary.json'}")
