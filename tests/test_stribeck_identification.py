"""Breakaway (Stribeck) friction in the identification (issue 30) on our plant's stick-slip logs.

What the data show (docs/identification.md, "Breakaway friction"):

* MATCHED filtering (torques and friction entries through the angles' filter too, so every entry of
  both sides of eq. 19 sees two filters) with ``steering_guard`` 12 removes the steering-inertia bias
  that breakaway friction gives the default PARALLEL rows (C_r +10..+14 %, d_vr -11..-14 % at 1.3x,
  w_s 0.05: the rows next to each stick phase);
* the wheels' breakaway level d_sw is determined by slow chassis rows (``stiction_threshold`` 0.005):
  within 5 % at w_s 0.05 and 0.8 % at w_s 0.1 over 30 logs (1.2-1.5x, 5 seeds), not at w_s 0.02;
* the steering groups' d_sl, d_sr are not determined by rate-domain rows: a passive steering joint
  sticks at every reversal and crosses its Stribeck region within a few ms at each breakaway, inside
  the 40 rad/s filter's window (not tested here as a number: what the fit returns there is no estimate).
"""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from agvdyn.identification import Filtering, IdentificationSettings, identify
from agvdyn.identification.stretches import MATCHED_COLUMNS, filtered_stretch, stretch_bounds
from agvdyn.io import Log
from agvdyn.model_spec import ModelSpec
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE
from agvdyn.row_rules import Filtering as RuleFiltering
from agvdyn.signals import lowpass
from model_logs import identification_frame

P = PAPER_PARAMETERS
SHORT = {"steer_left": 10.0, "steer_right": 10.0, "straight": 10.0, "rotation": 10.0}
FREE = [i for i, n in enumerate(PARAMETER_NAMES) if n != "B_w"]
#: The rows for stick-slip logs (measured, docs/identification.md): MATCHED filtering, the steering guard
#: 12 / cutoff = 300 ms, slow chassis rows kept (0.005 m/s, rad/s) for the wheels' breakaway level.
STICK_SLIP = dict(filtering="matched", steering_guard=12.0, stiction_threshold=0.005)
#: Breakaway 1.3 x sliding, Stribeck velocity 0.05 rad/s in all three joint groups (benchmarks/effect_logs.py).
RATIO, W_S = 1.3, 0.05


def _simulated(ratio: float, w_s: float, seed: int = 0) -> Log:
    from agvdyn.simulation import SimulationSettings, simulate

    settings = SimulationSettings()
    if ratio != 1.0:
        settings = replace(settings, plant=settings.plant.with_breakaway("all", ratio, w_s))
    result = simulate("identification", settings=settings, seed=seed)
    return Log.from_frame(result.log_frame(), sidecar=result.sidecar())


@pytest.fixture(scope="module")
def breakaway_log() -> Log:
    return _simulated(RATIO, W_S)


@pytest.fixture(scope="module")
def effect_free_log() -> Log:
    return _simulated(1.0, W_S)


def _error(ident, name: str) -> float:
    return getattr(ident.parameters, name) / getattr(P, name) - 1


# --- MATCHED filtering ---------------------------------------------------------------------------------------


def test_matched_is_a_filtering_choice():
    assert Filtering is RuleFiltering and Filtering("matched") is Filtering.MATCHED
    assert IdentificationSettings.from_flat(filtering="matched").to_dict()["filtering"] == "matched"
    with pytest.raises(ValueError):
        IdentificationSettings.from_flat(filtering="twice")


