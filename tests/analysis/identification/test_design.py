"""Experiment design for identification (``rimd experiment --for-identification``).

The library: rimd_sim.analysis.identification.design.

Hypotheses:

* for the default rig the chosen steps lie in band A, which holds the paper's gap-0 band-A resonance 3.75 Hz
  (Table 1; docs/interface.md), spread across it, each one steady impact per cycle in the experiment's continued run,
  as an independent check of the core's ``sweep`` up the same steps also reads one impact per cycle;
* a rig whose gap the hammer never reaches gets a one-line refusal naming the range searched;
* ``rimd experiment --for-identification`` schedules the design's steps (the verb's ``schedule()``, no rig
  needed) and refuses it together with ``--frequencies``.
"""

from __future__ import annotations

import argparse

import pytest

from rimd_sim.analysis.dynamics.sweep import sweep
from rimd_sim.analysis.identification.design import DesignError, identification_steps
from rimd_sim.settings.config import SimConfig


def test_default_rig_gets_six_steady_band_a_steps_around_the_papers_resonance():
    design = identification_steps(SimConfig(), dwell=10.0, settle=3.0, ramp_rate=2.0)
    lo, hi = design.band
    assert lo <= 3.75 <= hi                                   # Table 1: band A peaks at 3.75 Hz (gap 0)
    assert len(design.frequencies) == 6 and len(set(design.frequencies)) == 6
    assert all(lo <= f <= hi for f in design.frequencies)
    assert max(design.frequencies) - min(design.frequencies) >= 0.5 * (hi - lo)   # spread across the band
    for p in design.predictions:
        assert p.steady and abs(p.impacts_per_cycle - 1.0) <= 0.03, p
    # the core's up-sweep through the same steps (another code path of the same integrator): one impact per cycle
    ordered = sorted(design.frequencies)
    ref = sweep(SimConfig(), ordered, "up", cycles=40, measure_cycles=16, ramp_rate=2.0)
    assert all(abs(p.impacts_per_cycle - 1.0) <= 0.07 for p in ref.points), [p.impacts_per_cycle for p in ref.points]
    # the impact velocities differ from step to step (the pulses' scales separate the mass from the contact)
    v = [p.impact_velocity_m_s for p in design.predictions]
    assert max(v) > 1.3 * min(v)


def test_a_rig_that_never_reaches_its_gap_is_refused_in_one_line():
    with pytest.raises(DesignError) as info:
        identification_steps(SimConfig().with_parameters({"gap": 0.02}), dwell=10.0, settle=3.0)
    message = str(info.value)
    assert "no motor frequency from" in message and "gap 20 mm" in message and "\n" not in message


def _experiment_args(*argv: str) -> argparse.Namespace:
    from rimd_sim.cli.verbs import experiment

    parser = argparse.ArgumentParser()
    experiment.add_arguments(parser)
    return parser.parse_args(list(argv))


def test_experiment_schedules_the_design(capsys):
    from rimd_sim.cli.verbs.experiment import plan

    chosen = plan(_experiment_args("--for-identification", "--dwell", "10", "--settle", "3", "--ramp-rate", "2"))
    design = identification_steps(SimConfig(), dwell=10.0, settle=3.0, ramp_rate=2.0)
    assert list(chosen.frequencies) == design.frequencies
    assert "for identification of the rig of" in capsys.readouterr().err


def test_experiment_refuses_the_design_with_frequencies():
    from rimd_sim.cli.verbs.experiment import plan
    from rimd_sim.errors import RimdError

    with pytest.raises(RimdError, match="--for-identification chooses the frequencies"):
        plan(_experiment_args("--for-identification", "--frequencies", "3.0"))
