"""Estimators and uncertainty methods: known answers on constructed data, and the simulator."""
from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from agvdyn.identification import IdentificationSettings, identify
from agvdyn.identification.estimators import Bounded, LeastSquares, Robust, WeightedLeastSquares, make_estimator
from agvdyn.identification.normal import RegressionData, RowIndex
from agvdyn.identification.uncertainty import correlation_time, parameter_uncertainty
from agvdyn.io import Log
from agvdyn.simulation import SLIP_SCENARIO, PlantSettings, SimulationSettings, simulate

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics


def _index(m: int, groups: np.ndarray | None = None) -> RowIndex:
    g = np.zeros(m, dtype=np.int64) if groups is None else groups
    return RowIndex(g, tuple(str(i) for i in range(int(g.max()) + 1)), np.zeros(m, dtype=np.int64), np.arange(m))


def test_wls_weights_groups_by_their_noise():
    """Two groups of rows with noise 0.01 and 1: WLS recovers the per-group variances and its
    standard deviations follow the information, OLS's pooled sigma does not."""
    rng = np.random.default_rng(1)
    A = rng.standard_normal((4000, 2))
    g = np.repeat([0, 1], 2000)
    y = A @ [1.0, -2.0] + np.where(g == 0, 0.01, 1.0) * rng.standard_normal(4000)
    wls = WeightedLeastSquares().fit(A, y, groups=g)
    assert np.sqrt(wls.group_variance_) == pytest.approx([0.01, 1.0], rel=0.1)
    ols = LeastSquares().fit(A, y)
    assert np.all(wls.std_ < 0.5 * ols.std_)
    assert np.abs(wls.coef_ - [1.0, -2.0]).max() < 4 * wls.std_.max()


def test_robust_ignores_gross_outliers_and_reports_them():
    rng = np.random.default_rng(2)
    A = rng.standard_normal((2000, 3))
    y = A @ [0.5, 1.0, -1.0] + 0.05 * rng.standard_normal(2000)
    bad = rng.choice(2000, 60, replace=False)
    y[bad] += 30.0
    for loss in ("tukey", "huber"):
        est = Robust(loss=loss).fit(A, y)
        assert np.abs(est.coef_ - [0.5, 1.0, -1.0]).max() < (0.01 if loss == "tukey" else 0.05)
        assert set(bad) <= set(np.flatnonzero(est.downweighted_))
    assert np.abs(LeastSquares().fit(A, y).coef_ - [0.5, 1.0, -1.0]).max() > 0.05


def test_bounded_keeps_physical_signs_and_names_active_bounds():
    rng = np.random.default_rng(3)
    A = np.abs(rng.standard_normal((500, 2)))
    y = A @ [2.0, -0.3] + 0.01 * rng.standard_normal(500)  # the data want d_vw < 0
    est = Bounded().fit(A, y, names=["m_ch", "d_vw"])
    assert est.coef_[1] == 0.0 and est.active_ == ("d_vw",) and est.coef_[0] > 0
    assert est.cov_[1, 1] == 0.0
    est = Bounded({"m_ch": (2.5, 3.0)}).fit(A, y, names=["m_ch", "d_vw"])
    assert est.coef_[0] == pytest.approx(2.5) and set(est.active_) == {"m_ch"} | ({"d_vw"} if est.coef_[1] == 0 else set())
    with pytest.raises(ValueError, match="estimator 'lasso'"):
        make_estimator("lasso")


