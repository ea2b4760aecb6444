"""Closed-loop simulator: energy balance, stiction, convergence to the rolling-constraint model,
tracking, reproducibility and the log schema."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import yaml

from agvdyn.io import LOG_COLUMNS, read_log
from agvdyn.kinematics import Mode
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE
from agvdyn.simulation import (
    ControllerSettings,
    PlantSettings,
    SimulationSettings,
    feedforward_table,
    plant_constants,
    run_open_loop,
    simulate,
)
from agvdyn.trajectories import (
    FourierSeries,
    LimitError,
    Trajectory,
    fourier_segment,
    lane_change,
    lateral_experiment,
)

G, P = PROTOTYPE, PAPER_PARAMETERS


def _series(period: float, peak: float) -> FourierSeries:
    return FourierSeries.at_rest(2 * math.pi / period, (1.0, -0.5, 0.3), (0.2, 0.5, -0.4), peak_velocity=peak)


@pytest.fixture(scope="module")
def result(short_sequence):
    """Closed loop with a controller whose parameters are 20 % off the plant's."""
    wrong = P.from_vector(P.to_vector() * np.where(np.arange(11) % 2 == 0, 1.2, 0.8))
    return simulate(short_sequence, controller_params=wrong, seed=3)


def test_power_balance(result):
    """Motor work = dissipated work + stop work + change of kinetic energy, within 0.1 % of the motor work.

    The remainder is the numerical dissipation of the implicit Euler step (~1e-4 of the motor work).
    The plant runs with all neglected effects on (steering-unit masses with their Coriolis coupling).
    """
    assert result.settings.plant.steering_masses
    w_motor, w_diss, w_stop = result.work[-1]
    balance = result.energy[-1] - result.energy[0] + w_diss - w_stop - w_motor
    assert w_motor > 100.0
    assert abs(balance) < 1e-3 * w_motor


def test_vehicle_at_rest_stays_at_rest():
    """Zero torque: nothing moves at all (true stiction, not a tanh that creeps)."""
    c = plant_constants(G, P, PlantSettings())
    pos0 = np.zeros(9)
    pos0[3:5] = (0.3, -0.2)
    pos, vel, _, _ = run_open_loop(c, pos0, np.zeros(9), np.zeros((1000, 4)), 2e-3, 4)
    np.testing.assert_array_equal(pos[-1], pos0)
    np.testing.assert_array_equal(vel[-1], 0.0)


def _steer_at_rest(steering_torque: float, coulomb: str) -> float:
    """Steering angle change (rad) after 2 s of a constant steering torque on the left side, at rest."""
    c = plant_constants(G, P, replace(PlantSettings(), coulomb=coulomb))
    dm = steering_torque * G.r / (2 * G.a * G.i_G)  # differential motor torque front/rear
    u = np.tile([-dm, dm, 0.0, 0.0], (1000, 1))
    pos0 = np.zeros(9)
    pos0[3:5] = (0.3, 0.0)
    pos, _, _, _ = run_open_loop(c, pos0, np.zeros(9), u, 2e-3, 4)
    return pos[-1, 3] - pos0[3]


def test_stiction_holds_below_breakaway_and_slides_above():
    # breakaway: d_cl on the steering plus d_cw of both wheels through the lever r/a (about 17 N m)
    breakaway = P.d_cl + 2 * P.d_cw * G.a / G.r
    assert abs(_steer_at_rest(0.5 * breakaway, "stiction")) < 2e-4
    assert abs(_steer_at_rest(0.5 * breakaway, "tanh")) > 5e-3  # the model's tanh creeps
    assert _steer_at_rest(2.0 * breakaway, "stiction") > 0.1


