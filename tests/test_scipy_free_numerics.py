"""The numerics that replace scipy on the default identification path (issue 28), against scipy
itself: Student's t and normal quantiles (the intervals), the triangular solve (the estimators and
the variance inflation) and the FFT autocovariance (the correlation time)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.fft
import scipy.linalg
import scipy.special
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.identification._student_t import normal_quantile, student_t_quantile
from agvdyn.identification.correlation import autocovariance_sums, next_fast_length
from agvdyn.identification.estimators import solve_upper_triangular

#: Degrees of freedom log-uniform over [1, 1e7] and probabilities over [0.5, 0.9999].
DOF = st.floats(0.0, math.log(1e7)).map(math.exp)
PROBABILITY = st.floats(0.5, 0.9999)


@settings(max_examples=400, deadline=None)
@given(dof=DOF, p=PROBABILITY)
def test_student_t_quantile_is_scipys(dof, p):
    """1e-12 relative; near p = 1/2 scipy's own stdtrit is off by ~1e-16 absolute (at p = 0.5 + 1e-9
    its value is 3e-8 relative from the true one, which the series below confirm), hence the small
    absolute allowance."""
    ours, ref = student_t_quantile(dof, p), float(scipy.special.stdtrit(dof, p))
    assert abs(ours - ref) <= 1e-12 * abs(ref) + 1e-15, (dof, p, ours, ref)


@settings(max_examples=200, deadline=None)
@given(dof=DOF, p=PROBABILITY)
def test_student_t_quantile_is_the_inverse_of_scipys_distribution(dof, p):
    """F(t(p)) = p to the distribution function's own rounding (a relative error of 1e-12 in t would
    move p by up to 1e-13), and the quantile is odd: t(1 - p) = -t(p). scipy's stdtr itself is off by up
    to ~9e-15 near p = 1/2 (dof = 1, p = 0.5005126761178511: our t equals tan(pi (p - 1/2)) to the last
    bit, 0.5 + atan(t) / pi - p = 0, stdtr(1, t) - p = 8.9e-15), hence 1e-14."""
    t = student_t_quantile(dof, p)
    assert abs(float(scipy.special.stdtr(dof, t)) - p) <= 1e-14  # scipy.stdtrit: up to 1.3e-13
    if dof == 1.0:  # the Cauchy distribution's closed form
        assert abs(0.5 + math.atan(t) / math.pi - p) <= 2e-15
    assert student_t_quantile(dof, 1.0 - p) == pytest.approx(-t, rel=1e-12, abs=1e-15) or 1.0 - p == p


@pytest.mark.parametrize("dof", [1.0, 1.7, 3.0, 25.0, 1e3, 1e6])
def test_student_t_quantile_near_the_centre_is_the_density_at_zero(dof):
    """For p -> 1/2, t = (p - 1/2) / f(0) (1 + O(t^2)): the relative accuracy where scipy's is lost."""
    f0 = math.exp(math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2)) / math.sqrt(dof * math.pi)
    for dp in (1e-15, 1e-12, 1e-9):
        assert student_t_quantile(dof, 0.5 + dp) == pytest.approx(((0.5 + dp) - 0.5) / f0, rel=1e-8)


def test_student_t_quantile_closed_forms_and_limits():
    p = np.array([0.6, 0.9, 0.975, 0.9999])
    cauchy, two = student_t_quantile(1.0, p), student_t_quantile(2.0, p)  # their distribution functions:
    assert np.all(np.abs(0.5 + np.arctan(cauchy) / np.pi - p) <= 2.3e-16)
    assert np.all(np.abs(0.5 + two / (2 * np.sqrt(2 + two * two)) - p) <= 2.3e-16)
    assert np.array_equal(student_t_quantile(np.inf, p), normal_quantile(p))
    assert student_t_quantile(5.0, 0.5) == 0.0
    assert student_t_quantile(5.0, 1.0) == math.inf and student_t_quantile(5.0, 0.0) == -math.inf
    assert math.isnan(student_t_quantile(math.nan, 0.975)) and math.isnan(student_t_quantile(4.0, math.nan))
    out = student_t_quantile(np.array([[3.0], [30.0]]), np.array([0.9, 0.975]))  # broadcast
    assert out.shape == (2, 2) and np.allclose(out, scipy.special.stdtrit([[3.0], [30.0]], [0.9, 0.975]), rtol=1e-12)


@pytest.mark.parametrize("dof, p", [(0.0, 0.9), (0.5, 0.9), (-1.0, 0.9), (3.0, 1.5), (3.0, -0.1)])
def test_student_t_quantile_refuses_bad_arguments(dof, p):
    with pytest.raises(ValueError, match="dof|p ="):
        student_t_quantile(dof, p)


def test_normal_quantile_is_scipys_ndtri():
    p = np.concatenate([np.linspace(1e-9, 1 - 1e-9, 20001), [1e-300, 1e-100, 1e-20, 0.025, 0.975]])
    ref = scipy.special.ndtri(p)
    assert np.all(np.abs(normal_quantile(p) - ref) <= 1e-15 * np.abs(ref) + 1e-300)  # a few ulps
    assert normal_quantile(0.0) == -math.inf and normal_quantile(1.0) == math.inf


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 16), decades=st.floats(0, 8), seed=st.integers(0, 2**32 - 1))
def test_triangular_solve_is_scipys(n, decades, seed):
    """The estimators' R^-1 [Q^T y, I] within a few ulps of scipy's solve_triangular (column norms
    over ``decades`` decades: an ill-conditioned R)."""
    rng = np.random.default_rng(seed)
    R = np.linalg.qr(rng.standard_normal((4 * n + 4, n)) * np.logspace(0, decades, n), mode="r")
    rhs = np.column_stack([rng.standard_normal(n), np.eye(n)])
    ours, ref = solve_upper_triangular(R, rhs), scipy.linalg.solve_triangular(R, rhs)
    scale = np.abs(ref).max(axis=0)
    assert np.all(np.abs(ours - ref) <= 1e-15 * np.linalg.cond(R) * scale)


def test_triangular_solve_refuses_a_singular_factor():
    R = np.triu(np.ones((3, 3)))
    R[1, 1] = 0.0
    with pytest.raises(np.linalg.LinAlgError):
        solve_upper_triangular(R, np.eye(3))


def test_next_fast_length_is_scipys():
    for n in [*range(1, 5000), 65537, 1_000_007, 123_456_789]:
        assert next_fast_length(n) == scipy.fft.next_fast_len(n, real=True), n


@pytest.mark.parametrize("n, p", [(1, 1), (7, 2), (1000, 3), (4099, 1)])
def test_autocovariance_sums_are_the_lagged_products(n, p):
    """Bit for bit scipy.fft's double-precision result, and the direct sums to round-off."""
    rng = np.random.default_rng(n)
    x = rng.standard_normal((n, p))
    ours = autocovariance_sums(x)
    size = scipy.fft.next_fast_len(2 * n, real=True)
    f = scipy.fft.rfft(x.T, size, axis=1)
    assert np.array_equal(ours, scipy.fft.irfft(f * np.conj(f), size, axis=1)[:, :n].T)
    direct = np.array([[x[: n - lag, j] @ x[lag:, j] for j in range(p)] for lag in range(n)])
    assert np.allclose(ours, direct, rtol=0, atol=1e-12 * n)
