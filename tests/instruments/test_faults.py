"""The fault layer and the capture in the core (no ROS): determinism however time is cut, clear, refusals."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from rimd_sim.errors import CommandError, ConfigError
from rimd_sim.instruments.faults import parse_fault_entry
from rimd_sim.instruments.rig_simulator import RigSimulator
from rimd_sim.settings.capture import CaptureConfig
from rimd_sim.settings.config import SimConfig

CFG = SimConfig().with_parameters({"seed": 5, "motor.initial_frequency": 3.75})
SCENARIO = [("impact_force", "spike", 0.2, 0.3, 500.0), ("impact_force", "delay", 0.25, 0.2, 0.05),
            ("rimd_acceleration", "clock_drift", 0.1, 0.0, 3000.0), ("cart_displacement", "block_loss", 0.0, 0.5, 0.5),
            ("rimd_displacement", "stuck", 0.33, 0.2, 0.0), ("rimd_acceleration", "noise_burst", 0.5, 0.1, 2.0)]


def run(per_call: int, blocks: int = 80):
    sim = RigSimulator(CFG, capture=CaptureConfig(enabled=True))
    for fault in SCENARIO:
        sim.inject_fault(*fault)
    out, events, captures = [], [], []
    for i in range(0, blocks, per_call):
        for b in sim.advance_blocks([Fraction(k + 1, 100) for k in range(i, min(i + per_call, blocks))]):
            for name, delivered in b.deliveries.items():
                out += [(name, c.first_index, c.samples.tobytes(), c.saturated) for c in delivered]
            events += [(e.time, e.event, e.fault.kind) for e in b.fault_events]
            captures += [(c.trigger_index, c.force.tobytes(), c.acceleration.tobytes()) for c in b.captures]
    return out, events, captures


def test_faults_and_captures_are_bit_identical_however_the_passes_cut_time():
    """Hypothesis: every random choice comes from per-fault streams drawn in sample or block order, and the
    drift and stuck states carry over between passes, so 1, 7 or 40 blocks per pass give the same bytes."""
    a, b, c = run(1), run(7), run(40)
    assert a == b == c
    out, events, captures = a
    assert len(captures) >= 2
    kinds = {k for _, e, k in events if e == "start"}
    assert kinds == {f[1] for f in SCENARIO}
    ends = {k for _, e, k in events if e == "end"}
    assert ends == {f[1] for f in SCENARIO if f[3] > 0}   # the drift runs until cleared
    # the block loss lost some cart blocks, none after its end
    cart = sorted(i for n, i, *_ in out if n == "cart_displacement")
    assert 0 < 80 - len(cart) < 50 and all(j - i == 20 for i, j in zip(cart, cart[1:], strict=False) if i >= 1000)


def test_clear_ends_the_faults_in_force_and_cancels_the_scheduled_ones():
    sim = RigSimulator(CFG)
    sim.inject_fault("impact_force", "offset", 0.0, 0.0, 1.0)
    sim.inject_fault("impact_force", "dropout", 0.5, 0.1, 0.0)
    sim.advance(Fraction(1, 10))
    assert [f.kind for f in sim.active_faults()] == ["offset"]
    assert sim.clear_faults() == (1, 1)
    block = sim.advance(Fraction(2, 10))
    assert [(e.event, e.fault.kind, e.detail) for e in block.fault_events] == [("end", "offset", "cleared")]
    assert sim.active_faults() == []
    assert np.abs(block.channels["impact_force"].samples).max() < 0.5   # the offset of 1 N is gone


@pytest.mark.parametrize(("fault", "message"), [
    (("nope", "dropout"), "channel = 'nope' refused"),
    (("impact_force", "melt"), "kind = 'melt' refused"),
    (("impact_force", "dropout", 0.0, -1.0), "duration = -1.0 refused: must be >= 0"),
    (("impact_force", "offset", 0.0, 0.0, float("nan")), "magnitude = nan refused: must be finite"),
    (("impact_force", "block_loss", 0.0, 0.0, 1.01), "for kind 'block_loss' it must be a fraction within [0, 1]"),
    (("impact_force", "spike", 0.0, 0.0, 30000.0), "at most the channel's sample rate"),
    (("impact_force", "dropout", 0.05), "start = 0.05 refused: in the past"),
    (("impact_force", "motor_slip"), "acts on the channel 'motor'"),
    (("motor", "motor_slip", 0.0, 0.0, 1.5), "must be a fraction within [0, 1]"),
])
def test_bad_faults_are_refused_naming_the_field_and_nothing_is_scheduled(fault, message):
    sim = RigSimulator(CFG)
    sim.advance(Fraction(1, 10))
    with pytest.raises(CommandError, match=None) as refused:
        sim.inject_fault(*fault)
    assert message in str(refused.value)
    assert sim.advance(Fraction(2, 10)).fault_events == []


def test_scenario_entries_and_capture_parameters_are_checked():
    assert parse_fault_entry("channel=impact_force kind=stuck start=1 duration=2", "faults[0]") == {
        "channel": "impact_force", "kind": "stuck", "start": 1.0, "after": 0.0, "duration": 2.0, "magnitude": 0.0}
    assert parse_fault_entry({"channel": "impact_force", "kind": "offset", "after": 2}, "faults[1]")["after"] == 2.0
    with pytest.raises(CommandError, match=r"faults\[2\]: give start .* or after"):
        parse_fault_entry({"channel": "impact_force", "kind": "offset", "start": 1.0, "after": 2.0}, "faults[2]")
    with pytest.raises(CommandError, match=r"faults\[3\] = 'channel=x oops' refused: 'oops' is not key=value"):
        parse_fault_entry("channel=x oops", "faults[3]")
    with pytest.raises(ConfigError, match=r"parameter 'capture.sample_rate' = 5.0 refused: must be >= 20000"):
        CaptureConfig.from_parameters({"capture.sample_rate": 5.0})
    with pytest.raises(ConfigError, match=r"'capture.threshold' = nan refused"):
        CaptureConfig.from_parameters({"capture.threshold": float("nan")})


def test_capture_acceleration_outside_contact_is_close_to_the_full_1_mhz_evaluation():
    """The fast acceleration is evaluated in contact only and interpolated from the 20 kHz channel outside:
    within 0.5 m/s^2 (noise of 0.05 included) of evaluating the model at every microsecond, where the
    contact reaches hundreds of m/s^2; the captured force peak within 0.5 % of the impact's."""
    from rimd_sim.model.rig_model import RigModel

    sim = RigSimulator(CFG, capture=CaptureConfig(enabled=True))
    captures, impacts = [], []
    for b in sim.advance_blocks([Fraction(k + 1, 100) for k in range(150)]):
        captures += b.captures
        impacts += b.impacts
    full = RigModel(CFG, extra_channels=(("acc", Fraction(10**6), "rimd_acceleration"),)).advance(Fraction(3, 2))
    acc = full.channels["acc"][1]
    assert len(captures) >= 4
    for c in captures:
        lo = c.trigger_index - c.pre_trigger_samples
        assert np.abs(c.acceleration - acc[lo:lo + c.acceleration.size]).max() < 0.5
        assert c.acceleration.min() < -300.0
        impact = min(impacts, key=lambda i: abs(i.t_start - float(c.trigger_time)))
        assert abs(c.force.max() / impact.peak_force - 1) <= 0.005


