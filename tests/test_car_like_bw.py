"""B_w from car-like data (issue 11): the car-like experiment, ``identify --fix none`` on it, the
refusal when the car-like motion does not determine B_w, and why the default plant cannot meet
the criterion (steering-unit masses over the contact point are indistinguishable from B_w)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from agvdyn.identification import UnidentifiableError, identify
from agvdyn.io import Log
from agvdyn.montecarlo import model_plant
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE
from agvdyn.preflight import preflight
from agvdyn.simulation import SimulationSettings, simulate
from agvdyn.trajectories import (
    Limits,
    Trajectory,
    alignment,
    car_like_experiment,
    check_limits,
    experiment,
    identification_sequence,
    lane_change,
)
from agvdyn.trajectories.planner import NoiseLevels, PlanSettings, evaluate_sequence

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics

#: The model plant's noise: the planner's default levels grow with acceleration, calibrated on the
#: default plant's model error over the identification motions (docs/planning.md); the car-like
#: motion is beyond that range, and these predictions describe the plant equal to the model.
MODEL_NOISE = PlanSettings(noise=NoiseLevels.constant())

TRUTH = dict(zip(PARAMETER_NAMES, PAPER_PARAMETERS.to_vector()))


@pytest.fixture(scope="module")
def car_like():
    return car_like_experiment()


def _with_sequence(traj: Trajectory) -> Trajectory:
    seq = identification_sequence()
    return Trajectory(seq.segments + traj.segments, seq.geometry, seq.sample_time, "both")


def _logs(experiments, plant, seed: int) -> list[Log]:
    settings = replace(SimulationSettings(), plant=plant)
    out = []
    for exp in experiments:
        result = simulate(exp, settings=settings, seed=seed)
        out.append(Log.from_frame(result.log_frame(), sidecar=result.sidecar()))
    return out


def test_car_like_experiment_within_limits_small_floor_and_predicted_bw_std_below_3_percent(car_like):
    """The shipped experiment: within 0.9 of the limits, on 2.6 m x 3.1 m, 127 s; with the
    identification sequence its predicted std of B_w is <= 3 % (2.8 %), for any centre of the turns
    from 0 to 0.45 rad. Without its fast rotation, or with the lane change instead of it, B_w is not determined
    (predicted std > 10 %): the rotation's yaw inertia is half of B_w's signature."""
    assert experiment("car-like").duration == pytest.approx(car_like.duration)
    report = check_limits(car_like, PAPER_PARAMETERS, Limits())
    assert all(report.peaks[k] <= 0.9 * report.limits[k] + 1e-9 for k in report.peaks)
    floor = car_like.floor_space()
    assert floor.length < 3.0 and floor.width < 3.2 and 100 < car_like.duration < 140
    for centre in (0.0, 0.45):
        other = evaluate_sequence(_with_sequence(car_like_experiment(centre=centre)), estimate_bw=True,
                                  settings=MODEL_NOISE)
        assert other.relative_std["B_w"] <= 0.031
    assert {s.name for s in car_like.segments} == {"align", "rotation", "lane_change"}
    both = evaluate_sequence(_with_sequence(car_like), estimate_bw=True, settings=MODEL_NOISE)
    assert both.relative_std["B_w"] <= 0.03
    assert max(v for k, v in both.relative_std.items() if k != "B_w") < 0.03
    to_turns = alignment(np.zeros(2), car_like.segments[3].alpha[0])
    turns_only = Trajectory((to_turns, *car_like.segments[3:]), PROTOTYPE, car_like.sample_time, "turns")
    assert evaluate_sequence(_with_sequence(turns_only), estimate_bw=True,
                             settings=MODEL_NOISE).relative_std["B_w"] > 0.1
    assert evaluate_sequence(_with_sequence(lane_change()), estimate_bw=True,
                             settings=MODEL_NOISE).relative_std["B_w"] > 0.1


def test_identify_fix_none_on_car_like_data_finds_bw_within_10_percent_on_the_model_plant(car_like):
    """Sequence + car-like experiment on the plant equal to the model (rigid tyres, no neglected
    effects): all eleven parameters, B_w within 10 % (seeds 1-10: -5.7 to +3.5 %, std 3.2-4.4 %),
    its std honest (error below 3 std), the other ten within 5 % (measured: 1.8 %). ~5 s."""
    logs = _logs(["identification", car_like], model_plant(SimulationSettings().plant), seed=2)
    ident = identify(logs, fixed={}, keep_blocks=False)
    est = dict(zip(PARAMETER_NAMES, ident.parameters.to_vector()))
    err = {n: est[n] / TRUTH[n] - 1 for n in PARAMETER_NAMES}
    assert ident.fixed == ()
    assert abs(err["B_w"]) < 0.10 and ident.std["B_w"] < 0.06 * TRUTH["B_w"]
    assert abs(est["B_w"] - TRUTH["B_w"]) < 3 * ident.std["B_w"]
    assert max(abs(v) for k, v in err.items() if k != "B_w") < 0.05, err
    assert any("B_w" in w and "determined by the data" in w for w in ident.warnings)
    check = preflight(logs, PROTOTYPE, fixed={})
    assert check.ready and {e.name: e.status for e in check.excitation}["B_w"] == "ok"


def test_the_car_like_experiment_alone_determines_all_eleven(car_like):
    """Its alignments at rest steer both sides, so the experiment alone identifies all eleven on the
    model plant (seeds 1-5: B_w -5.9 to -0.8 %, std 3.1-4.6 %; the others within 3.3 %). ~3 s."""
    ident = identify(_logs([car_like], model_plant(SimulationSettings().plant), seed=1), fixed={}, keep_blocks=False)
    est = dict(zip(PARAMETER_NAMES, ident.parameters.to_vector()))
    err = {n: est[n] / TRUTH[n] - 1 for n in PARAMETER_NAMES}
    assert abs(err["B_w"]) < 0.10 and abs(est["B_w"] - TRUTH["B_w"]) < 3 * ident.std["B_w"]
    assert max(abs(v) for k, v in err.items() if k != "B_w") < 0.05, err


def test_too_little_car_like_motion_is_refused_naming_bw():
    """Sequence + the lane change: B_w's predicted std is far above 10 %: refused, naming B_w (with
    its predicted std), m_ch and C_ch, and the car-like experiment."""
    logs = _logs(["identification", "lane-change"], model_plant(SimulationSettings().plant), seed=1)
    with pytest.raises(UnidentifiableError, match="variance inflation") as info:
        identify(logs, fixed={}, keep_blocks=False)
    deps = {d.name: d for d in info.value.dependencies}
    assert "B_w" in deps and deps["B_w"].relative_std > 0.1
    assert {"m_ch", "C_ch"} <= set(deps)
    assert "car-like" in str(info.value) and "B_w" in str(info.value).splitlines()[-1]
    check = preflight(logs, PROTOTYPE, fixed={})
    assert not check.ready and {e.name: e.status for e in check.excitation}["B_w"] == "weak"


def test_steering_unit_masses_over_the_contact_point_are_identified_as_wheel_inertia(car_like):
    """A steering unit of mass m_u whose centre of mass lies over the contact point moves like the
    contact point, i.e. like a wheel of inertia m_u r^2: the rolling vehicle is exactly the model
    with B_w + m_u r^2, m_ch - 4 m_u, C_l - 2 m_u a^2, C_r - 2 m_u a^2 and
    C_ch - 4 m_u ((l/2)^2 + (b/2 + a)^2 - a^2). Car-like data find those (B_w +248 % against the
    wheels' own inertia): no excitation on the floor can separate the two, only the lifted-wheel test."""
    plant = replace(model_plant(SimulationSettings().plant), steering_masses=True)
    logs = _logs(["identification", car_like], plant, seed=1)
    ident = identify(logs, fixed={}, keep_blocks=False)
    est = dict(zip(PARAMETER_NAMES, ident.parameters.to_vector()))
    g, m_u = PROTOTYPE, 30.0
    equivalent = dict(TRUTH, B_w=TRUTH["B_w"] + m_u * g.r**2, m_ch=TRUTH["m_ch"] - 4 * m_u,
                      C_l=TRUTH["C_l"] - 2 * m_u * g.a**2, C_r=TRUTH["C_r"] - 2 * m_u * g.a**2,
                      C_ch=TRUTH["C_ch"] - 4 * m_u * ((g.l / 2) ** 2 + (g.b / 2 + g.a) ** 2 - g.a**2))
    err = np.array([est[n] / equivalent[n] - 1 for n in PARAMETER_NAMES])
    assert np.abs(err).max() < 0.05, dict(zip(PARAMETER_NAMES, err.round(4)))
    assert est["B_w"] > 3 * TRUTH["B_w"]
