"""The searched values' uncertainty in the estimates' std (issue 30, :mod:`agvdyn.identification.search_uncertainty`):
a searched delay moves the inertias, so their std must include how far they move over the delay's interval."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agvdyn.identification import UnidentifiableError, identify
from agvdyn.identification.model_search import DELAY, model_identification
from agvdyn.identification.search_uncertainty import SearchSpread, with_spread
from agvdyn.identification.settings import IdentificationSettings
from agvdyn.model_spec import DELAY_RANGE, ModelSpec
from agvdyn.platform import PROTOTYPE
from test_model_selection import _short_log

DT = 0.002


@pytest.fixture(scope="module")
def lagged():
    """A 65 s log of the model plant whose torque columns lag the angles by 3 samples, its delay searched."""
    log = _short_log(0, 3, model_plant=True)
    return log, model_identification(log, PROTOTYPE, model=ModelSpec(delay="auto"))


def _at(log, delay: float, settings: IdentificationSettings = IdentificationSettings()):
    return identify(log, PROTOTYPE, keep_blocks=False, model=ModelSpec(delay=delay), settings=settings)


def test_std_adds_the_estimates_move_over_the_delays_interval(lagged):
    """Against fits at the interval's ends made through the public API: each estimate's added std is its
    largest move from the fit at the found delay, and its std the root sum of squares of that and the
    std the fit at the found delay reports."""
    log, fit = lagged
    ident = fit.identification
    x, (lo, hi) = ident.model.delay, fit.intervals[DELAY]
    assert lo < x < hi and math.isfinite(ident.delay_std_s)
    centre = _at(log, x)
    ends = [_at(log, min(max(e, DELAY_RANGE[0]), DELAY_RANGE[1])) for e in (lo, hi)]
    assert set(ident.search_std) == set(centre.std)
    for n, s in centre.std.items():
        moved = max(abs(getattr(e.parameters, n) - getattr(centre.parameters, n)) for e in ends)
        assert ident.search_std[n] == pytest.approx(moved, rel=1e-6, abs=1e-12)
        assert ident.std[n] == pytest.approx(math.hypot(s, moved), rel=1e-6)
        assert getattr(ident.parameters, n) == getattr(centre.parameters, n)
    # the delay moves the steering inertias (C_l -8 % for 3 samples taken as 0) far more than the chassis'
    relative = {n: v / getattr(ident.parameters, n) for n, v in ident.search_std.items()}
    assert relative["C_l"] > 10 * relative["m_ch"] and relative["C_l"] > 0.001
    entry = ident.to_json_dict()["parameters"]["C_l"]
    assert entry["std"] == ident.std["C_l"] and entry["std_search"] == ident.search_std["C_l"]


def test_correlation_stays_a_correlation_matrix(lagged):
    corr = lagged[1].identification.correlation
    r = np.asarray(corr.matrix)
    assert np.allclose(r, r.T) and np.all(np.diag(r) == 1.0) and np.all(np.abs(r) <= 1.0)
    assert np.linalg.eigvalsh(r).min() > -1e-5


def test_a_delay_on_its_bound_spreads_over_the_range_side_it_has():
    """An effect-free log, range (2, 20) ms: the delay sits on its lower bound with an unbounded std; the
    estimates' std then cover the move from the bound to where the profile rises (finite, never below
    the conditional std)."""
    log = _short_log(0, model_plant=True)
    fit = model_identification(log, PROTOTYPE, model=ModelSpec(delay="auto", delay_range=(0.002, 0.02)))
    ident = fit.identification
    assert ident.delay_std_s == math.inf
    centre = _at(log, ident.model.delay)
    assert ident.search_std and all(math.isfinite(v) and v >= 0 for v in ident.search_std.values())
    assert all(ident.std[n] >= s for n, s in centre.std.items())


def test_an_estimate_the_spread_makes_too_uncertain_is_refused_by_name(lagged):
    """A spread that puts C_l's std above max_relative_std of its value (and y_c's above the platform's
    half-diagonal would alike): refused by name; with unexcited='report' a warning and the wide std."""
    ident = lagged[1].identification
    spread = SearchSpread({DELAY: {"C_l": 0.6 * ident.parameters.C_l, "m_ch": 1e-3 * ident.parameters.m_ch}})
    with pytest.raises(UnidentifiableError, match=r"searched delay_s.*\['C_l'\]"):
        with_spread(ident, spread)
    reported = with_spread(dataclasses.replace(ident, settings=ident.settings.replace(unexcited="report")), spread)
    assert [w for w in reported.warnings if w.startswith("weakly excited with the searched delay_s")][0].count("C_l")
    assert reported.std["C_l"] == pytest.approx(math.hypot(ident.std["C_l"], 0.6 * ident.parameters.C_l))
    assert reported.search_std == {"C_l": 0.6 * ident.parameters.C_l, "m_ch": 1e-3 * ident.parameters.m_ch}
