"""Undetermined directions are infinite everywhere (issue 26, item 1): the rank test of an
information matrix, stds from it and from covariances, and the places that turn a covariance into a
std (planner predictions, identification uncertainty, estimators, trial fits)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from agvdyn.determinacy import (
    DETERMINACY_TOLERANCE,
    determinacy,
    std_from_covariance,
    std_from_information,
)
from agvdyn.identification.estimators import LeastSquares
from agvdyn.identification.uncertainty import Uncertainty, UncertaintyMethod
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE
from agvdyn.trajectories import Trajectory, identification_sequence, lane_change
from agvdyn.trajectories import planner as pl

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics

#: Column scales as different as the regression's (steering inertias ~0.3, chassis mass ~800).
_SCALES = st.lists(st.floats(-3, 3), min_size=2, max_size=12).map(lambda e: 10.0 ** np.array(e))


@settings(max_examples=40, deadline=None)
@given(scales=_SCALES, seed=st.integers(0, 2**32 - 1))
def test_full_rank_information_gives_the_inverse(scales, seed):
    """A full-rank regressor (random rows, columns scaled by 1e-3..1e3): nothing undetermined, and the
    std is ``sqrt(diag(F^-1))`` (F well conditioned after scaling: inv is exact to ~1e-12 here)."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((200, scales.size)) * scales
    F = A.T @ A
    std, cov, det, warnings = std_from_information(F)
    assert not det.undetermined.any() and not warnings
    np.testing.assert_allclose(std, np.sqrt(np.diag(np.linalg.inv(F))), rtol=1e-8)


@settings(max_examples=40, deadline=None)
@given(scales=_SCALES, seed=st.integers(0, 2**32 - 1), data=st.data())
def test_a_dependent_column_makes_its_group_infinite_and_leaves_the_others(scales, seed, data):
    """Column j a combination of the columns in S: exactly S + {j} are undetermined (inf), every
    other std equals the one of the system without column j (the pseudo-inverse on the determined
    directions; exact algebra, module doc)."""
    p = scales.size
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((200, p)) * scales
    j = data.draw(st.integers(0, p - 1))
    S = data.draw(st.lists(st.sampled_from([i for i in range(p) if i != j]), min_size=1, max_size=p - 1, unique=True))
    coef = rng.uniform(0.5, 2.0, len(S)) * rng.choice([-1, 1], len(S))
    A[:, j] = (A[:, S] / scales[S]) @ coef * scales[j]
    std, _, det, _ = std_from_information(A.T @ A)
    group = set(S) | {j}
    assert set(np.flatnonzero(det.undetermined)) == group
    assert all(math.isinf(std[i]) for i in group)
    rest = [i for i in range(p) if i != j]
    reduced = np.sqrt(np.diag(np.linalg.inv(A[:, rest].T @ A[:, rest])))
    for k, i in enumerate(rest):
        if i not in group:
            assert std[i] == pytest.approx(reduced[k], rel=1e-6)


def test_a_zero_column_is_undetermined():
    A = np.random.default_rng(0).standard_normal((50, 4))
    A[:, 2] = 0.0
    std, _, det, _ = std_from_information(A.T @ A, names=list("abcd"))
    assert det.names(list("abcd")) == ("c",) and math.isinf(std[2]) and np.all(np.isfinite(std[[0, 1, 3]]))


def test_tolerance_separates_singular_from_hardly_determined():
    """A column 1e-4 (relative) away from another is determined; 1e-7 away is not (tolerance 1e-12 on
    the eigenvalue, i.e. ~1e-6 on the distance of unit columns, as the identification's QR test)."""
    rng = np.random.default_rng(1)
    A = rng.standard_normal((400, 3))
    for gap, undetermined in ((1e-4, False), (1e-7, True)):
        B = A.copy()
        B[:, 2] = A[:, 0] + gap * rng.standard_normal(400)
        assert determinacy(B.T @ B).undetermined[[0, 2]].all() == undetermined
    assert DETERMINACY_TOLERANCE == 1e-12


def test_negative_or_non_finite_variance_is_infinite_with_a_warning():
    cov = np.diag([4.0, -1e-9, np.nan, 0.25])
    std, warnings = std_from_covariance(cov, ["C_l", "d_vl", "d_cl", "m_ch"])
    assert std[0] == 2.0 and std[3] == 0.5
    assert math.isinf(std[1]) and math.isinf(std[2])
    assert len(warnings) == 2 and warnings[0].startswith("d_vl") and warnings[1].startswith("d_cl")


def test_uncertainty_and_estimator_never_clip_a_negative_variance_to_zero():
    """The old ``sqrt(max(diag, 0))`` turned a negative variance into a zero std."""
    unc = Uncertainty(UncertaintyMethod.HAC, np.diag([1.0, -4.0]))
    assert unc.std[0] == 1.0 and math.isinf(unc.std[1])
    rng = np.random.default_rng(2)
    A = rng.standard_normal((30, 2))
    est = LeastSquares().fit(A, A @ [1.0, 2.0] + 0.1 * rng.standard_normal(30))
    est.cov_ = np.diag([1.0, -1.0])
    assert math.isinf(est.std_[1])


def test_planner_undetermined_group_is_infinite_on_any_machine():
    """B_w free on the default sequence (modes 1, 2s, 4: Table 1 leaves B_w dependent): the
    information matrix is exactly singular, and every parameter of the group B_w is a combination
    of (C_l, C_r, m_ch, C_ch, B_w) is infinite; the rest stay finite. The old ``np.linalg.inv``
    returned garbage on some BLAS and a std of 0.0 for B_w."""
    ev = pl.evaluate_sequence(identification_sequence(), PAPER_PARAMETERS, estimate_bw=True)
    group = {"C_l", "C_r", "m_ch", "C_ch", "B_w"}
    assert {n for n, s in ev.std.items() if math.isinf(s)} == group
    assert all(0 < s < math.inf for n, s in ev.std.items() if n not in group)
    both = Trajectory(identification_sequence().segments + tuple(lane_change().segments), PROTOTYPE)
    hard = pl.evaluate_sequence(both, PAPER_PARAMETERS, estimate_bw=True)
    assert 0.2 < hard.relative_std["B_w"] < math.inf  # hardly determined, but determined


def test_predicted_relative_std_of_a_singular_system_is_infinite():
    from agvdyn.identification.excitation import predicted_relative_std
    from agvdyn.identification.normal import RegressionData

    rng = np.random.default_rng(3)
    A = rng.standard_normal((100, 3))
    A[:, 2] = A[:, 0] - A[:, 1]
    data = RegressionData(A=A, y=A @ [1.0, 2.0, 3.0], group=np.zeros(100, dtype=np.int64), group_names=("x_ch",),
                          group_rows=np.array([100]), n_rows=100, pseudo=False, free=(0, 1, 2),
                          theta_fixed=np.zeros(3))
    rel = predicted_relative_std(data, np.array([1.0, 2.0, 3.0]), ["m_ch", "C_ch", "d_vw"])
    assert all(math.isinf(v) for v in rel.values())
