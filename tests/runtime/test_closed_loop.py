"""The reference controller's algorithm (rimd_sim.ros.examples.resonance_seeker.PerturbObserve) and the offline
closed loop it runs in (rimd_sim.runtime.closed_loop): in process, no ROS.

Hypotheses:

* perturb and observe climbs a peaked curve with its first step, turns back with half the step each time a step
  made the peak force lower, counts only the impacts after a command's ramp and settling time, and converges
  on the best frequency it measured once the step is below ``min_step_hz``; it refuses settings it cannot run;
* against the rig's core in lockstep (offline, as the rig runs it: each setpoint applied at the end of the block
  it was decided on), started at 3.0 Hz, it converges within 0.05 Hz of the resonance a 0.01 Hz rest sweep finds
  (the frequency of band A's largest steady peak force from rest), at gap 0 and at gap 1.0 mm; the running rig
  gives the same commands bit for bit (tests/ros/test_controller_example.py);
* a command stamped at a time already simulated is late, as on the rig: applied at the end of its block.
"""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

from harness.resonance import rest_resonance
from rimd_sim.ros.examples.resonance_seeker import PerturbObserve, seek_offline
from rimd_sim.runtime.closed_loop import Command, run_closed_loop
from rimd_sim.settings.config import load_config


def feed(seeker: PerturbObserve, force, period: float = 0.25, until: float = 200.0) -> list[tuple[float, float]]:
    """Impacts every ``period`` s whose peak is ``force(setpoint in force)``; the (time, setpoint) commands."""
    commands = [(0.0, seeker.begin(0.0))]
    t = 0.0
    while not seeker.converged and t < until:
        t += period
        target = seeker.impact(t, force(seeker.frequency_hz))
        if target is not None:
            commands.append((t, target))
    return commands


def test_it_climbs_turns_back_with_half_the_step_and_converges_on_the_best_point():
    seeker = PerturbObserve(start_hz=3.0, step_hz=0.2, min_step_hz=0.01, settle_s=1.0, measure=3, ramp_hz_s=2.0)
    commands = feed(seeker, lambda f: 80.0 - 30.0 * (f - 3.67) ** 2)
    assert seeker.converged and abs(seeker.result_hz - 3.67) < 0.01
    steps = [round(f, 4) for _, f in commands]
    assert steps[:8] == [3.0, 3.2, 3.4, 3.6, 3.8, 3.5, 3.65, 3.7]   # up by 0.2; turned back with 0.1, then 0.05
    # Every observation is taken after the ramp and the settling time of the command before it.
    for (t_cmd, f_cmd), (_, f_prev), seen in zip(commands[1:], commands, seeker.observations[1:], strict=False):
        assert seen.frequency_hz == f_cmd and seen.first_s >= t_cmd + abs(f_cmd - f_prev) / 2.0 + 1.0
    assert seeker.observations[0].first_s >= 3.0 / 2.0 + 1.0       # the first setpoint ramps from rest
    assert seeker.impact(1e6, 1e3) is None                           # converged: it holds


def test_at_a_bound_it_turns_the_other_way():
    seeker = PerturbObserve(start_hz=11.9, step_hz=0.2, min_step_hz=0.05, settle_s=0.0, measure=1)
    commands = feed(seeker, lambda f: -abs(f - 11.0))
    assert all(0.5 <= f <= 12.0 for _, f in commands) and abs(seeker.result_hz - 11.0) <= 0.05


@pytest.mark.parametrize("bad", [{"step_hz": 0.0}, {"min_step_hz": 0.5}, {"measure": 0}, {"settle_s": math.nan},
                                 {"start_hz": 20.0}, {"ramp_hz_s": -1.0}])
def test_settings_it_cannot_run_are_refused(bad):
    with pytest.raises(ValueError, match=f"^{next(iter(bad))} = "):
        PerturbObserve(**bad)


@pytest.mark.parametrize("gap", [0.0, 1.0e-3])
def test_in_lockstep_it_converges_within_0_05_hz_of_the_rest_sweep_resonance(gap):
    config = load_config(None, {"gap": gap})
    seeker = PerturbObserve(start_hz=3.0)
    applied = seek_offline(config, seeker, 120.0)
    resonance, _ = rest_resonance(gap)
    assert seeker.converged, [(o.frequency_hz, o.peak_n) for o in seeker.observations]
    assert abs(seeker.result_hz - resonance) <= 0.05, (seeker.result_hz, resonance)
    print(f"gap {gap * 1e3:g} mm: converged to {seeker.result_hz:.4f} Hz at {seeker.converged_at:.2f} s of "
          f"simulation time ({len(applied)} commands); rest sweep resonance {resonance:.2f} Hz")
    # Each setpoint applied at the end of the 10 ms block of the impact that decided it (stamp zero).
    assert applied[0].time == 0 and not any(a.late for a in applied)
    for a in applied[1:]:
        assert a.time.denominator in (1, 2, 4, 5, 10, 20, 25, 50, 100)   # a block boundary
    assert applied[-1].command.frequency_hz == seeker.result_hz or seeker.frequency_hz == seeker.result_hz


def test_a_command_stamped_in_the_past_applies_late_at_the_end_of_its_block():
    config = load_config(None, {"motor.initial_frequency": 3.0, "motor.initial_setpoint": 3.0})
    decided: list[Command] = [Command(3.5, 0.0, 0.005), Command(3.6, 0.0, 0.5)]

    def decide(block):
        return [decided.pop(0)] if block.t_stop in (Fraction(1, 50), Fraction(3, 100)) else []

    applied = run_closed_loop(config, decide, 0.1)
    assert [(a.time, a.late) for a in applied] == [(Fraction(1, 50), True), (Fraction(1, 2), False)]