def _slip_run(slip: tuple | None, t_end: float = 4.0, clear_at: float | None = None):
    sim = RigSimulator(CFG.with_parameters({"motor.initial_setpoint": 3.75}))
    if slip is not None:
        sim.inject_fault("motor", "motor_slip", *slip)
    freq, impacts, blocks = [], [], []
    for k in range(int(t_end * 100)):
        if clear_at is not None and k == int(clear_at * 100):
            sim.clear_faults()
        b = sim.advance(Fraction(k + 1, 100))
        first, rows = b.truth
        freq.append(rows[9])
        impacts += b.impacts
        blocks.append(b.channels["impact_force"].samples.tobytes())
    return np.concatenate(freq), impacts, blocks


def test_motor_slip_sags_the_motor_at_each_impact_and_it_ramps_back():
    """Hypothesis (the one physical fault): from its start, each contact onset takes 5 % off the motor's
    frequency over 2 ms (kernel.SLIP_TIME), which then ramps back to the setpoint at motor.ramp_rate (2 Hz/s:
    0.19 Hz in 94 ms, well within the 267 ms between impacts at 3.75 Hz); before the start everything is
    bit for bit the run without it, and after its end the motor sits on its setpoint again."""
    base_f, base_imp, base_blocks = _slip_run(None)
    f, imp, blocks = _slip_run((1.0, 2.0, 0.05))
    rate = CFG.truth_rate
    n_start = int(1.0 * rate)
    assert np.array_equal(f[:n_start], base_f[:n_start]) and blocks[:100] == base_blocks[:100]
    assert [i for i in imp if i.t_start < 1.0] == [i for i in base_imp if i.t_start < 1.0]
    assert np.all(base_f[int(0.5 * rate):] == 3.75)                  # the motor is at its setpoint without slip
    during = [i for i in imp if 1.0 <= i.t_start < 3.0]
    assert len(during) >= 6
    for i in during:
        assert i.excitation_frequency == pytest.approx(3.75, abs=1e-9)   # recovered before each next impact
        n = int(np.ceil((i.t_start + 0.002) * rate))               # the first truth sample after the sag
        assert f[n] == pytest.approx(3.75 * 0.95 + 2.0 * (n / rate - i.t_start - 0.002), abs=2e-3)
        assert f[n + int(0.1 * rate)] == 3.75                          # back on the setpoint 100 ms later
    # The deepest sample: the sag's bottom, or up to one truth sample of the 2 Hz/s ramp after it.
    assert 3.75 * 0.95 - 1e-9 <= f.min() <= 3.75 * 0.95 + 2.0 / rate + 1e-9
    assert np.all(f[int(3.2 * rate):] == 3.75) and not np.all(f[n_start:int(3.0 * rate)] == 3.75)
    assert blocks[100:300] != base_blocks[100:300]                     # the truth and the sensors show it


