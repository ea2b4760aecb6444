"""The planner's predicted stds with the model beyond the paper (issue 30): evaluate_sequence(model=)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from agvdyn.model_spec import PAPER_MODEL, ModelParameters, ModelSpec
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE
from agvdyn.trajectories import car_like_experiment, identification_sequence
from agvdyn.trajectories.planner.evaluation import _sequence_rows, evaluate_sequence
from agvdyn.trajectories.planner.settings import PlanSettings

SPECS = [ModelSpec(friction="stribeck", stribeck_velocities=(0.1, 0.1, 0.1)), ModelSpec(delay="auto"),
         ModelSpec(com_offset=True), ModelSpec(friction="stribeck", delay=0.004, com_offset=True)]


@pytest.fixture(scope="module")
def sequence():
    return identification_sequence(PROTOTYPE)


@pytest.fixture(scope="module")
def car_like():
    return car_like_experiment(PROTOTYPE)


def test_paper_model_predicts_the_same(sequence):
    a = evaluate_sequence(sequence)
    b = evaluate_sequence(sequence, model=PAPER_MODEL)
    assert a.std == b.std and a.cond == b.cond


@pytest.mark.parametrize("spec", SPECS, ids=lambda s: s.label)
def test_more_parameters_never_predict_a_smaller_std(sequence, spec):
    """Adding columns to a least-squares problem cannot shrink the others' (sandwich) stds by more than
    rounding: every paper parameter's std is at least the paper model's."""
    a, b = evaluate_sequence(sequence), evaluate_sequence(sequence, model=spec)
    for name, s in a.std.items():
        assert b.std[name] >= s * (1 - 1e-9), (name, s, b.std[name])


def test_held_levels_are_not_estimated(sequence):
    """A level the spec holds has no column (its Coulomb column stays the paper's) and an unbounded std:
    all three held, the paper's parameters are predicted as the paper model's."""
    paper = evaluate_sequence(sequence)
    held = evaluate_sequence(sequence, model=SPECS[0].replace(held=("d_sl", "d_sr", "d_sw")))
    assert {n: held.std[n] for n in paper.std} == pytest.approx(paper.std, rel=1e-12)
    assert all(held.std[n] == math.inf for n in ("d_sl", "d_sr", "d_sw"))
    wheels = evaluate_sequence(sequence, model=SPECS[0].replace(held=("d_sl", "d_sr")))
    assert 0 < wheels.std["d_sw"] < math.inf and wheels.std["d_sl"] == math.inf


def test_stribeck_columns_split_the_coulomb_column(sequence):
    """(1 - e) tanh + e tanh = tanh: the Coulomb and breakaway columns sum to the paper's Coulomb column."""
    settings = PlanSettings()
    A0 = _sequence_rows(sequence, settings)[0]
    spec = SPECS[0]
    A1 = _sequence_rows(sequence, settings, model=ModelParameters(
        PAPER_PARAMETERS, {**{f"d_s{g}": 1.0 for g in "lrw"}, **{f"w_s{g}": 0.1 for g in "lrw"}}, 0.0, spec))[0]
    assert A1.shape[1] == A0.shape[1] + 3
    for k, dc in enumerate((2, 5, 9)):  # d_cl, d_cr, d_cw among the ten
        np.testing.assert_allclose(A1[:, dc] + A1[:, 10 + k], A0[:, dc], atol=1e-12)
    assert np.abs(A1[:, 10:13]).max() > 0.1  # the breakaway columns are not empty


def test_offset_needs_rotation_with_translation(sequence, car_like):
    """x_c is never determined (its column vanishes in every mode); y_c only where the chassis turns
    while it translates (car-like motion): the default sequence has none."""
    spec = ModelSpec(com_offset=True)
    on_sequence = evaluate_sequence(sequence, model=spec)
    assert math.isinf(on_sequence.std["x_c"]) and math.isinf(on_sequence.std["y_c"])
    turning = evaluate_sequence(car_like, model=spec, estimate_bw=False)
    assert math.isinf(turning.std["x_c"])
    assert 0 < turning.std["y_c"] < 0.05


def test_delay_is_predicted_from_the_planned_torque_rate(sequence):
    """The linearised delay column -H^T B u_dot: a finite std well below a sample period."""
    std = evaluate_sequence(sequence, model=ModelSpec(delay="auto")).std["delay_s"]
    assert 0 < std < sequence.sample_time