def test_matched_filtering_filters_torques_and_friction_entries_once_more():
    """MATCHED changes the torques and the friction entries ``tanh`` only (and the model's channels):
    inside the stretch (away from the filter's edge transients) they are the angles' low-pass of
    PARALLEL's (the filters and the torque alignment are linear and time invariant: they commute; what
    is left, 1e-6 of the values, is the odd-extension padding of the two orders); the other entries of
    Theta, the rates and the edge rows are PARALLEL's to the last bit."""
    frame, _ = identification_frame(SHORT)
    log = Log.from_frame(frame, sidecar={"torque_lead": 0.5})
    parallel, matched = (IdentificationSettings.from_flat(filtering=f) for f in ("parallel", "matched"))
    model = ModelSpec(friction="stribeck", stribeck_velocities=(0.05, 0.06, 0.08))
    (a, b), *_ = stretch_bounds(log.t, log.alpha, log.beta, parallel)[0]
    p = filtered_stretch(PROTOTYPE, log, a, b, parallel, model=model)
    m = filtered_stretch(PROTOTYPE, log, a, b, matched, model=model)
    friction = MATCHED_COLUMNS[MATCHED_COLUMNS < 21]
    linear = np.setdiff1d(np.arange(21), friction)
    assert np.array_equal(m.signals[:, linear], p.signals[:, linear]) and np.array_equal(m.q_dot, p.q_dot)
    assert np.array_equal(m.edge, p.edge) and np.array_equal(m.slip, p.slip)
    inner = ~p.edge
    for once, twice in ((p.torque, m.torque), (p.signals[:, friction], m.signals[:, friction]), (p.extra, m.extra)):
        expected = lowpass(once, p.dt, parallel.rows.filter)
        scale = np.abs(once[inner]).max()
        assert np.abs(twice[inner] - expected[inner]).max() < 1e-5 * scale
        assert np.abs(twice[inner] - once[inner]).max() > 1e-3 * scale  # not the same channels


def test_matched_filtering_keeps_exact_model_data_exact():
    """On a log that follows the paper's model exactly (smooth motion, no stick-slip) MATCHED recovers
    the parameters like PARALLEL: every entry of both sides sees two filters (torques filtered once
    more alone biased d_vr by 1.6 %: the Coulomb steps then see two filters against one)."""
    frame, _ = identification_frame(SHORT)
    log = Log.from_frame(frame)
    for filtering in ("parallel", "matched"):
        ident = identify(log, PROTOTYPE, settings=IdentificationSettings.from_flat(filtering=filtering),
                         keep_blocks=False)
        error = np.abs(ident.parameters.to_vector()[FREE] / P.to_vector()[FREE] - 1)
        assert error.max() < 1e-3, (filtering, error)


# --- breakaway friction on our plant -------------------------------------------------------------------------


def test_default_rows_bias_the_steering_under_breakaway(breakaway_log):
    """The reference the fix is measured against: with the default rows (PARALLEL, steering guard 4)
    breakaway friction biases C_r and d_vr by 10-14 % (5 seeds), several of their std."""
    ident = identify(breakaway_log, PROTOTYPE, keep_blocks=False)
    assert max(abs(_error(ident, "C_r")), abs(_error(ident, "d_vr"))) > 0.08


def test_the_row_check_warns_where_breakaway_biases_the_default_rows(breakaway_log, effect_free_log, tmp_path):
    """identify(check_rows=True), the identify command and the report refit on the stick-slip rows: under
    breakaway 1.3x the steering parameters move by 3.8 combined std (seed 0; 2.9-3.3 on seeds 1-2), on the
    effect-free log by 1.1 (at most 1.9 on 16 logs of both plants), against a threshold of 2.5. A warning
    naming d_vr and what to do there, none here, the estimates unchanged; none where the rows already are
    the stick-slip ones; the command's --no-row-check leaves it out, with --model it refits the model."""
    from typer.testing import CliRunner

    from agvdyn.cli import app
    from agvdyn.identification.row_check import row_check_applies

    plain = identify(breakaway_log, PROTOTYPE, keep_blocks=False)
    warned = identify(breakaway_log, PROTOTYPE, keep_blocks=False, check_rows=True)
    assert warned.parameters == plain.parameters
    [said] = [w for w in warned.warnings if w.startswith("the steering parameters depend on the rows")]
    assert "d_vr " in said and "--filtering matched --steering-guard 12" in said
    quiet = identify(effect_free_log, PROTOTYPE, keep_blocks=False, check_rows=True)
    assert not any("depend on the rows" in w for w in quiet.warnings)
    stick = IdentificationSettings.from_flat(filtering="matched", steering_guard=12.0)
    assert not row_check_applies(identify(breakaway_log, PROTOTYPE, keep_blocks=False, settings=stick), stick)
    path, model = tmp_path / "breakaway.parquet", tmp_path / "model.yaml"
    breakaway_log.frame.to_parquet(path)
    model.write_text("model: {friction: stribeck, stribeck_velocities: [0.05, 0.05, 0.05]}\n")
    for flag, expected in (([], True), (["--no-row-check"], False), (["--model", str(model)], True)):
        res = CliRunner().invoke(app, ["identify", str(path), "--out", str(tmp_path / "p.yaml"), "--json", *flag])
        assert res.exit_code == 0, res.output
        assert any("depend on the rows" in w for w in json.loads(res.stdout)["warnings"]) is expected


