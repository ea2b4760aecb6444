"""The single-axis (lifted-wheel) experiment of sec. 7: planning, simulation and the identification of B_w."""
from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from agvdyn.cli import app
from agvdyn.identification import experiment_of, identify, identify_lifted
from agvdyn.identification.lifted import LiftedWheelIdentification, is_lifted, lifted_experiment
from agvdyn.io import Log, read_log
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE
from agvdyn.simulation import simulate
from agvdyn.trajectories import Limits, Trajectory, TrajectoryError, check_limits, experiment, lifted_wheel_experiment

P = PAPER_PARAMETERS


def _log(result) -> Log:
    return Log.from_frame(result.log_frame(), sidecar=result.sidecar())


@pytest.fixture(scope="module")
def run():
    return simulate("lifted-wheel", seed=1)


def test_plan_turns_each_wheel_both_ways_from_rest_to_rest():
    traj = experiment("lifted-wheel")
    assert traj.lifted and [s.name for s in traj.segments] == ["lifted_wheel"]
    qd, qdd = traj.joint_motion()
    np.testing.assert_allclose(qd[:, :5], 0.0)  # chassis and steering at rest
    np.testing.assert_allclose(qd[[0, -1], 5:], 0.0, atol=1e-9)
    rates = qd[:, 5:]
    for i in range(4):  # forward, one reversal, backward: three standstills only
        sign = np.sign(rates[np.abs(rates[:, i]) > 1e-9, i])
        assert np.count_nonzero(np.diff(sign)) == 1
    np.testing.assert_allclose(np.gradient(rates, traj.sample_time, axis=0)[1:-1], qdd[1:-1, 5:], atol=0.05)
    report = check_limits(traj, P, Limits())
    assert report.peaks["wheel_speed"] < 20
    u = traj.feedforward(P)  # the wheel rows of eq. (16)-(17): i_G M = B_w a + d_vw v + d_cw tanh(v / eps)
    expected = (P.B_w * qdd[:, 5:] + P.d_vw * qd[:, 5:] + P.d_cw * np.tanh(qd[:, 5:] / 0.01)) / PROTOTYPE.i_G
    np.testing.assert_allclose(u, expected, atol=1e-12)


def test_lifted_and_ground_segments_do_not_mix():
    lifted = lifted_wheel_experiment().segments[0]
    ground = experiment("identification").segments[0]
    with pytest.raises(TrajectoryError, match="mix lifted wheels and ground contact"):
        Trajectory((lifted, ground))


def test_simulated_wheels_turn_without_ground_contact(run):
    np.testing.assert_allclose(run.position[:, :5], 0.0)  # chassis on jacks, steering still
    assert np.abs(run.velocity[:, 5:]).max() > 10
    w = run.work[-1]
    assert abs(w[0] - w[1] - run.energy[-1]) < 1e-3 * w[0]  # motor work = friction work (+ kinetic energy)
    assert run.slip_intervals() == [] and run.tracking()["wheel_speed_rms"].iloc[0] < 0.1
    frame = run.log_frame()
    assert set(frame["segment"].astype(str)) == {"lifted_wheel"}


def test_b_w_within_2_percent_of_the_truth(run):
    log = _log(run)
    assert experiment_of([log]) == "lifted-wheel"
    result = identify_lifted([log], PROTOTYPE)
    assert isinstance(result, LiftedWheelIdentification)
    assert result.B_w == pytest.approx(P.B_w, rel=0.02)
    assert result.values["d_vw"] == pytest.approx(P.d_vw, rel=0.02)
    assert result.values["d_cw"] == pytest.approx(P.d_cw, rel=0.02)
    assert 0 < result.std["B_w"] < 0.01 * P.B_w
    assert min(result.rows.values()) > 5000


def test_recognised_from_the_label_or_told(run, tmp_path):
    log = _log(run)
    assert is_lifted(log) and lifted_experiment([log], None)
    unlabelled = Log.from_frame(run.log_frame().drop(columns="segment"), sidecar=run.sidecar())
    assert not lifted_experiment([unlabelled], "auto")
    assert experiment_of([unlabelled], "lifted-wheel") == "lifted-wheel"
    told = identify_lifted([unlabelled], PROTOTYPE)
    assert told.B_w == pytest.approx(P.B_w, rel=0.02)
    ground = _log(simulate("lane-change", seed=1))
    with pytest.raises(ValueError, match="lifted-wheel logs .* and vehicle logs"):
        experiment_of([log, ground])
    with pytest.raises(ValueError, match="lifted-wheel logs .* and vehicle logs"):
        identify([log, ground])
    with pytest.raises(ValueError, match="lifted-wheel logs .* and vehicle logs"):
        identify([ground, log])  # found while the logs are read
    with pytest.raises(ValueError, match="identify_lifted"):
        identify(log)
    with pytest.raises(ValueError, match="experiment 'jacks'"):
        experiment_of([log], "jacks")
    with pytest.raises(ValueError, match="experiment 'jacks'"):
        identify(log, experiment="jacks")


def test_cli_identify_lifted_wheel(run, tmp_path):
    path = run.write(tmp_path / "lifted.parquet")
    assert is_lifted(read_log(path))
    out = tmp_path / "bw.yaml"
    res = CliRunner().invoke(app, ["identify", str(path), "--out", str(out), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["experiment"] == "lifted_wheel"
    assert data["parameters"]["B_w"]["value"] == pytest.approx(P.B_w, rel=0.02)
    assert "d_vw" in data["parameters"] and "--fix B_w=" in data["use"]
    text = out.read_text(encoding="utf-8")
    assert "B_w" in text and "lifted_wheel" in text
    res = CliRunner().invoke(app, ["identify", str(path), "--out", str(out), "--experiment", "lifted-wheel"])
    assert res.exit_code == 0 and "B_w = 0.12" in res.output