@hsettings(max_examples=15, deadline=None, derandomize=True)
@given(st.floats(0.0, 0.9), st.integers(0, 10_000))
def test_hac_against_the_known_long_run_variance(phi, seed):
    """AR(1) residuals: the Bartlett HAC std of a mean is within 25 % of the exact value
    sqrt(sigma^2 (1 + phi) / (1 - phi) / n), classic's is too small by sqrt((1 + phi)/(1 - phi)).

    The HAC estimate itself scatters by about sqrt(L / n) (L ~ 2 tau, n / tau independent
    blocks): with phi <= 0.9 (tau <= 19) and n = 40,000 that is below 5 %, so 25 % is 5 sigma."""
    rng = np.random.default_rng(seed)
    n = 40000
    e = np.empty(n)
    e[0] = rng.standard_normal()
    for i in range(1, n):
        e[i] = phi * e[i - 1] + math.sqrt(1 - phi**2) * rng.standard_normal()
    A = np.ones((n, 1))
    est = LeastSquares().fit(A, 3.0 + e)
    exact = math.sqrt((1 + phi) / (1 - phi) / n)
    hac = parameter_uncertainty("hac", est, RegressionData.from_rows(A, 3.0 + e, _index(n))).std[0]
    assert hac == pytest.approx(exact, rel=0.25)
    assert est.std_[0] == pytest.approx(1 / math.sqrt(n), rel=0.05)
    tau = correlation_time([e[:, None]])[0]
    assert tau == pytest.approx((1 + phi) / (1 - phi), rel=0.35)
    # scores of any scale (a near-exact fit weighted by tiny variances reaches 1e16): the same time
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scaled = correlation_time([np.column_stack([e, 1e17 * e])])
    assert scaled == pytest.approx([tau, tau], rel=1e-5)


def test_bootstrap_agrees_with_hac_on_correlated_residuals():
    rng = np.random.default_rng(5)
    n = 30000
    A = np.column_stack([np.ones(n), np.sin(np.arange(n) / 500.0)])
    e = np.convolve(rng.standard_normal(n + 99), np.ones(100) / 10, mode="valid")
    y = A @ [1.0, 2.0] + e
    est = LeastSquares().fit(A, y)
    hac = parameter_uncertainty("hac", est, RegressionData.from_rows(A, y, _index(n)))
    boot = parameter_uncertainty("bootstrap", est, RegressionData.from_rows(A, y, _index(n)), replicates=400)
    assert boot.std == pytest.approx(hac.std, rel=0.2)
    assert np.all(hac.std > 3 * est.std_)  # correlation time ~100 samples


