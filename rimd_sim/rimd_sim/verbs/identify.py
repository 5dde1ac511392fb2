"""``rimd identify REC --out DIR``: make the twin the recorded rig (see :mod:`rimd_sim.analysis.identify`).

Writes into DIR: ``identified.yaml`` (the base parameter file with the identified values replaced: every value
of the ``rimd_simulator`` section written out, the other nodes' sections kept, runnable by ``rimd rig --config``
and ``--params-file``), ``identification.json`` (estimates, standard errors, sources, residuals, what was held
fixed), ``validation.csv`` and ``validation.png`` (the recording against the twin re-simulated with the
identified parameters under the recorded motor schedule).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rimd_sim.cli import positive_float


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


def parse_fix(items: list[str]) -> dict[str, float]:
    """``NAME=VALUE`` strings to a dict; refuses unknown names and non-numbers in one line."""
    from rimd_sim.analysis.identify import IDENTIFIABLE
    from rimd_sim.cli import CommandError

    fixed: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep:
            raise CommandError(f"--fix {item!r} refused: must be NAME=VALUE")
        if name not in IDENTIFIABLE:
            raise CommandError(f"--fix {item!r} refused: NAME must be one of {', '.join(IDENTIFIABLE)}")
        try:
            fixed[name] = float(value)
        except ValueError:
            raise CommandError(f"--fix {item!r} refused: VALUE must be a number") from None
    return fixed


def main(args: argparse.Namespace) -> int:
    """Identify, write the files, print the estimates."""
    from rimd_sim.analysis.identify import IdentificationError, identify
    from rimd_sim.cli import CommandError
    from rimd_sim.core.config import find_config_file, load_config
    from rimd_sim.core.errors import ConfigError
    from rimd_sim.recording.reader import RecordingError
    from rimd_sim.verbs._analysis_io import check_positive

    check_positive("--threshold", args.threshold)
    fixed = parse_fix(args.fix)
    base_path = args.config or find_config_file()
    try:
        base = load_config(base_path, fixed)
    except ConfigError as exc:
        raise CommandError(str(exc)) from None
    start = time.perf_counter()
    try:
        result = identify(args.recording, base, fixed, threshold=args.threshold, log=_log)
    except (IdentificationError, RecordingError) as exc:
        raise CommandError(str(exc)) from None
    from rimd_sim.analysis.recorded import loss_text

    text = loss_text(result.data["recording_loss"])
    if text:
        print(f"LOSS: identified from the valid part: {text}")
    write_outputs(result, base_path, args.out, args.recording, time.perf_counter() - start)
    print(f"{'parameter':<18} {'identified':>14} {'std error':>11}  base")
    for name, est in result.estimates.items():
        print(f"{name:<18} {est.value:>14.6g} {est.std_error or 0.0:>11.3g}  {base_value(base, name):.6g}")
    for name, value in result.fixed.items():
        print(f"{name:<18} {value:>14.6g} {'fixed':>11}")
    for row in result.validation:
        diff = row["peak_force_difference"]
        print(f"step {row['step']} {row['frequency_hz']:g} Hz: steady peak recorded "
              f"{row['peak_force_recorded_n']:.2f} N, "
              f"twin {row['peak_force_twin_n']:.2f} N" + (f" ({diff * 100:+.2f} %)" if diff is not None else ""))
    print(f"results in {args.out} ({time.perf_counter() - start:.1f} s)")
    return 0


def base_value(config, name: str) -> float:  # noqa: ANN001
    """The value of ``name`` in ``config``."""
    return float(config.to_parameters()[name])


def _log(text: str) -> None:
    print(f"rimd identify: {text}", file=sys.stderr, flush=True)


def nest(flat: dict) -> dict:
    """Dotted parameter names to nested mappings."""
    tree: dict = {}
    for key, value in flat.items():
        node = tree
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return tree


def write_outputs(result, base_path: Path, out: Path, recording: Path, seconds: float) -> None:  # noqa: ANN001
    """identified.yaml, identification.json, validation.csv and validation.png."""
    from rimd_sim.analysis import identify_plots
    from rimd_sim.verbs._analysis_io import write_csv, write_json

    out.mkdir(parents=True, exist_ok=True)
    write_parameter_file(out / "identified.yaml", base_path, result.config,
                         f"# Identified by `rimd identify {recording}` from that recording; base file {base_path}.\n"
                         "# Every value of the simulator is written out; identified: " + ", ".join(result.estimates)
                         + ("; fixed: " + ", ".join(result.fixed) if result.fixed else "")
                         + ".\n# Details: identification.json next to this file.\n")
    report = {
        "recording": str(recording),
        "base_config": str(base_path),
        "estimates": {k: v.as_dict() for k, v in result.estimates.items()},
        "fixed": result.fixed,
        "kicks": [{"time_s": t, "velocity_m_s": v} for t, v in result.kicks],
        "initial_state": {"theta_rad": result.initial[0], "theta_dot_rad_s": result.initial[1],
                          "at_s": result.schedule.t0},
        "residuals": result.residuals,
        "data": result.data,
        "validation": result.validation,
        "determined_by": DETERMINED_BY,
        "log": result.log,
        "wall_seconds": seconds,
    }
    write_json(out / "identification.json", report)
    write_csv(out / "validation.csv", result.validation)
    identify_plots.plot_validation(result, out / "validation.png", f"identification of {recording.name}")


#: What determines what (written into identification.json; docs/identification.md says the same).
DETERMINED_BY = {
    "amplitude": "cart laser against the motor phase",
    "natural_frequency": "free flight of the hammer relative to the cart (base-excitation response, free decay)",
    "damping_ratio": "free flight of the hammer relative to the cart (decay, response amplitude and phase)",
    "gap": "relative displacement at the contact onsets",
    "mass": "pulse scale m v0 (force channel) over the impact velocity v0 (laser); equivalently impulse = m dv",
    "contact.stiffness": "pulse duration ~ pi sqrt(m/k) and shape (k/m), times the mass",
    "contact.damping": "pulse decay and the force jump c v0 at the onset (c/m), times the mass",
}


def write_parameter_file(path: Path, base_path: Path, config, header: str) -> None:  # noqa: ANN001
    """The base file with the simulator's section replaced by every value of ``config``.

    The section is written as ``/**/rimd_simulator``: the node runs in namespace ``/rig`` and ROS applies a
    section only to the fully qualified name or a wildcard (a plain ``rimd_simulator:`` key means
    ``/rimd_simulator``, which the node is not); the core reads the same section.
    """
    import yaml

    from rimd_sim.core.config import NODE_NAME

    doc = yaml.safe_load(Path(base_path).read_text()) or {}
    for section in (NODE_NAME, "/" + NODE_NAME, "/**/" + NODE_NAME):
        doc.pop(section, None)
    wildcard = doc.pop("/**", None)   # its simulator values are in the new section; other nodes keep it
    if wildcard is not None:
        doc["/**"] = wildcard
    doc["/**/" + NODE_NAME] = {"ros__parameters": nest(config.to_parameters())}
    path.write_text(header + yaml.safe_dump(doc, sort_keys=False))


