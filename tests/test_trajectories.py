"""Trajectories: Fourier series at rest, identification sequence, lane change, lateral, limits, files."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.dynamics import projected_regressor
from agvdyn.kinematics import Mode, detect_mode, icr_residual, joint_motion
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, SAMPLE_TIME
from agvdyn.trajectories import (
    FourierSeries,
    LimitError,
    Limits,
    Trajectory,
    TrajectoryError,
    check_limits,
    default_excitation,
    experiment,
    floor_space,
    fourier_segment,
    identification_sequence,
    lane_change,
    lateral_experiment,
    read_trajectory,
)

coefficients = st.lists(st.floats(-2, 2, allow_nan=False), min_size=2, max_size=7)


@settings(max_examples=40, deadline=None)
@given(a=coefficients, b=coefficients, w=st.floats(0.1, 3.0), start=st.floats(-1, 1))
def test_fourier_at_rest_starts_and_ends_at_rest(a, b, w, start):
    n = min(len(a), len(b))
    series = FourierSeries.at_rest(w, a[:n], b[:n], start)
    q, qd, qdd = series.evaluate(np.array([0.0, series.period]))
    np.testing.assert_allclose(q, [start, start], atol=1e-9)
    np.testing.assert_allclose(qd, 0.0, atol=1e-9)
    np.testing.assert_allclose(qdd, 0.0, atol=1e-9)


def test_fourier_derivatives_match_finite_differences():
    series = FourierSeries.at_rest(2 * math.pi / 4, (1.0, -0.3, 0.5), (0.2, 0.4, -0.1), 0.3)
    t = np.linspace(0, 4, 40001)
    q, qd, qdd = series.evaluate(t)
    np.testing.assert_allclose(np.gradient(q, t)[1:-1], qd[1:-1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(qd, t)[1:-1], qdd[1:-1], atol=1e-5)


def test_fourier_recurrence_matches_the_sum_of_harmonics():
    """evaluate() takes the harmonics' powers of exp(i w t) by recurrence: equal to the direct sum of
    sin(k w t), cos(k w t) to round-off over three periods and up to 12 harmonics."""
    rng = np.random.default_rng(7)
    for n in (1, 5, 12):
        series = FourierSeries(0.7, tuple(rng.normal(size=n)), tuple(rng.normal(size=n)), 0.4)
        t = np.arange(int(3 * series.period / 0.002)) * 0.002
        k = np.arange(1, n + 1) * series.base_frequency
        a, b = np.array(series.a), np.array(series.b)
        s, c = np.sin(np.multiply.outer(t, k)), np.cos(np.multiply.outer(t, k))
        direct = (series.start + np.sum(b / k) + s @ (a / k) - c @ (b / k), c @ a + s @ b, -s @ (a * k) + c @ (b * k))
        for got, want in zip(series.evaluate(t), direct):
            assert np.abs(got - want).max() <= 1e-13 * np.abs(want).max()


def test_feedforward_with_the_joint_motion_given_and_against_the_per_sample_solve():
    """Trajectory.feedforward(params, motion) equals feedforward(params); in the modes with a constant
    admissible basis the torques equal the per-sample minimum-norm solution of N^T B u = N^T Theta p."""
    from agvdyn.dynamics import generalized_forces
    from agvdyn.kinematics import admissible_basis

    for traj in (identification_sequence(), lane_change(), lateral_experiment()):
        motion = traj.joint_motion()
        u = traj.feedforward(PAPER_PARAMETERS, motion)
        np.testing.assert_array_equal(u, traj.feedforward(PAPER_PARAMETERS))
        for seg, (_, sl) in zip(traj.segments, traj.segment_slices()):
            if seg.mode in (Mode.CAR_LIKE, Mode.LATERAL):
                continue
            f = generalized_forces(motion[0][sl], motion[1][sl], PAPER_PARAMETERS)
            N = admissible_basis(PROTOTYPE, seg.mode, seg.alpha)
            M = PROTOTYPE.i_G * np.swapaxes(N[:, 5:, :], 1, 2)
            g = np.einsum("nim,ni->nm", N, f)
            y = np.linalg.solve(np.einsum("nik,njk->nij", M, M), g[..., None])[..., 0]
            np.testing.assert_allclose(u[sl], np.einsum("nik,ni->nk", M, y), rtol=1e-12, atol=1e-14)


def test_fourier_scaling_to_peaks():
    series = FourierSeries.at_rest(1.0, (1.0, 0.5), (0.3, -0.2), peak_velocity=0.7, peak_excursion=10.0)
    q, qd, _ = series.evaluate(np.linspace(0, series.period, 5001))
    assert np.max(np.abs(qd)) == pytest.approx(0.7, rel=1e-3)
    series = FourierSeries.at_rest(1.0, (1.0, 0.5), (0.3, -0.2), peak_velocity=10.0, peak_excursion=0.2)
    q, qd, _ = series.evaluate(np.linspace(0, series.period, 5001))
    assert np.max(np.abs(q)) == pytest.approx(0.2, rel=1e-3)


def test_fourier_rejects_bad_coefficients():
    with pytest.raises(TrajectoryError, match="base_frequency"):
        FourierSeries(0.0, (1.0,), (1.0,))
    with pytest.raises(TrajectoryError, match="same number"):
        FourierSeries(1.0, (1.0, 2.0), (1.0,))


@pytest.fixture(scope="module")
def sequence() -> Trajectory:
    return identification_sequence()


def test_identification_sequence_order_and_modes(sequence):
    names = [s.name for s in sequence.segments if s.name != "align"]
    assert names == ["steer_left", "steer_right", "straight", "rotation"]
    modes = {s.name: s.mode for s in sequence.segments}
    assert modes["steer_left"] is Mode.PARKING and modes["straight"] is Mode.STRAIGHT
    assert modes["rotation"] is Mode.ROTATION
    # steering one side holds the other at zero
    left = next(s for s in sequence.segments if s.name == "steer_left")
    assert np.all(left.alpha[:, 1] == 0) and np.ptp(left.alpha[:, 0]) > 1.0
    # straight and rotation are planned in their configuration (eq. 9)
    for seg in sequence.segments:
        if seg.mode in (Mode.STRAIGHT, Mode.ROTATION):
            assert np.all(detect_mode(PROTOTYPE, seg.alpha) == int(seg.mode))
    rot = next(s for s in sequence.segments if s.name == "rotation")
    np.testing.assert_allclose(rot.alpha[0], math.atan2(1.2, 0.8) * np.array([-1, 1]))


def test_sequence_is_continuous_and_at_rest_between_segments(sequence):
    qd, qdd = sequence.joint_motion()
    np.testing.assert_allclose(np.diff(sequence.t), SAMPLE_TIME)
    # steering angles continuous, every segment starts at rest
    assert np.max(np.abs(np.diff(sequence.alpha, axis=0))) < 2 * 1.5 * SAMPLE_TIME
    starts = sequence.bounds[:-1]
    np.testing.assert_allclose(qd[starts], 0.0, atol=1e-9)
    # straight and rotation return to their start: periodic Fourier series
    pose = sequence.pose(qd)
    np.testing.assert_allclose(pose[-1], 0.0, atol=2e-3)


def test_default_excitation_is_well_conditioned(sequence):
    """cond(Theta_1w^T Theta_1w) of the planned sequence (column-scaled as eq. 25); the paper reports 11.56."""
    rows = []
    for seg in sequence.segments:
        if seg.name == "align":
            continue
        qd, qdd = joint_motion(PROTOTYPE, seg.mode, seg.alpha, seg.s_dot, seg.s_ddot)
        rows.append(projected_regressor(PROTOTYPE, seg.mode, seg.alpha, qd, qdd).reshape(-1, 11))
    Y = np.concatenate(rows)[:, :10]
    Yw = Y / np.linalg.norm(Y, axis=0)
    assert np.linalg.cond(Yw.T @ Yw) < 15


def test_floor_space_of_the_sequence(sequence):
    fs = floor_space(sequence)
    straight = next(s for s in sequence.segments if s.name == "straight")
    assert fs.length == pytest.approx(1.2 + 2 * np.max(np.abs(straight.s)), rel=1e-3)
    assert fs.width == pytest.approx(math.hypot(1.2, 0.8) + 2 * 0.05)


def test_default_experiments_respect_the_limits(sequence):
    for traj in (sequence, lane_change(), lateral_experiment()):
        report = check_limits(traj, PAPER_PARAMETERS)
        assert report.ok


def test_limit_violation_names_limit_and_segment():
    fast = FourierSeries.at_rest(2 * math.pi / 4, (1.0, -0.5), (0.3, 0.2), peak_velocity=3.0)
    traj = Trajectory((fourier_segment("straight", Mode.STRAIGHT, fast),))
    with pytest.raises(LimitError, match=r"speed limit in segment 'straight' at t = .* > 1\.5"):
        check_limits(traj)
    with pytest.raises(LimitError, match="motor_torque"):
        check_limits(traj, limits=Limits(speed=5, acceleration=50, wheel_speed=100, motor_torque=0.5))


def test_lane_change_geometry():
    traj = lane_change(speed=1.0, offset=2.0, length=10.0)
    seg = traj.segments[0]
    assert seg.mode is Mode.CAR_LIKE
    np.testing.assert_allclose(icr_residual(PROTOTYPE, seg.alpha), 0.0, atol=1e-9)
    qd, _ = traj.joint_motion()
    pose = traj.pose(qd)
    assert pose[-1, 1] == pytest.approx(2.0, abs=5e-3)
    assert pose[-1, 2] == pytest.approx(0.0, abs=1e-6)
    assert np.max(qd[:, 0]) == pytest.approx(1.0, rel=1e-6)
    np.testing.assert_allclose(qd[[0, -1]], 0.0, atol=1e-9)
    # omega = 2 v_x tan(alpha_v) / l (PLATFORM.md)
    np.testing.assert_allclose(qd[:, 2], 2 * qd[:, 0] * np.tan(seg.s[:, 0]) / 1.2, atol=1e-9)
    with pytest.raises(TrajectoryError, match="offset"):
        lane_change(offset=5.0, length=8.0)


def test_lateral_experiment_reaches_the_stops():
    traj = lateral_experiment()
    lat = next(s for s in traj.segments if s.name == "lateral")
    np.testing.assert_allclose(lat.alpha, np.tile([-math.pi / 2, math.pi / 2], (lat.n_samples, 1)))
    assert [s.name for s in traj.segments] == ["align", "lateral", "align"]
    np.testing.assert_allclose(traj.alpha[-1], 0.0, atol=1e-12)


def test_csv_trajectory_round_trip(tmp_path):
    series = default_excitation("straight")
    planned = Trajectory((fourier_segment("straight", Mode.STRAIGHT, series),))
    seg = planned.segments[0]
    step = 10  # 20 ms rows, the reader interpolates back to 2 ms
    frame = pd.DataFrame({"t": seg.t[::step], "mode": "2s", "alpha_l": 0.0, "alpha_r": 0.0,
                          "x_ch": seg.s[::step, 0], "segment": "straight"})
    path = tmp_path / "user.csv"
    frame.to_csv(path, index=False)
    before = path.read_bytes()
    traj = read_trajectory(path)
    assert path.read_bytes() == before
    got = traj.segments[0]
    n = got.n_samples
    assert got.mode is Mode.STRAIGHT and got.name == "straight"
    np.testing.assert_allclose(got.s_dot[:, 0], seg.s_dot[:n, 0], atol=2e-4)
    np.testing.assert_allclose(got.s_ddot[:, 0], seg.s_ddot[:n, 0], atol=5e-3)


def test_csv_errors_name_row_and_column(tmp_path):
    path = tmp_path / "bad.csv"
    pd.DataFrame({"t": [0, 1, 2, 3], "mode": ["2s", "2s", "9", "2s"], "alpha_l": 0.0, "alpha_r": 0.0,
                  "x_ch": [0, 1, 2, 3]}).to_csv(path, index=False)
    with pytest.raises(TrajectoryError, match=r"column 'mode', row 4"):
        read_trajectory(path)
    pd.DataFrame({"t": [0, 1, 1, 3], "mode": "2s", "alpha_l": 0.0, "alpha_r": 0.0, "x_ch": [0, 1, 2, 3]}
                 ).to_csv(path, index=False)
    with pytest.raises(TrajectoryError, match=r"column 't', row 4"):
        read_trajectory(path)
    pd.DataFrame({"t": [0, 1, 2, 3], "mode": "4", "alpha_l": 0.0, "alpha_r": 0.0, "gamma_ch": [0, 1, 2, 3]}
                 ).to_csv(path, index=False)
    with pytest.raises(TrajectoryError, match=r"not in mode 4"):
        read_trajectory(path)


def test_yaml_trajectory(tmp_path):
    path = tmp_path / "plan.yaml"
    path.write_text(
        "segments:\n"
        "  - name: steer_left\n    mode: 1\n"
        "    fourier: {alpha_l: {base_frequency: 1.0, a: [0.5, -0.2], b: [0.1, 0.3]}}\n"
        "  - name: align\n    to: [-0.9827937232473292, 0.9827937232473292]\n"
        "  - name: rotation\n    mode: 4\n    fourier: {base_frequency: 0.5, a: [0.3, 0.1], b: [0.2, -0.1]}\n",
        encoding="utf-8",
    )
    traj = read_trajectory(path)
    assert [s.name for s in traj.segments] == ["steer_left", "align", "rotation"]
    assert [s.mode for s in traj.segments] == [Mode.PARKING, Mode.PARKING, Mode.ROTATION]
    path.write_text("segments:\n  - name: rotation\n    mode: 4\n    fourier: {base_frequency: 0.5, a: [1], b: [1]}\n")
    with pytest.raises(TrajectoryError, match="insert an 'align' segment"):
        read_trajectory(path)


def test_experiment_names():
    assert experiment("lane-change").name == "lane_change"
    assert experiment("identification").name == "identification"
    with pytest.raises(TrajectoryError, match="unknown experiment"):
        experiment("slalom")


def test_yaml_lane_change(tmp_path):
    path = tmp_path / "lane.yaml"
    path.write_text("segments:\n  - name: lane_change\n    speed: 0.5\n    offset: -1.0\n    length: 6\n",
                    encoding="utf-8")
    traj = read_trajectory(path)
    assert traj.segments[0].mode is Mode.CAR_LIKE
    assert traj.pose()[-1, 1] == pytest.approx(-1.0, abs=5e-3)
    path.write_text("segments:\n  - name: lane_change\n    sped: 0.5\n", encoding="utf-8")
    with pytest.raises(TrajectoryError, match=r"unknown keys \['sped'\]"):
        read_trajectory(path)


def test_trajectory_checks_continuity_and_modes(sequence):
    with pytest.raises(TrajectoryError, match=r"segment 1 \('rotation'\) starts at alpha"):
        Trajectory((sequence.segments[5], sequence.segments[7]))  # straight, then rotation without alignment
    bad = sequence.segments[7]
    from agvdyn.trajectories import Segment
    wrong = Segment("rotation", Mode.ROTATION, bad.t, np.zeros_like(bad.alpha), bad.s, bad.s_dot, bad.s_ddot)
    with pytest.raises(TrajectoryError, match=r"segment 0 \('rotation'\).*not in mode 4"):
        Trajectory((wrong,))


def test_per_sample_generalized_coordinates(sequence):
    rot = sequence.segment == "rotation"
    steer = sequence.segment == "steer_left"
    assert sequence.s.shape == (sequence.n_samples, 2)
    assert np.all(np.isnan(sequence.s[rot, 1])) and not np.any(np.isnan(sequence.s[steer]))
    np.testing.assert_array_equal(sequence.s[steer], sequence.alpha[steer])  # mode 1: s = alpha
    qd, _ = sequence.joint_motion()
    np.testing.assert_allclose(sequence.s_dot[rot, 0], qd[rot, 2])  # mode 4: s_dot = omega


def test_package_modules_and_public_names():
    """One module per job under agvdyn.trajectories; every public name importable from the package."""
    import importlib

    import agvdyn.trajectories as trajectories

    for module in ("errors", "fourier", "segments", "limits", "experiments", "files", "planner"):
        importlib.import_module(f"agvdyn.trajectories.{module}")
    for name in trajectories.__all__:
        assert hasattr(trajectories, name), name
    for name in ("Limits", "Trajectory", "TrajectoryError", "check_limits", "experiment", "floor_space",
                 "pose_from_velocities", "read_trajectory", "lifted_wheel_experiment"):
        assert name in trajectories.__all__


def test_car_like_fourier_segment_and_yaml(tmp_path):
    """Mode 2 from two series (alpha_v, x_ch): steering on the ICR relation (eq. 8), omega = 2 v tan(alpha_v) / l."""
    w = 2 * math.pi / 20
    av = FourierSeries.at_rest(w, (0.3, -0.5, 0.2), (0.4, 0.1, -0.3), peak_excursion=0.6, peak_velocity=0.5)
    x = FourierSeries.at_rest(w, (0.5, 0.2, -0.4), (-0.2, 0.6, 0.1), peak_excursion=1.0, peak_velocity=0.5)
    seg = fourier_segment("lane_change", Mode.CAR_LIKE, (av, x))
    np.testing.assert_allclose(icr_residual(PROTOTYPE, seg.alpha), 0.0, atol=1e-9)
    traj = Trajectory((seg,))
    qd, _ = traj.joint_motion()
    np.testing.assert_allclose(qd[:, 2], 2 * qd[:, 0] * np.tan(seg.s[:, 0]) / 1.2, atol=1e-9)
    with pytest.raises(TrajectoryError, match="beyond the stops"):
        fourier_segment("lane_change", Mode.CAR_LIKE, (FourierSeries.at_rest(w, (1.0, -1.0), (1.0, 0.5),
                                                                              peak_excursion=1.4), x))
    path = tmp_path / "car.yaml"
    spec = {"segments": [{"name": "lane_change", "mode": "2", "fourier": {
        "alpha_v": {"base_frequency": w, "a": list(av.a), "b": list(av.b)},
        "x_ch": {"base_frequency": w, "a": list(x.a), "b": list(x.b)}}}]}
    import yaml

    path.write_text(yaml.safe_dump(spec), encoding="utf-8")
    got = read_trajectory(path).segments[0]
    np.testing.assert_allclose(got.s, seg.s, atol=1e-9)
    np.testing.assert_allclose(got.alpha, seg.alpha, atol=1e-9)


def test_lifted_wheel_experiment_by_name():
    traj = experiment("lifted-wheel")
    assert traj.lifted and traj.name == "lifted_wheel"
    assert traj.floor_space().length == pytest.approx(1.2)  # on jacks: the chassis does not move
    with pytest.raises(TrajectoryError, match="lifted-wheel"):
        experiment("jacks")