def _open_loop_error(traj: Trajectory, stiffness: float) -> float:
    settings = replace(PlantSettings().ideal(), slip_stiffness_long=stiffness, slip_stiffness_lat=stiffness,
                       mu=100.0, substeps=16)
    c = plant_constants(G, P, settings)
    u = traj.feedforward(P)
    qd, _ = traj.joint_motion()
    pos0 = np.zeros(9)
    pos0[3:5] = traj.alpha[0]
    _, vel, _, _ = run_open_loop(c, pos0, np.zeros(9), u, 2e-3, 16)
    return float(np.sqrt(np.mean((vel[:-1] - qd) ** 2)) / np.sqrt(np.mean(qd**2)))


@pytest.mark.parametrize("mode", [Mode.PARKING, Mode.STRAIGHT, Mode.ROTATION])
def test_plant_converges_to_the_rolling_constraint_model(mode):
    """The feed-forward of eq. (21) with the true parameters is the constrained model's input for the
    planned motion; driven open loop by it, the plant (neglected effects off, tyre friction not
    limiting) follows the plan the better the stiffer the tyres: the error falls like 1/C (measured
    order between 0.7 and 1.3) until the integration floor (torques held over T_s)."""
    series = _series(3, 1.0 if mode is Mode.PARKING else 0.6)
    seg = fourier_segment({Mode.PARKING: "steer_left", Mode.STRAIGHT: "straight", Mode.ROTATION: "rotation"}[mode],
                          mode, (series, series) if mode is Mode.PARKING else series)
    traj = Trajectory((seg,))
    errors = [_open_loop_error(traj, c) for c in (1e3, 3e3, 1e4, 1e5)]
    order = math.log(errors[0] / errors[2]) / math.log(10)
    assert errors[0] > errors[1] > errors[2] > errors[3]
    assert errors[0] > 0.05  # soft tyres: the plant is far from the constrained model
    assert 0.7 < order < 1.3, errors
    assert errors[3] < 0.02, errors


def test_tracking_errors_per_segment(result):
    table = result.tracking().set_index("segment", append=True)
    assert list(dict.fromkeys(result.segment)) == ["align", "steer_left", "steer_right", "straight", "rotation"]
    assert table["steering_max"].max() < 0.03           # rad, the mode tolerance of detect_mode is 0.02
    assert table["wheel_speed_rms"].max() < 0.05         # rad/s on the wheel side
    assert table["speed_rms"].max() < 0.005              # m/s
    assert table["position_error"].max() < 0.05          # m, over the whole run
    assert table["odometry_drift"].max() < 0.01          # m
    assert table["saturated"].max() == 0.0


def test_lane_change_and_lateral_are_followed():
    lane = simulate(lane_change(speed=0.8, offset=1.0, length=5.0, straight_before=0.2, straight_after=0.2), seed=1)
    row = lane.tracking().iloc[0]
    assert row["steering_max"] < 0.03 and row["heading_error"] < 0.02 and row["position_error"] < 0.05
    assert lane.position[-1, 1] == pytest.approx(1.0, abs=0.05)
    lateral = simulate(lateral_experiment(series=_series(4, 0.4), pause=0.2), seed=1)
    tab = lateral.tracking().set_index("segment", append=True)
    assert tab.xs("lateral", level=1)["steering_max"].max() < 0.015
    # leaving the stops: at alpha = (-pi/2, pi/2) a steering torque is a lateral force of its side
    # (T = a F_y), and left and right friction differ, so the chassis is pushed while the wheels
    # break away; the steering lags by a few centiradians there
    assert tab["steering_max"].max() < 0.05 and tab["position_error"].max() < 0.02
    # the steering rests on its stops during the lateral motion
    lat = lateral.segment == "lateral"
    assert np.all(np.abs(np.abs(lateral.position[lat, 3:5]) - math.pi / 2) < 0.02)


def test_same_seed_same_log_other_seed_other_noise(short_sequence):
    traj = Trajectory(short_sequence.segments[:2])
    a = simulate(traj, seed=7).log_frame()
    b = simulate(traj, seed=7).log_frame()
    c = simulate(traj, seed=8).log_frame()
    assert a.equals(b)
    assert not np.array_equal(a["m_fl"].to_numpy(), c["m_fl"].to_numpy())


