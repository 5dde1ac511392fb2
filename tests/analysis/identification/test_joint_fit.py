"""The joint fit of ``rimd identify`` on a short recording of a known rig.

The fit: rimd_sim.analysis.identification.joint_fit.JointFit.

The recording is the core's run of a rig that differs from the defaults (battery rig 5 of
``tests/harness/ident_rigs.py``), two motor steps of 5 s, instrument noise on, written as the recorder writes it;
the JointFit is the one ``rimd identify`` builds (``local_stages``). Hypotheses:

* packing and unpacking the unknowns are inverse;
* the residuals are scaled by the data's own noise: at the true parameters (the shots' initial states fitted)
  the lasers' have a mean square of about 1 (their noise is white), the impacts' samples at most 1 (their spread
  is the sensor's noise and the pulse model's accuracy, 0.1 % of the impact's peak);
* the Jacobian (forward differences, segment columns re-running one shot) equals central differences;
* from a start 5 % off in mass, stiffness and damping the fit as ``rimd identify`` runs it (a robust loss, then
  least squares) converges (by its tolerances, not a budget) back to the truth within its standard errors;
* with white-noise residuals the cluster bootstrap and the Jacobian covariance agree (ratio of standard errors
  within 0.6-1.6);
* the Jacobian the covariances use (``JointFit.two_sided_jacobian``: forward and backward differences, their
  minmod) equals the forward one where the residuals are smooth (the parameters' Jacobian standard errors within
  2 %), and where one residual jumps within the step (a planted jump, as an impact's onset fit switching branch)
  the forward Jacobian reads the jump as a slope and pins the parameter (its standard error falls tenfold) while
  the two-sided one keeps the smooth standard error (within 5 %);
* the verdict says ``poorly determined``, naming the parameter, as soon as a 95 % interval exceeds its target
  (1 %; the gap 0.02 mm), and ``identified`` only when every interval is within it.
"""

from __future__ import annotations

import numpy as np
import pytest

from harness.ident_rigs import Schedule, draw_rigs, write_core_recording
from rimd_sim.analysis.identification import local as loc
from rimd_sim.analysis.identification.identify import local_stages
from rimd_sim.analysis.recordings import recorded as rec
from rimd_sim.settings.config import SimConfig

RIG = draw_rigs(14)[5]


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    path = tmp_path_factory.mktemp("joint") / "rig5.mcap"
    write_core_recording(path, RIG, Schedule([2.5, 2.25], dwell=5.0, seed=5))
    return local_stages(rec.load(path), SimConfig(), {})


@pytest.fixture(scope="module")
def truth_x(prepared) -> np.ndarray:
    """The unknowns at the true parameters (:func:`_truth_x`), fitted once for the tests that start from them."""
    return _truth_x(_fit(prepared), prepared)


def _fit(prepared):
    from rimd_sim.analysis.identification.joint_fit import JointFit

    return JointFit(SimConfig(), list(prepared.estimates), {}, prepared.segments, prepared.obs)


def _truth_x(fit, prepared):
    """The unknowns at the true parameters, each shot's initial state (and kicks) fitted."""
    from scipy.optimize import least_squares

    x = fit.pack({**prepared.params, **RIG}, [s.initial for s in fit.segments], [k for s in fit.segments
                                                                                  for k in s.kicks])
    free = np.arange(fit.n_par, fit.n)

    def f(z: np.ndarray) -> np.ndarray:
        xx = x.copy()
        xx[free] = z
        return fit.residuals(xx)

    x[free] = least_squares(f, x[free], x_scale="jac", xtol=1e-10, ftol=1e-10).x
    return x


def test_packing_round_trips(prepared):
    fit = _fit(prepared)
    values = {p: RIG[p] * 1.01 for p in fit.names}
    states = [(0.01 * (i + 1), -0.1 * i) for i in range(len(fit.segments))]
    kicks = [(t + 1e-4, v) for s in fit.segments for t, v in s.kicks]
    got_values, got_states, got_kicks = fit.unpack(fit.pack(values, states, kicks))
    assert all(got_values[p] == pytest.approx(values[p], rel=1e-12) for p in fit.names)
    assert np.allclose(got_states, states, rtol=1e-12, atol=0) and np.allclose(np.reshape(got_kicks, (-1, 2)),
                                                                            np.reshape(kicks, (-1, 2)), rtol=1e-12)


def test_residuals_at_the_truth_are_the_data_noise(prepared, truth_x):
    fit = _fit(prepared)
    parts = fit.parts(truth_x)
    for kind in ("displacement", "cart"):
        assert 0.6 < float(np.mean(parts[kind] ** 2)) < 1.4, (kind, float(np.mean(parts[kind] ** 2)))
    assert float(np.mean(parts["samples"] ** 2)) < 1.4
    # the impacts' onsets and scales: within their floors at the truth (mean square of order 1 or less)
    assert float(np.mean(parts["onset"] ** 2)) < 2.0 and float(np.mean(parts["scale"] ** 2)) < 2.0