def test_stribeck_fit_recovers_the_wheels_breakaway_and_the_steering_under_matched_rows(breakaway_log):
    """Stribeck model at the true w_s on MATCHED rows (STICK_SLIP): C_l, C_r within the steering
    tolerance (5 %; 5 seeds at 1.3x, w_s 0.05: C_l -2.4..+1.7 %, C_r -1.3..+1.5 %), d_vr within 5 %
    (-4.5..-0.5 %), the sliding levels within 2 %, m_ch within 0.5 %, and the wheels' static level
    d_sw within 10 % of 1.3 d_cw (-1.5..+1.8 %, std 2 %). The steering groups' d_sl, d_sr are no
    estimates (the module docstring): the plausibility check, which would refuse their negative
    values, is off."""
    model = ModelSpec(friction="stribeck", stribeck_velocities=(W_S,) * 3)
    settings = IdentificationSettings.from_flat(**STICK_SLIP, max_relative_std=math.inf, plausibility=False)
    ident = identify(breakaway_log, PROTOTYPE, model=model, settings=settings, keep_blocks=False)
    for name in ("C_l", "C_r", "d_vr"):
        assert abs(_error(ident, name)) < 0.05, (name, _error(ident, name))
    for name in ("d_cl", "d_cr", "d_cw"):
        assert abs(_error(ident, name)) < 0.02, (name, _error(ident, name))
    assert abs(_error(ident, "m_ch")) < 0.005
    d_sw = RATIO * P.d_cw
    assert ident.extra["d_sw"] == pytest.approx(d_sw, rel=0.10)
    assert 0 < ident.extra_std["d_sw"] < 0.1 * d_sw


def test_stribeck_fit_on_an_effect_free_log_finds_no_wheel_breakaway(effect_free_log):
    """No breakaway (the plant's stiction at the sliding level): d_sw = d_cw within 3 std and 2.5 %
    (w_s 0.1; 5 seeds: +0.1..+0.9 %, std 0.3-0.6 %), and the paper's parameters as the paper model
    gives them on the same rows, within their std."""
    settings = IdentificationSettings.from_flat(**STICK_SLIP, max_relative_std=math.inf, plausibility=False)
    model = ModelSpec(friction="stribeck", stribeck_velocities=(0.1, 0.1, 0.1))
    ident = identify(effect_free_log, PROTOTYPE, model=model, settings=settings, keep_blocks=False)
    paper = identify(effect_free_log, PROTOTYPE, settings=settings, keep_blocks=False)
    assert abs(ident.extra["d_sw"] - P.d_cw) < 3 * ident.extra_std["d_sw"]
    assert ident.extra["d_sw"] == pytest.approx(P.d_cw, rel=0.025)
    for name in ("C_r", "d_vr", "d_cr", "m_ch", "C_ch", "d_vw", "d_cw"):
        change = abs(getattr(ident.parameters, name) - getattr(paper.parameters, name))
        assert change < paper.std[name], (name, change, paper.std[name])