@pytest.mark.parametrize("estimator", ["ols", "wls"])
def test_jackknife_is_the_spread_of_the_delete_one_block_refits(estimator):
    """CR3 by definition: refit with each block of 2 L steps left out; the covariance is the sum of
    the outer products of the changes. The closed form (Woodbury) must equal the refits."""
    rng = np.random.default_rng(11)
    n, L = 3000, 60
    g = np.repeat([0, 1], n // 2)
    step = np.tile(np.arange(n // 2), 2)
    A = np.column_stack([np.ones(n), np.sin(step / 40.0) * (1 + g), np.cos(step / 97.0) ** 3])
    noise = np.convolve(rng.standard_normal(n + 29), np.ones(30) / 5, mode="valid") * np.where(g == 0, 0.1, 1.0)
    y = A @ [1.0, -2.0, 0.5] + noise
    index = RowIndex(g, ("a", "b"), np.zeros(n, dtype=np.int64), step)
    est = make_estimator(estimator).fit(A, y, groups=g)
    jk = parameter_uncertainty("jackknife", est, RegressionData.from_rows(A, y, index), bandwidth=L)
    w = np.asarray(est.weights_, float)
    sw = np.sqrt(w if w.size == n else np.ones(n))
    full = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)[0]
    deltas = []
    for b in np.unique(step // (2 * L)):
        keep = step // (2 * L) != b
        deltas.append(full - np.linalg.lstsq(A[keep] * sw[keep, None], y[keep] * sw[keep], rcond=None)[0])
    d = np.array(deltas)
    np.testing.assert_allclose(jk.cov, d.T @ d, rtol=1e-8, atol=1e-14)
    assert jk.details["blocks"] == len(deltas) and jk.details["block_steps"] == 2 * L
    assert 0 < jk.details["max_block_leverage"] < 0.5 and not jk.warnings


def test_jackknife_warns_when_one_block_carries_a_direction():
    """A column excited in one short burst only: that block's leverage is near 1 and the std rests on
    it; the jackknife says so."""
    rng = np.random.default_rng(2)
    n = 4000
    burst = np.zeros(n)
    burst[100:160] = 1.0
    A = np.column_stack([np.ones(n), burst])
    y = A @ [1.0, 2.0] + 0.1 * rng.standard_normal(n)
    est = LeastSquares().fit(A, y)
    jk = parameter_uncertainty("jackknife", est, RegressionData.from_rows(A, y, _index(n)), bandwidth=100)
    assert jk.details["max_block_leverage"] > 0.9
    assert jk.warnings and "1 are determined by one block" in jk.warnings[0] and np.all(np.isfinite(jk.std))


@pytest.fixture(scope="module")
def slip_log():
    settings = replace(SimulationSettings(plant=PlantSettings().ideal()), slip=SLIP_SCENARIO)
    slipped = simulate("identification", settings=settings, seed=1)
    clean = simulate("identification", settings=SimulationSettings(plant=PlantSettings().ideal()), seed=1)
    return (Log.from_frame(slipped.log_frame(), sidecar=slipped.sidecar()),
            Log.from_frame(clean.log_frame(), sidecar=clean.sidecar()))


def test_robust_on_a_slip_log_without_slip_detection(slip_log):
    """The full --slip scenario (torque bursts, with and without slip), slip detection off: the
    robust estimator stays within 2 % of the slip-free twin where ols does not."""
    slipped, clean = slip_log
    twin = identify(clean, settings=IdentificationSettings.from_flat(estimator="ols"))
    blind = dict(slip_threshold=math.inf, max_relative_std=math.inf)
    names = ("m_ch", "C_ch", "d_vw", "d_cw")

    def worst(ident):
        return max(abs(getattr(ident.parameters, n) / getattr(twin.parameters, n) - 1) for n in names)

    robust = identify(slipped, settings=IdentificationSettings.from_flat(estimator="robust", **blind))
    ols = identify(slipped, settings=IdentificationSettings.from_flat(estimator="ols", **blind))
    assert worst(robust) < 0.02 < worst(ols)
    assert robust.downweighted_rows > 100


def test_uncertainty_outputs_and_classic_is_eq25(slip_log):
    _, clean = slip_log
    classic = identify(clean, settings=IdentificationSettings.from_flat(estimator="ols", uncertainty="classic"))
    hac = identify(clean, settings=IdentificationSettings.from_flat(estimator="ols", uncertainty="hac"))
    assert classic.std == pytest.approx(classic.std_classic)
    assert hac.parameters.to_vector() == pytest.approx(classic.parameters.to_vector())
    # the chassis std grows (correlated residuals), the steering std shrinks (no more pooled sigma)
    assert hac.std["m_ch"] > 3 * classic.std["m_ch"] and hac.std["d_cl"] < classic.std["d_cl"]
    low, high = hac.ci95("m_ch")
    assert low < hac.parameters.m_ch < high and high - low == pytest.approx(2 * 1.959964 * hac.std["m_ch"])
    corr = np.array(hac.correlation.matrix)
    assert np.allclose(corr, corr.T) and np.allclose(np.diag(corr), 1) and np.all(np.abs(corr) <= 1 + 1e-9)
    assert hac.uncertainty.method == "hac" and hac.uncertainty.bandwidth_steps >= 50


def test_interval_quantiles_equal_scipy_stats():
    """Uncertainty.quantile takes our normal and Student's t quantiles (no scipy import,
    agvdyn.identification._student_t): stats.norm.ppf's and stats.t.ppf's values to a few ulps and
    1e-12, also for infinite degrees of freedom."""
    from scipy import stats

    from agvdyn.identification.uncertainty import Uncertainty, UncertaintyMethod

    cov = np.eye(4)
    normal = Uncertainty(UncertaintyMethod.JACKKNIFE, cov).quantile(0.9)
    assert np.allclose(normal, np.full(4, stats.norm.ppf(0.95)), rtol=1e-15, atol=0)
    dof = np.array([0.5, 3.3, 40.0, np.inf])
    student = Uncertainty(UncertaintyMethod.JACKKNIFE, cov, dof=dof).quantile()
    assert np.allclose(student, stats.t.ppf(0.975, np.maximum(dof, 1.0)), rtol=1e-12, atol=0)