def test_jacobian_equals_central_differences(prepared, truth_x):
    fit = _fit(prepared)
    x = truth_x.copy()
    jac = fit.jacobian(x)
    for i in (fit.names.index("mass"), fit.names.index("contact.stiffness"), fit.n_par, fit.n_par + 3):
        h = 1e-5 * max(1.0, abs(x[i]))
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        central = (fit.residuals(xp) - fit.residuals(xm)) / (2 * h)
        scale = np.linalg.norm(central)
        assert np.linalg.norm(jac[:, i] - central) < 0.02 * scale, (i, np.linalg.norm(jac[:, i] - central) / scale)


def test_the_fit_converges_back_to_the_truth_from_5_percent_off(prepared):
    fit = _fit(prepared)
    start = {**prepared.params, **{p: RIG[p] * f for p, f in (("mass", 1.05), ("contact.stiffness", 0.95),
                                                             ("contact.damping", 1.05))}}
    robust = fit.solve(fit.pack(start, [s.initial for s in fit.segments], [k for s in fit.segments for k in s.kicks]),
                       loss="soft_l1")
    result = fit.solve(robust.x)
    assert result.converged, result.message
    runs = fit.run(result.x)
    r = fit.residuals(result.x, runs)
    cov = fit.covariance(fit.jacobian(result.x, runs, r), r)
    from rimd_sim.analysis.identification.joint_fit import SCALES

    for i, p in enumerate(fit.names):
        se = float(np.sqrt(cov[i, i])) * SCALES[p]
        err = result.values[p] - RIG[p]
        assert abs(err) <= 4 * se + (1e-9 if p == "gap" else 0.0), (p, err / (RIG[p] or 1.0), se)


def test_cluster_bootstrap_agrees_with_the_jacobian_for_white_noise(prepared, truth_x):
    fit = _fit(prepared)
    x = truth_x.copy()
    runs = fit.run(x)
    r = fit.residuals(x, runs)
    jac = fit.jacobian(x, runs, r)
    cov_j = fit.covariance(jac, r)
    motor = prepared.motor
    cov_b, dxs = fit.bootstrap(jac, r, fit.clusters(motor["time"], loc.unwrapped_phase(motor)), resamples=300)
    assert dxs.shape == (300, fit.n)
    ratio = np.sqrt(np.diag(cov_b)[: fit.n_par] / np.diag(cov_j)[: fit.n_par])
    assert np.all((ratio > 0.6) & (ratio < 1.6)), dict(zip(fit.names, ratio.round(2), strict=True))


def _jacobian_se(fit, jac, r):
    from rimd_sim.analysis.identification.joint_fit import SCALES

    cov = fit.covariance(jac, r)
    return np.array([np.sqrt(cov[i, i]) * SCALES[p] for i, p in enumerate(fit.names)])


def test_the_two_sided_jacobian_keeps_the_smooth_slope_across_a_jump(prepared, truth_x):
    fit = _fit(prepared)
    x = truth_x.copy()
    runs = fit.run(x)
    r = fit.residuals(x, runs)
    smooth = _jacobian_se(fit, fit.jacobian(x, runs, r), r)
    two = _jacobian_se(fit, fit.two_sided_jacobian(x, runs, r), r)
    assert np.all(np.abs(two / smooth - 1) < 0.02), dict(zip(fit.names, (two / smooth).round(4), strict=True))
    # a jump of 3 spreads in one residual a third of a step above the mass: the forward difference crosses it
    from rimd_sim.analysis.identification.joint_fit import FD_STEP

    i = fit.names.index("mass")
    edge = x[i] + FD_STEP * max(1.0, abs(x[i])) / 3
    row = int(np.argmax(np.abs(r) < 1))   # a residual of order 1 (the jump stays within Huber's range)
    plain = fit.residuals

    def jumping(xx, runs=None):
        out = plain(xx, runs).copy()
        out[row] += 3.0 if xx[i] > edge else 0.0
        return out

    fit.residuals = jumping
    forward = _jacobian_se(fit, fit.jacobian(x, runs, r), r)
    two_jump = _jacobian_se(fit, fit.two_sided_jacobian(x, runs, r), r)
    assert forward[i] < 0.1 * smooth[i], (forward[i], smooth[i])
    assert abs(two_jump[i] / smooth[i] - 1) < 0.05, (two_jump[i], smooth[i])


@pytest.mark.parametrize("relative, gap_mm, identified", [(0.009, 0.019, True), (0.011, 0.019, False),
                                                         (0.009, 0.021, False)])
def test_the_verdict_names_a_parameter_whose_interval_exceeds_its_target(relative, gap_mm, identified):
    from types import SimpleNamespace

    from rimd_sim.analysis.identification.identify import IDENTIFIABLE, Estimate, _verdict

    values = {p: RIG[p] for p in IDENTIFIABLE}
    estimates = {p: Estimate(v, (gap_mm * 1e-3 if p == "gap" else relative * v) / 1.96, "test")
                 for p, v in values.items()}
    result = SimpleNamespace(converged=True, message="", chi2={"displacement": 1.0})
    obs = SimpleNamespace(onsets=np.zeros(10))
    verdict = _verdict(estimates, result, None, None, obs)
    assert verdict.identified is identified, verdict.line()
    named = {p for p, _, _ in verdict.poorly}
    assert named == (set() if identified else {"gap"} if gap_mm > 0.02 else set(IDENTIFIABLE) - {"gap"}), named
    assert verdict.line().startswith("VERDICT: identified" if identified else "VERDICT: poorly determined")