def test_clear_faults_ends_a_motor_slip_and_cancels_a_scheduled_one():
    f, imp, _ = _slip_run((0.5, 0.0, 0.1), t_end=2.5, clear_at=1.0)
    rate = CFG.truth_rate
    assert f[int(0.5 * rate):int(1.0 * rate)].min() < 3.5               # sagging until the clear
    assert np.all(f[int(1.2 * rate):] == 3.75)                          # none after (a sag ramps back first)
    f2, _, _ = _slip_run((1.5, 0.5, 0.1), t_end=2.5, clear_at=1.0)     # cleared before it started
    assert np.all(f2[int(0.5 * rate):] == 3.75)


def test_motor_slip_motor_states_are_the_same_however_the_passes_cut_time():
    """Under a slip the motor changes at every impact, several times within a pass of many blocks: the motor
    state of each block end (what /rig/motor/state publishes) must not depend on how the passes cut time."""
    def states(per_call: int):
        sim = RigSimulator(CFG.with_parameters({"motor.initial_setpoint": 3.75}))
        sim.inject_fault("motor", "motor_slip", 0.3, 0.0, 0.05)
        out = []
        for i in range(0, 150, per_call):
            out += [(b.motor.frequency, b.motor.phase, b.truth[1].tobytes(), b.motor.frequency_setpoint)
                    for b in sim.advance_blocks([Fraction(k + 1, 100) for k in range(i, min(i + per_call, 150))])]
        return out
    one, many = states(1), states(25)
    assert one == many
    assert min(f for f, *_ in one) < 3.6
    assert {s for *_, s in one} == {3.75}   # the sag is not a new setpoint: it returns to the user's one


def test_block_loss_loses_the_stated_fraction_of_blocks_and_only_within_its_window():
    """``block_loss`` 0.2 over 1000 blocks (10 s at 100 blocks/s): the lost count is Binomial(1000, 0.2), so
    within 5 standard deviations of 200 (137..263); a rule inverted to 1 - p, or one ignoring the magnitude,
    loses 800 or 1000. Nothing is lost outside the window (before 1 s, after 11 s)."""
    sim = RigSimulator(CFG.with_parameters({"seed": 9}))
    sim.inject_fault("cart_displacement", "block_loss", 1.0, 10.0, 0.2)
    firsts = []
    for b in sim.advance_blocks([Fraction(k, 100) for k in range(1, 1201)]):
        firsts += [c.first_index for c in b.deliveries.get("cart_displacement", [])]
    per_block = round(CFG.channel("cart_displacement").sample_rate / 100)   # samples per block
    received = set(firsts)
    lost = [k for k in range(1200) if k * per_block not in received]    # block k covers [k, k + 1) / 100 s
    assert all(100 <= k < 1100 for k in lost), "a block lost outside the fault's window"
    assert 137 <= len(lost) <= 263, len(lost)