def test_sensor_models(result):
    res = 2 * math.pi / (4096 * G.i_G)
    counts = result.beta_measured / res
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.max(np.abs(result.beta_measured - result.position[:, 5:])) <= res
    err = result.alpha_measured - result.position[:, 3:5]
    assert 2e-4 < np.std(err) < 1e-3  # 0.5 mrad noise + 0.38 mrad quantization
    offset = np.mean(result.torque_measured - result.torque_applied, axis=0)
    assert np.all(np.abs(offset) < 0.1) and np.ptp(offset) > 1e-3


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_log_schema_and_sidecar(tmp_path, result, suffix):
    path = result.write(tmp_path / f"run{suffix}")
    log = read_log(path)
    assert list(log.frame.columns[: len(LOG_COLUMNS)]) == list(LOG_COLUMNS)
    assert set(log.segments) == {"align", "steer_left", "steer_right", "straight", "rotation"}
    np.testing.assert_allclose(log.t[1] - log.t[0], 2e-3)
    np.testing.assert_allclose(log.beta, result.beta_measured)
    side = log.sidecar
    assert side["true_parameters"] == {n: getattr(P, n) for n in PARAMETER_NAMES}
    assert side["platform"]["l"] == G.l and side["seed"] == 3
    assert side["settings"]["plant"]["coulomb"] == "stiction"


def test_limits_are_checked_before_running():
    fast = FourierSeries.at_rest(2 * math.pi / 4, (1.0, -0.5), (0.3, 0.2), peak_velocity=3.0)
    traj = Trajectory((fourier_segment("straight", Mode.STRAIGHT, fast),))
    with pytest.raises(LimitError, match="speed limit in segment 'straight'"):
        simulate(traj)


def test_torque_limit_saturates_the_drive(short_sequence):
    traj = Trajectory(short_sequence.segments[5:6])
    settings = SimulationSettings(plant=replace(PlantSettings(), torque_limit=0.4), check_limits=False)
    res = simulate(traj, settings=settings)
    assert np.max(np.abs(res.torque_applied)) <= 0.4 + 1e-12
    assert res.tracking()["saturated"].iloc[0] > 0


def test_feedforward_table_matches_eq21(short_sequence):
    table = feedforward_table(short_sequence, P)
    np.testing.assert_allclose(table[["m_fl", "m_rl", "m_fr", "m_rr"]].to_numpy(), short_sequence.feedforward(P))
    assert set(table["mode"]) == {"1", "2s", "4"}
    assert len(table) == short_sequence.n_samples


def test_feedforward_alone_is_worse_than_with_feedback(short_sequence):
    wrong = P.replace(m_ch=1.3 * P.m_ch, d_cw=0.6 * P.d_cw)
    traj = Trajectory(short_sequence.segments[5:6])
    with_fb = simulate(traj, controller_params=wrong).tracking().iloc[0]
    without = simulate(traj, controller_params=wrong,
                       settings=SimulationSettings(controller=ControllerSettings(feedback=False))).tracking().iloc[0]
    assert with_fb["wheel_speed_rms"] < 0.5 * without["wheel_speed_rms"]


