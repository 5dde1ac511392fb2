"""Continuation of periodic orbits (rimd_sim.analysis.dynamics.continuation), checked against independent methods.

* the period doubling against where the largest Lyapunov exponent of ``rimd poincare`` (two trajectories on the
  attractor reached from rest) peaks at zero, bisected here on the sign of its slope;
* the Floquet multipliers against a monodromy matrix built here by central differences of ``RigModel`` runs,
  and against Liouville's formula (``det M = exp(-2 zeta omega_n T)`` in free flight, exact);
* an unstable orbit's departure rate in a long run against its largest multiplier;
* the grazing frequency against the non-impacting orbit of the pendulum's equation integrated by scipy;
* the verb's files, its exit status on orbits outside the model's valid domain, every model of the registry.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, fsolve, minimize_scalar

from harness.presets import SINGLE_MASS_SET
from rimd_sim import cli
from rimd_sim.analysis.dynamics.continuation import (
    SHOOTING_TOLERANCES,
    ContinuationSettings,
    StartOutsideDomain,
    continuation,
    fixed_point,
    monodromy,
)
from rimd_sim.analysis.dynamics.lyapunov import largest_lyapunov
from rimd_sim.analysis.dynamics.steady import constant_frequency
from rimd_sim.model.rig_model import RigModel
from rimd_sim.model.shooting import flow_points
from rimd_sim.settings.config import find_config_file, load_config


def _config(name: str, gap_mm: float, **overrides):
    return load_config(find_config_file(name), {"gap": gap_mm * 1e-3, **overrides})


def _strobe(config, f: float, x, periods: int = 1) -> np.ndarray:
    """``P^periods(x)`` by a plain ``RigModel`` run (the core's run, not the shooting kernel)."""
    model = RigModel(constant_frequency(config, f, float(x[0]), float(x[1])), channels=False, truth=False,
                     strobe=True, initial_modes=tuple(x[2:]))
    out = model.advance((periods + 0.5) / f)
    s = next(s for s in out.strobe if s.cycle_index == periods)
    return np.array([s.theta, s.theta_dot, *s.modes])


# ---- the shooting kernel --------------------------------------------------------------------------------


def test_the_shooting_kernel_gives_the_stroboscopic_point_of_a_rig_model_run_bit_for_bit():
    config = _config("paper_model.yaml", 0.0)
    from rimd_sim.model.rig_model import model_for

    p = model_for(config).params(config)
    starts = np.array([[-0.04, 0.1], [0.0, 0.0], [-0.03, -0.7]])
    out, status = flow_points("rigid", p, 4.0, starts, 3)
    assert (status == 0).all()
    for x, y in zip(starts, out, strict=True):
        assert np.array_equal(_strobe(config, 4.0, x, 3), y)


# ---- Must show 1: the period doubling, against the Lyapunov exponent ----------------------------------


def _lyapunov_peak(config, lo: float, hi: float, eps: float = 0.004, width: float = 0.006) -> tuple[float, float]:
    """Where the largest Lyapunov exponent of the attractor from rest peaks, by bisection on its slope's sign.

    Below a period doubling the attractor is the period-1 orbit, its exponent ``f ln|mu|`` rising to 0; above it
    the new period-2 orbit's, falling from 0: the exponent crosses zero (touches it) at the bifurcation.
    """
    def lam(f):
        return largest_lyapunov(config, f, transient_cycles=200, cycles=200).exponent

    while hi - lo > width:
        mid = 0.5 * (lo + hi)
        if lam(mid + eps) > lam(mid - eps):
            lo = mid
        else:
            hi = mid
    mid = 0.5 * (lo + hi)
    return mid, lam(mid)


@pytest.mark.parametrize("name, f_end", [("paper_model.yaml", 5.0), ("rimd.yaml", 5.1)])
def test_the_period_doubling_is_where_the_lyapunov_exponent_crosses_zero_and_the_period_two_branch_is_followed(
        name, f_end):
    config = _config(name, 0.0)
    result = continuation(config, 3.0, f_end, settings=ContinuationSettings(max_period=2))
    first = result.branches[0]
    assert first.period == 1 and first.points[0].stable and first.points[0].impacts_per_period == 1
    pds = result.of_kind("period_doubling")
    assert len(pds) == 1, result.bifurcations
    pd = pds[0]
    assert pd.branch == 0 and pd.period == 1
    assert abs(min(abs(pd.multipliers + 1.0))) < 1e-2
    # Stable below, unstable above, on the period-1 branch.
    assert all(p.stable for p in first.points if p.parameter < pd.parameter - 1e-3)
    assert not any(p.stable for p in first.points if p.parameter > pd.parameter + 1e-3)
    # The period-2 branch is followed from the switch: stable 2/2 orbits just past the doubling.
    child = result.branches[pd.new_branch]
    assert child.period == 2 and child.parent == 0 and len(child.points) >= 5
    near = [p for p in child.points if pd.parameter < p.parameter < pd.parameter + 0.05]
    assert near and all(p.stable and p.impacts_per_period == 2 for p in near)
    assert max(np.linalg.norm(p.orbit[0] - p.orbit[1]) for p in near) > 1e-4   # two distinct points
    # The independent location: the Lyapunov exponent of rimd poincare's core peaks at zero there.
    f_lyap, lam_peak = _lyapunov_peak(config, pd.parameter - 0.15, pd.parameter + 0.15)
    assert abs(f_lyap - pd.parameter) < 0.02, (f_lyap, pd.parameter)
    assert lam_peak > -0.5 > largest_lyapunov(config, pd.parameter - 0.1, transient_cycles=200, cycles=200).exponent


# ---- Must show 2: the multipliers against an independent monodromy matrix -------------------------------


@pytest.mark.parametrize("f, period", [(4.0, 1), (4.9, 2)])
def test_the_multipliers_agree_with_a_monodromy_matrix_built_from_rig_model_runs(f, period):
    config = _config("paper_model.yaml", 0.0)
    result = continuation(config, 3.0, 5.0, settings=ContinuationSettings(max_period=2))
    branch = next(b for b in result.branches if b.period == period)
    point = min(branch.points, key=lambda p: abs(p.parameter - f))
    f = point.frequency_hz
    x = point.point
    tight = config.with_parameters(SHOOTING_TOLERANCES)
    assert np.allclose(_strobe(tight, f, x, period), x, rtol=0, atol=1e-8)   # a fixed point of P^n
    m = np.empty((2, 2))
    for j, h in enumerate((1e-6, 1e-5)):   # rad, rad/s
        e = np.zeros(2)
        e[j] = h
        m[:, j] = (_strobe(tight, f, x + e, period) - _strobe(tight, f, x - e, period)) / (2 * h)
    mine = np.sort_complex(point.multipliers)
    theirs = np.sort_complex(np.linalg.eigvals(m))
    assert np.max(np.abs(mine - theirs)) < 1e-4, (mine, theirs)
    # The exported monodromy matrix is the same matrix.
    assert np.max(np.abs(monodromy(config, f, x, period=period) - m)) < 1e-4 * max(1.0, np.abs(m).max())


def test_in_free_flight_the_multipliers_obey_liouville_exactly():
    """No impact: ``det M = exp(-2 zeta omega_n T)`` (the trace of the pendulum's Jacobian is ``-2 zeta omega_n``)."""
    config = _config("rimd.yaml", 2.4).with_parameters(SINGLE_MASS_SET)   # no impact at 3 Hz
    f = 3.0
    x, mu = fixed_point(config, f, (0.0, 0.0))
    rig = config.rig
    assert abs(np.prod(mu).real - math.exp(-2 * rig.damping_ratio * rig.omega_n / f)) < 1e-6
    assert np.all(np.abs(mu) < 1)


# ---- Must show 3: an unstable orbit leaves at the rate of its largest multiplier ------------------------


def test_an_unstable_orbit_started_in_a_long_run_leaves_at_the_rate_of_its_largest_multiplier():
    config = _config("paper_model.yaml", 0.0)
    f = 5.0
    result = continuation(config, 4.5, 5.1, settings=ContinuationSettings(switch=False))
    point = min(result.branches[0].points, key=lambda p: abs(p.parameter - f))
    assert not point.stable
    f, x = point.frequency_hz, point.point
    mu = point.multipliers[0]
    assert abs(mu.imag) < 1e-12 and abs(mu) > 1.3
    a = monodromy(config, f, x)
    w, v = np.linalg.eig(a)
    direction = np.real(v[:, int(np.argmax(np.abs(w)))])
    tight = config.with_parameters(SHOOTING_TOLERANCES)
    model = RigModel(constant_frequency(tight, f, *(x + 1e-9 * direction / np.linalg.norm(direction))),
                     channels=False, truth=False, strobe=True)
    out = model.advance(60.5 / f)
    scale = np.array([1.0, 1.0 / (2 * math.pi * f)])
    dist = np.array([np.linalg.norm((np.array([s.theta, s.theta_dot]) - x) * scale) for s in out.strobe])
    # The linear regime: from 100 times the start's offset to a thousandth of the orbit's size.
    k = np.arange(dist.size)
    linear = (dist > 1e-7) & (dist < 1e-4) & (k > 0)
    assert linear.sum() >= 6, dist
    rate = np.polyfit(k[linear], np.log(dist[linear]), 1)[0]
    assert abs(rate - math.log(abs(mu))) < 0.05 * math.log(abs(mu)), (rate, math.log(abs(mu)))
    assert dist[-1] > 1e-3   # and it has left


# ---- Must show 4: grazing at gap 2.4 mm, against scipy --------------------------------------------------


def _scipy_grazing(config, gap: float, lo: float, hi: float) -> float:
    """The frequency where the pendulum's non-impacting periodic orbit reaches ``l sin(theta) = gap``.

    The pendulum's equation (docs/physics.md) written out here and integrated by scipy's DOP853; the periodic orbit
    by fsolve on one period; the largest ``l sin(theta)`` by a bounded minimisation on the dense output.
    """
    rig = config.rig
    a0, length, wn, zeta = rig.amplitude, rig.length, rig.omega_n, rig.damping_ratio

    def rhs(t, y, w):
        ac = -a0 * w * w * math.sin(w * t)
        return [y[1], -(ac / length) * math.cos(y[0]) - wn * wn * math.sin(y[0]) - 2 * zeta * wn * y[1]]

    def reach(f):
        w = 2 * math.pi * f
        amp = a0 * w * w / length / (wn * wn - w * w)

        def shoot(y0):
            return solve_ivp(rhs, (0, 1 / f), y0, args=(w,), method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1] - y0

        y0 = fsolve(shoot, [0.0, amp * w], xtol=1e-13)
        sol = solve_ivp(rhs, (0, 1 / f), y0, args=(w,), method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True)
        t = np.linspace(0, 1 / f, 4001)
        j = int(np.argmax(np.sin(sol.sol(t)[0])))
        best = minimize_scalar(lambda s: -math.sin(sol.sol(s)[0]), bounds=(t[max(j - 1, 0)], t[min(j + 1, 4000)]),
                               method="bounded", options={"xatol": 1e-12})
        return length * math.sin(sol.sol(best.x)[0]) - gap

    return brentq(reach, lo, hi, xtol=1e-10)


@pytest.mark.filterwarnings("ignore:The iteration is not making good progress")
@pytest.mark.parametrize("name", ["rimd.yaml", "paper_model.yaml"])
def test_grazing_at_gap_2_4_mm_is_located_where_the_non_impacting_orbit_first_touches_the_stop(name):
    config = _config(name, 2.4)
    # Down from 3.5 Hz, where the no-impact orbit is the only periodic one near the linear response.
    result = continuation(config, 3.5, 2.0, period=1)
    first = result.branches[0]
    assert first.points[0].impacts_per_period == 0
    grazings = [b for b in result.of_kind("grazing") if b.branch == 0]
    assert grazings, (first.end, result.bifurcations)
    f_graze = grazings[0].frequency_hz
    assert not result.of_kind("neimark_sacker")   # the undamped model's conservative orbits: no false alarm
    expected = _scipy_grazing(config, 2.4e-3, 2.2, 3.0)
    assert abs(f_graze - expected) < 1e-4, (f_graze, expected)


# ---- every model of the registry ------------------------------------------------------------------------


def test_the_two_mass_model_is_continued_with_its_modes_in_the_fixed_point():
    config = load_config(find_config_file("structural.yaml"), {"gap": 0.0})
    result = continuation(config, 3.5, 3.8, settings=ContinuationSettings(max_points=12))
    branch = result.branches[0]
    assert len(branch.points) >= 3 and branch.points[0].impacts_per_period >= 1
    point = branch.points[-1]
    assert point.point.size == 6 and point.multipliers.size == 6
    tight = config.with_parameters(SHOOTING_TOLERANCES)
    y = _strobe(tight, point.frequency_hz, point.point, branch.period)
    assert np.allclose(y[:2], point.point[:2], rtol=0, atol=1e-8)
    lyap = largest_lyapunov(config, point.frequency_hz, transient_cycles=100, cycles=60).exponent
    assert (lyap < 0) == point.stable


def test_a_branch_in_the_gap_meets_the_frequency_branch_at_their_common_point():
    """Continuation in another parameter (the gap, from its bound 0) at a fixed frequency: its first orbit is the
    frequency branch's orbit at that frequency, and each orbit is a fixed point at its own gap."""
    config = _config("rimd.yaml", 0.0)
    by_gap = continuation(config, 0.0, 0.5e-3, parameter="gap", frequency_hz=3.75,
                          settings=ContinuationSettings(switch=False))
    branch = by_gap.branches[0]
    assert by_gap.parameter == "gap" and branch.points[0].parameter == 0.0
    assert branch.points[-1].parameter == pytest.approx(0.5e-3) and all(p.frequency_hz == 3.75 for p in branch.points)
    x, _ = fixed_point(config, 3.75, branch.points[0].point)
    assert np.allclose(x, branch.points[0].point, rtol=0, atol=1e-9)
    mid = branch.points[len(branch.points) // 2]
    tight = _config("rimd.yaml", mid.parameter * 1e3).with_parameters(SHOOTING_TOLERANCES)
    assert np.allclose(_strobe(tight, 3.75, mid.point), mid.point, rtol=0, atol=1e-8)


# ---- the verb ---------------------------------------------------------------------------------------------


@pytest.mark.process   # the brute-force diagram behind runs its up and down sweeps in two processes
def test_rimd_continue_writes_the_branch_the_bifurcations_and_the_plot(tmp_path):
    out = tmp_path / "cont"
    status = cli.main(["continue", "--config", str(find_config_file("paper_model.yaml")), "--gap-mm", "0",
                       "--f-start", "4.5", "--f-end", "4.95", "--max-period", "2", "--diagram-points", "4",
                       "--out", str(out)])
    assert status == 0
    rows = list(csv.DictReader(open(out / "branch.csv")))
    assert {"frequency_hz", "theta_rad", "theta_dot_rad_s", "stable", "mu1_re", "mu1_im", "mu2_re",
            "peak_force_n", "impacts_per_period", "valid", "invalid_rule"} <= set(rows[0])
    assert {r["period"] for r in rows} == {"1", "2"}
    assert {r["stable"] for r in rows} == {"True", "False"}
    bifs = json.loads((out / "bifurcations.json").read_text())
    pd = [b for b in bifs if b["kind"] == "period_doubling"]
    assert pd and {"kind", "frequency_hz", "period"} <= set(pd[0]) and 4.8 < pd[0]["frequency_hz"] < 4.85
    assert (out / "continuation.png").stat().st_size > 10_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["bifurcations"]["period_doubling"] == 1


FN11 = """/**/rimd_simulator:
  ros__parameters:
    natural_frequency: 11.0
    motor:
      max_frequency: 30.0
"""


def test_orbits_outside_the_valid_domain_are_marked_and_the_verb_exits_non_zero(tmp_path, capsys):
    path = tmp_path / "fn11.yaml"
    path.write_text(FN11)
    # f_n 11 Hz, gap 1 mm, 22 Hz: the motion from rest chatters; there is no branch to follow.
    status = cli.main(["continue", "--config", str(path), "--gap-mm", "1", "--f-start", "22", "--f-end", "23",
                       "--diagram-points", "0", "--out", str(tmp_path / "a")])
    assert status == 3
    assert "chattering" in capsys.readouterr().out.strip().splitlines()[-1]
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["invalid_rule"] == "chattering"
    with pytest.raises(StartOutsideDomain):
        continuation(load_config(path, {"gap": 1e-3}), 22.0, 23.0)
    # Gap 0.5 mm, 21 Hz: a periodic orbit past 90 deg; every orbit of the branch is marked.
    status = cli.main(["continue", "--config", str(path), "--gap-mm", "0.5", "--f-start", "21", "--f-end", "21.2",
                       "--diagram-points", "0", "--out", str(tmp_path / "b")])
    assert status == 3
    rows = list(csv.DictReader(open(tmp_path / "b" / "branch.csv")))
    assert rows and all(r["valid"] == "False" and "pendulum_angle" in r["invalid_rule"] for r in rows)
    assert "|theta| > 90 deg" in capsys.readouterr().out.strip().splitlines()[-1]
    # Accepted: the same files, exit 0.
    assert cli.main(["continue", "--config", str(path), "--gap-mm", "0.5", "--f-start", "21", "--f-end", "21.2",
                     "--diagram-points", "0", "--accept-invalid", "--out", str(tmp_path / "c")]) == 0


def test_bad_ranges_are_refused_with_the_parameter_named():
    config = _config("rimd.yaml", 0.0)
    with pytest.raises(Exception, match="max_frequency|frequency"):
        continuation(config, 3.0, 40.0)
    with pytest.raises(Exception, match="range"):
        continuation(config, 3.0, 3.0)
    with pytest.raises(Exception, match="frequency"):
        continuation(config, 0.0, 1e-3, parameter="gap")


def test_a_fold_at_its_branch_start_is_flagged_as_suspect():
    """A fold within 1 % of the range from its branch's first orbit is flagged (the predictor may have turned back
    there); one further on is not."""
    from types import SimpleNamespace

    from rimd_sim.cli.verbs.continuation import suspect_fold

    point = SimpleNamespace(parameter=3.0)
    result = SimpleNamespace(start=3.0, end=5.0, branches=[SimpleNamespace(points=[point])])
    assert suspect_fold(result, SimpleNamespace(kind="fold", branch=0, parameter=3.001))
    assert not suspect_fold(result, SimpleNamespace(kind="fold", branch=0, parameter=3.5))
    assert not suspect_fold(result, SimpleNamespace(kind="period_doubling", branch=0, parameter=3.001))
