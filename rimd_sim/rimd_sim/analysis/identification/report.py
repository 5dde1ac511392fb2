"""What ``rimd identify`` writes and prints, from an identification.

The files of an :class:`~rimd_sim.analysis.identification.identify.Identification`: ``identified.yaml`` (the
base parameter file with the identified values), ``identification.json``, ``validation.csv``,
``validation.png``, and the report's lines.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from rimd_sim.analysis.outputs import write_csv, write_json, write_parameter_file

if TYPE_CHECKING:   # the identification is imported when it runs
    from rimd_sim.analysis.identification.identify import Identification
    from rimd_sim.settings.config import SimConfig

__all__ = ["DETERMINED_BY", "format_identification", "parse_fix", "write_outputs"]

#: What determines what (written into identification.json; docs/identification.md says the same).
DETERMINED_BY = {
    "amplitude": "cart laser against the motor phase",
    "natural_frequency": "free flight of the hammer relative to the cart (base-excitation response, free decay)",
    "damping_ratio": "free flight of the hammer relative to the cart (decay, response amplitude and phase)",
    "gap": "relative displacement at the contact onsets; the onset times in the joint fit",
    "mass": "pulse scale m v0 / cos(theta) (force channel) over the impact velocity v0 (lasers, joint fit)",
    "contact.stiffness": "pulse shape w0^2 = k cos(theta) / m (all impacts or the 1 MHz captures), times the mass",
    "contact.damping": "pulse shape sigma = c cos(theta) / 2m + zeta w_n (the force's jump c v0 and decay), "
                       "times the mass",
}


def parse_fix(items: list[str]) -> dict[str, float]:
    """``NAME=VALUE`` strings to a dict.

    Raises:
        InputError: One line naming the item as typed and the rule.
    """
    from rimd_sim.analysis.identification.identify import IDENTIFIABLE
    from rimd_sim.errors import InputError

    fixed: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep:
            raise InputError(f"--fix {item!r} refused: must be NAME=VALUE")
        if name not in IDENTIFIABLE:
            raise InputError(f"--fix {item!r} refused: NAME must be one of {', '.join(IDENTIFIABLE)}")
        try:
            fixed[name] = float(value)
        except ValueError:
            raise InputError(f"--fix {item!r} refused: VALUE must be a number") from None
    return fixed


def write_outputs(result: Identification, base_path: Path, out: Path, recording: Path, seconds: float) -> None:
    """identified.yaml, identification.json, validation.csv and validation.png.

    Raises:
        rimd_sim.analysis.outputs.FileFormatError: The base file is not a YAML mapping.
    """
    from rimd_sim.analysis.identification import plots as identify_plots

    out.mkdir(parents=True, exist_ok=True)
    write_parameter_file(out / "identified.yaml", base_path, result.config,
                         f"# Identified by `rimd identify {recording}` from that recording; base file {base_path}.\n"
                         "# Every value of the simulator is written out; identified: " + ", ".join(result.estimates)
                         + ("; fixed: " + ", ".join(result.fixed) if result.fixed else "")
                         + f".\n# {result.verdict.line()}\n# Details: identification.json next to this file.\n")
    report = {
        "recording": str(recording),
        "base_config": str(base_path),
        "estimates": {k: v.as_dict() for k, v in result.estimates.items()},
        "fixed": result.fixed,
        "verdict": result.verdict.as_dict(),
        "left_out": [w.as_dict() for w in result.windows],
        "kicks": [{"time_s": t, "velocity_m_s": v} for t, v in result.kicks],
        "initial_state": {"theta_rad": result.initial[0], "theta_dot_rad_s": result.initial[1]},
        "residuals": result.residuals,
        "data": result.data,
        "validation": result.validation,
        "determined_by": DETERMINED_BY,
        "log": result.log,
        "wall_seconds": seconds,
    }
    write_json(out / "identification.json", report)
    write_csv(out / "validation.csv", result.validation)
    identify_plots.plot_validation(result, out / "validation.png", f"identification of {Path(recording).name}")


def format_identification(result: Identification, base: SimConfig) -> list[str]:
    """The lines ``rimd identify`` prints: loss, windows left out, estimates with 95 % intervals, verdict, steps."""
    from rimd_sim.analysis.recordings.recorded import loss_text

    lines = []
    text = loss_text(result.data["recording_loss"])
    if text:
        lines.append(f"LOSS: identified from the valid part: {text}")
    if result.windows:
        lines.append(f"LEFT OUT ({len(result.windows)} windows): " + "; ".join(w.describe() for w in result.windows))
    lines.append(f"{'parameter':<18} {'identified':>14} {'+- (95 %)':>11}  base")
    base_values = base.to_parameters()
    for name, est in result.estimates.items():
        hw = est.half_width_95
        lines.append(f"{name:<18} {est.value:>14.6g} {'-' if hw is None else format(hw, '11.3g'):>11}  "
                     f"{float(base_values[name]):.6g}")
    for name, value in result.fixed.items():
        lines.append(f"{name:<18} {value:>14.6g} {'fixed':>11}")
    lines.append(result.verdict.line())
    for row in result.validation:
        diff = row["peak_force_difference"]
        of = row["peak_force_difference_of"]
        rec_ipc, twin_ipc = row["impacts_per_cycle_recorded"], row["impacts_per_cycle_twin"]
        rec_peak, twin_peak = ((row["peak_force_events_recorded_n"], row["peak_force_events_twin_n"]) if of == "events"
                               else (row["peak_force_recorded_n"], row["peak_force_twin_n"]))
        lines.append(f"step {row['step']} {row['frequency_hz']:g} Hz: steady peak ({of}) recorded "
                     f"{rec_peak or 0.0:.2f} N, twin {twin_peak or 0.0:.2f} N"
                     + (f" ({diff * 100:+.2f} %)" if diff is not None else "")
                     + (f"; impacts/cycle {rec_ipc:.3f} recorded, {twin_ipc:.3f} twin"
                        if rec_ipc is not None and twin_ipc is not None else ""))
    return lines