def test_cli_simulate_and_feedforward(tmp_path):
    from typer.testing import CliRunner

    from agvdyn.cli import app
    from agvdyn.platform import write_parameters

    plan = tmp_path / "plan.yaml"
    plan.write_text("segments:\n  - name: straight\n    mode: straight\n"
                    "    fourier: {base_frequency: 2.0, a: [0.3, -0.1], b: [0.1, 0.2]}\n", encoding="utf-8")
    params = write_parameters(tmp_path / "params.yaml", P)
    runner = CliRunner()
    out = tmp_path / "run.csv"
    res = runner.invoke(app, ["simulate", str(plan), "--out", str(out), "--seed", "4", "--params", str(params)])
    assert res.exit_code == 0, res.output
    log = read_log(out)
    assert set(log.segments) == {"straight"} and log.sidecar["seed"] == 4
    res = runner.invoke(app, ["feedforward", str(plan), "--params", str(params), "--out", str(tmp_path / "ff.parquet")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["simulate", "slalom", "--out", str(out)])
    assert res.exit_code == 2 and "unknown experiment 'slalom'" in res.output
    res = runner.invoke(app, ["feedforward", str(plan), "--params", str(tmp_path / "missing.yaml"), "--out", str(out)])
    assert res.exit_code == 2 and "missing.yaml" in res.output


def test_coriolis_terms_do_no_spurious_work():
    """v^T h(alpha, v) = 1/2 v^T dM/dt v for random states (steering-unit masses on): the Coriolis and
    centrifugal terms of the body-frame equations exchange no energy beyond the change of M(alpha).
    A sign or factor error in any unit term breaks it (checked against finite differences of M)."""
    from agvdyn.simulation._plant_kernels import _bias, _mass_matrix

    c = plant_constants(G, P, replace(PlantSettings(), unit_mass=60.0))
    rng = np.random.default_rng(0)
    M1, M2, h = np.zeros((9, 9)), np.zeros((9, 9)), np.zeros(9)
    for _ in range(50):
        alpha = rng.uniform(-1.5, 1.5, 2)
        v = rng.normal(size=9)
        _bias(c, alpha, v, h)
        eps = 1e-6
        _mass_matrix(c, alpha + eps * v[3:5], M1)
        _mass_matrix(c, alpha - eps * v[3:5], M2)
        m_dot = (M1 - M2) / (2 * eps)
        assert v @ h == pytest.approx(0.5 * v @ m_dot @ v, rel=1e-6, abs=1e-8)
        assert np.abs(h).max() > 1e-3  # the terms are there


@pytest.mark.parametrize("geom", [
    PROTOTYPE.__class__(l=1.6, b=1.0, a=0.08, r=0.125, i_G=20.0, name="large"),
    PROTOTYPE.__class__(l=1.2, b=0.8, a=-0.04, r=0.1, i_G=25.0, name="inboard offset"),
])
def test_other_platforms_are_followed(geom):
    lane = lane_change(geom, speed=0.6, offset=0.5, length=4.0, straight_before=0.1, straight_after=0.1)
    tab = simulate(lane, platform=geom, seed=1).tracking()
    assert tab["steering_max"].max() < 0.02 and tab["heading_error"].max() < 0.02


def test_settings_file(tmp_path):
    from agvdyn.simulation import read_settings

    path = tmp_path / "sim.yaml"
    path.write_text("plant: {coulomb: tanh, wheel_radius_error: [0, 0, 0, 0.01]}\n"
                    "controller: {steering_gain: 500}\nsensors: {steering_noise: 0.0}\n", encoding="utf-8")
    st = read_settings(path)
    assert st.plant.coulomb == "tanh" and st.plant.wheel_radius_error == (0, 0, 0, 0.01)
    assert st.controller.steering_gain == 500 and st.sensors.steering_noise == 0.0
    assert st.sensors.encoder_counts == 4096  # defaults kept
    from agvdyn.simulation import settings_from_dict

    # the settings recorded in a sidecar rebuild the same settings
    custom = SimulationSettings(plant=replace(PlantSettings(), unit_mass=20.0), check_limits=False)
    assert settings_from_dict(yaml.safe_load(yaml.safe_dump(custom.to_dict()))) == custom
    path.write_text("plant: {stiffness: 3}\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"plant: unknown keys \['stiffness'\]"):
        read_settings(path)
    path.write_text("plant: {coulomb: viscous}\n", encoding="utf-8")
    with pytest.raises(ValueError, match="coulomb='viscous'"):
        read_settings(path)


def _momenta(c, geom, pos, vel):
    """World linear momentum (2,) and angular momentum about the world origin of all plant bodies."""
    from agvdyn.simulation import plant as pl

    X, Y, g = pos[:3]
    R = np.array([[np.cos(g), -np.sin(g)], [np.sin(g), np.cos(g)]])
    cross = lambda a, b: a[0] * b[1] - a[1] * b[0]  # noqa: E731
    v, w = vel[:2], vel[2]
    lin = c[pl._MB] * (R @ v)
    ang = c[pl._MB] * cross((X, Y), R @ v) + c[pl._CB] * w
    m_u, e = c[pl._MU_MASS], c[pl._EU]
    for i in range(4):
        side, s, h = (0 if i < 2 else 1), (1 if i < 2 else -1), (1 if i % 2 == 0 else -1)
        th, ad = h * pos[3 + side], vel[3 + side]
        p = np.array([geom.l / 2 * h - s * e * np.sin(th), geom.b / 2 * s + s * e * np.cos(th)])
        dp = -s * e * h * np.array([np.cos(th), np.sin(th)])
        vw = R @ (v + w * np.array([-p[1], p[0]]) + dp * ad)
        lin = lin + m_u * vw
        ang += m_u * cross(np.array([X, Y]) + R @ p, vw) + (c[pl._JUL] if side == 0 else c[pl._JUR]) * (w + h * ad)
    return lin, ang


def test_free_plant_conserves_momentum():
    """No tyre forces, no friction, no torque: the plant with steering-unit masses (60 kg) keeps its
    world linear and angular momentum; the drift of the explicit Coriolis terms is first order in
    the step (a wrong term would not vanish with dt)."""
    free = P.replace(d_vl=0.0, d_cl=0.0, d_vr=0.0, d_cr=0.0, d_vw=0.0, d_cw=0.0)
    settings = replace(PlantSettings(), coulomb="none", slip_stiffness_long=1e-9, slip_stiffness_lat=1e-9,
                       unit_mass=60.0, torque_limit=None)
    c = plant_constants(G, free, settings)
    pos0 = np.zeros(9)
    pos0[3:5] = (0.3, -0.5)
    vel0 = np.random.default_rng(1).normal(size=9) * np.array([0.5, 0.5, 0.5, 2, 2, 1, 1, 1, 1])
    lin0, ang0 = _momenta(c, G, pos0, vel0)
    drift = []
    for sub in (4, 16):
        pos, vel, _, _ = run_open_loop(c, pos0, vel0, np.zeros((500, 4)), 2e-3, sub)
        lin1, ang1 = _momenta(c, G, pos[-1], vel[-1])
        drift.append(np.hypot(*(lin1 - lin0)) / np.hypot(*lin0) + abs(ang1 - ang0) / abs(ang0))
    assert drift[1] < 2e-4
    assert 3.0 < drift[0] / drift[1] < 5.0  # first order: 4x smaller step, 4x smaller drift


def test_feedforward_table_refuses_broken_limits():
    fast = FourierSeries.at_rest(2 * math.pi / 4, (1.0, -0.5), (0.3, 0.2), peak_velocity=3.0)
    traj = Trajectory((fourier_segment("straight", Mode.STRAIGHT, fast),))
    with pytest.raises(LimitError, match="speed limit"):
        feedforward_table(traj, P)
    assert len(feedforward_table(traj, P, limits=None)) == traj.n_samples


def test_sparse_plant_terms_equal_the_dense_products():
    """The plant step's sparse A(alpha), A v and K = M + dt A^T D A (lower triangle) against the
    dense products at random states: A exactly equal to kinematics' constraint matrix (rolling
    radii r), A v and K to rounding."""
    from agvdyn.kinematics import constraint_matrix
    from agvdyn.simulation._plant_kernels import (_constraint_rows, _inertia_terms, _iteration_matrix,
                                                  _slip_velocities, _unit_trig)

    c = plant_constants(G, P, replace(PlantSettings(), wheel_radius_error=(0.0,) * 4))
    rng = np.random.default_rng(3)
    tr, A, M, h, K, sv = np.zeros((4, 2)), np.zeros((8, 9)), np.zeros((9, 9)), np.zeros(9), np.zeros((9, 9)), np.zeros(8)
    for _ in range(20):
        alpha, v, d = rng.uniform(-1.57, 1.57, 2), rng.normal(size=9), rng.uniform(1e3, 1e6, 8)
        _unit_trig(alpha[0], alpha[1], tr)
        _constraint_rows(c, tr, A)
        np.testing.assert_array_equal(A, constraint_matrix(G, alpha[None])[0])
        _slip_velocities(A, v, sv)
        np.testing.assert_allclose(sv, A @ v, rtol=1e-13, atol=1e-13)
        _inertia_terms(c, tr, v, M, h)
        _iteration_matrix(M, A, d, 5e-4, K)
        dense = M + 5e-4 * A.T @ np.diag(d) @ A
        np.testing.assert_allclose(np.tril(K), np.tril(dense), rtol=1e-12, atol=1e-9)


def test_arrow_solve_equals_the_dense_solve():
    """The plant step's solve of K x = rhs (wheels, then steering sides, then the chassis block
    eliminated) against numpy's dense solve of the symmetric K at random states, with joint
    friction and a stop on the diagonal."""
    from agvdyn.simulation._plant_kernels import (_arrow_solve, _constraint_rows, _inertia_terms,
                                                  _iteration_matrix, _unit_trig)

    c = plant_constants(G, P, PlantSettings())
    rng = np.random.default_rng(11)
    tr, A, M, h, K = np.zeros((4, 2)), np.zeros((8, 9)), np.zeros((9, 9)), np.zeros(9), np.zeros((9, 9))
    for _ in range(50):
        alpha, v, d = rng.uniform(-1.57, 1.57, 2), rng.normal(size=9), 10 ** rng.uniform(1, 6, 8)
        _unit_trig(alpha[0], alpha[1], tr)
        _constraint_rows(c, tr, A)
        _inertia_terms(c, tr, v, M, h)
        _iteration_matrix(M, A, d, 5e-4, K)
        for q in range(3, 9):
            K[q, q] += 5e-4 * rng.uniform(0, 50)
        dense = np.tril(K) + np.tril(K, -1).T
        rhs = rng.normal(size=9)
        want = np.linalg.solve(dense, rhs)
        x = rhs.copy()
        _arrow_solve(K, x)
        np.testing.assert_allclose(x, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())


def test_tanh_ratio_equals_tanh_over_x():
    """The tyres' saturation tanh(x)/x from x^2 (Taylor series below x = 0.2) to round-off."""
    from agvdyn.simulation._plant_kernels import _tanh_ratio

    for x in np.concatenate([[0.0, 1e-12, 1e-5], np.linspace(1e-4, 0.2, 2001), [0.2 + 1e-12, 0.3, 1.0, 5.0, 50.0]]):
        want = 1.0 if x == 0 else math.tanh(x) / x
        assert abs(_tanh_ratio(x * x) - want) <= 4e-16 * want


# --- payload (issue 31, simulation/payload.py) ---

def test_payload_terms_do_no_work_and_are_a_rigid_body():
    """With a payload (300 kg at (0.3, -0.2) m, 40 kg m^2): M is the unloaded one plus the rigid-body
    block of the load, positive definite, and v^T h = 1/2 v^T dM/dt v still holds (the payload's
    forces do no work)."""
    from agvdyn.simulation._plant_kernels import _bias, _mass_matrix
    from agvdyn.simulation.payload import PayloadEvent
    from agvdyn.simulation.plant import set_payload

    c0 = plant_constants(G, P, PlantSettings())
    c = c0.copy()
    ev = PayloadEvent(0.0, 300.0, 0.3, -0.2, 40.0)
    set_payload(c, ev.moments(), P.m_ch)
    rng = np.random.default_rng(2)
    M0, M, M1, M2, h = *(np.zeros((9, 9)) for _ in range(4)), np.zeros(9)
    for _ in range(30):
        alpha = rng.uniform(-1.5, 1.5, 2)
        v = rng.normal(size=9)
        _mass_matrix(c0, alpha, M0)
        _mass_matrix(c, alpha, M)
        block = np.array([[300.0, 0, 60.0], [0, 300.0, 90.0], [60.0, 90.0, 40.0 + 300.0 * 0.13]])  # -m y, m x
        np.testing.assert_allclose((M - M0)[:3, :3], block, atol=1e-9)
        assert np.all(np.linalg.eigvalsh(M) > 0)
        _bias(c, alpha, v, h)
        eps = 1e-6
        _mass_matrix(c, alpha + eps * v[3:5], M1)
        _mass_matrix(c, alpha - eps * v[3:5], M2)
        assert v @ h == pytest.approx(0.5 * v @ ((M1 - M2) / (2 * eps)) @ v, rel=1e-6, abs=1e-8)


def test_payload_power_balance_and_truth(short_sequence):
    """Motor work = dissipated + stop work + change of kinetic energy + the jumps at the events
    (velocities continuous, 1/2 v^T (M' - M) v), within the 1e-3 of the run without a payload;
    the sidecar's truth: m_ch, C_ch (parallel axis), centre of mass."""
    from agvdyn.simulation.payload import PayloadEvent

    events = (PayloadEvent(12.0, 300.0, 0.3, -0.2, 40.0), PayloadEvent(19.0, -100.0, 0.5, 0.1, 5.0))
    r = simulate(short_sequence, settings=SimulationSettings(payload=events), seed=3)
    w_motor, w_diss, w_stop = r.work[-1]
    jumps = sum(p.energy_jump for p in r.payload_truth)
    assert abs(jumps) > 0.1
    assert abs(r.energy[-1] - r.energy[0] + w_diss - w_stop - w_motor - jumps) < 1e-3 * w_motor
    first, second = r.payload_truth
    assert first.m_ch == pytest.approx(P.m_ch + 300.0) and second.m_ch == pytest.approx(P.m_ch + 200.0)
    assert first.C_ch == pytest.approx(P.C_ch + 40.0 + 300.0 * 0.13)
    assert first.x_c == pytest.approx(90.0 / first.m_ch) and second.t_applied == pytest.approx(19.0)
    side = yaml.safe_load(yaml.safe_dump(r.sidecar()))
    assert [p["t"] for p in side["payload_truth"]] == [12.0, 19.0]
    assert "payload" in side["settings"]


def test_no_payload_event_in_the_run_changes_nothing(short_sequence):
    """An event after the end applies to no sample: the log equals the one without a payload."""
    from agvdyn.simulation.payload import PayloadEvent

    base = simulate(short_sequence, seed=4)
    late = simulate(short_sequence, settings=SimulationSettings(payload=(PayloadEvent(999.0, 100.0),)), seed=4)
    assert late.payload_truth == ()
    np.testing.assert_array_equal(base.log_frame().to_numpy(), late.log_frame().to_numpy())
    assert "payload_truth" not in base.sidecar() and "payload" not in base.settings.to_dict()


def test_parse_payload():
    from agvdyn.simulation.payload import PayloadEvent, parse_payload

    assert parse_payload("20:300") == PayloadEvent(20.0, 300.0)
    assert parse_payload("20:-150:0.2,-0.1:45") == PayloadEvent(20.0, -150.0, 0.2, -0.1, 45.0)
    for bad in ("20", "20:0", "x:300", "20:300:0.2", "-1:300", "20:300:0,0:-5"):
        with pytest.raises(ValueError, match="--payload"):
            parse_payload(bad)


def test_driving_experiment_stays_on_its_floor_within_the_limits():
    from agvdyn.trajectories import check_limits, experiment

    traj = experiment("driving", duration=120, floor=(14.0, 8.0), seed=5)
    assert traj.duration >= 120 and {"straight", "rotation", "lane_change", "align"} >= set(traj.segment)
    assert {"straight", "rotation"} <= set(traj.segment)
    check_limits(traj)
    pose = traj.pose()
    assert np.abs(pose[:, 0]).max() < 7.0 and np.abs(pose[:, 1]).max() < 4.0
    with pytest.raises(Exception, match="floor"):
        experiment("driving", floor=(2.0, 2.0))