def test_clock_drift_100_ppm_over_600_s():
    """+100 ppm on the force channel from t = 0: 600 s later its impact times lag the acceleration channel's
    by 60 ms (within one sample: 100e-6 * 600 s), and every block stays on the nominal grid. On the core: the
    drift is a property of the fault layer, not of the transport (the fault runs over DDS check that a drift
    reaches a client and a recording)."""
    from rimd_sim.analysis.recordings.faultscan import drift_fit

    rate = 20000.0
    config = SimConfig().with_parameters({"block_rate": 20.0, "motor.initial_frequency": 3.75,
                                          "motor.initial_setpoint": 3.75})
    sim = RigSimulator(config, truth=False)
    sim.inject_fault("impact_force", "clock_drift", 0.0, 0.0, 100.0)
    above = {"rimd_acceleration": [], "impact_force": []}
    thresholds = {"rimd_acceleration": 200.0, "impact_force": 20.0}   # |x| of an impact on each channel
    expected_first = dict.fromkeys(above, 0)
    for second in range(601):
        for b in sim.advance_blocks([Fraction(20 * second + k, 20) for k in range(1, 21)]):
            for name in above:
                c = b.channels[name]
                assert c.first_index == expected_first[name], (name, c.first_index)   # no hole, on the grid
                expected_first[name] += len(c.samples)
                above[name].append(np.flatnonzero(np.abs(c.samples) >= thresholds[name]) + c.first_index)

    def crossings(name: str) -> np.ndarray:
        idx = np.unique(np.concatenate(above[name]))
        return idx[np.r_[True, np.diff(idx) > int(0.002 * rate)]] / rate

    t, lag = drift_fit(crossings("rimd_acceleration"), crossings("impact_force"))
    assert t.size > 2000 and t.max() > 590   # one impact per cycle at 3.75 Hz: 2250 in 600 s
    slope, intercept = np.polyfit(t, lag, 1)
    at_600 = slope * 600.0 + intercept - (lag[:20].mean() - slope * t[:20].mean())   # accumulated since 0
    assert abs(at_600 - 0.060) <= 1.0 / rate, f"drift at 600 s: {at_600 * 1e3:.4f} ms"
    assert np.max(np.abs(lag - (slope * t + intercept))) <= 1.0 / rate + 1e-9   # each impact within a sample
    assert slope == pytest.approx(1e-4, rel=0.01)


def test_delay_releases_the_blocks_of_its_window_late_by_the_latency_plus_jitter():
    """The timing of ``delay``, behind the core's clock (the DDS test keeps a coarse check of arrival times): a
    block of the window leaves between ``latency`` and 1.5 ``latency`` (plus one block period, as blocks leave
    at block boundaries) after its last sample, in a random order; every other block leaves with its own."""
    start, duration, latency = 0.6, 0.3, 0.1
    sim = RigSimulator(CFG)
    sim.inject_fault("impact_force", "delay", start, duration, latency)
    rate, period = 20000, 0.01
    late, order = [], []
    for b in sim.advance_blocks([Fraction(k, 100) for k in range(1, 151)]):
        leaves = float(b.t_stop)   # the DAQ receives the deliveries at the end of the block
        for c in b.deliveries["impact_force"]:
            order.append(c.first_index)
            data_end = (c.first_index + len(c.samples)) / rate
            late.append((c.first_index / rate, leaves - data_end))
    in_window = [d for t, d in late if start <= t < start + duration]
    outside = [d for t, d in late if not start <= t < start + duration]
    assert len(in_window) == round(duration / period) and all(d == pytest.approx(0.0, abs=1e-9) for d in outside)
    assert all(latency - 1e-9 <= d <= 1.5 * latency + period + 1e-9 for d in in_window), in_window
    assert sorted(order) == list(range(0, 150 * 200, 200)) and order != sorted(order)   # late and reordered
