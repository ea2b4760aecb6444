"""The compiled kernels of the row pipeline (agvdyn.identification._kernels) against the numpy
formulation they replace: derivatives, odometry and slip, entries of Theta, modes, projection with
stiction mask and guard, and the gathered kept rows."""
from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as hst

from agvdyn._trig import sincos_steering
from agvdyn.dynamics import regressor_signals
from agvdyn.identification import IdentificationSettings
from agvdyn.identification._kernels import recording_breaks
from agvdyn.identification.equations import projected_block
from agvdyn.identification.normal import RowStatistics, reduce_blocks, row_statistics
from agvdyn.identification.rows import NO_MODE, _modes_and_virtual_angle, _stretch_blocks, log_rows
from agvdyn.identification.stretches import align_torque, filtered_stretch, slip_filter, stretch_bounds
from agvdyn.io import Log
from agvdyn.kinematics import Mode, detect_mode, icr_residual, kinematic_model
from agvdyn.odometry import odometry_with_slip
from agvdyn.platform import PROTOTYPE
from agvdyn.signals import guarded_mask, lowpass, row_max_abs, time_derivative
from model_logs import identification_frame

SETTINGS = IdentificationSettings()


@pytest.fixture(scope="module")
def log():
    frame, _ = identification_frame({"steer_left": 6.0, "steer_right": 6.0, "straight": 8.0, "rotation": 8.0},
                                    align=0.5)
    rng = np.random.default_rng(7)
    for c in [c for c in frame.columns if c.startswith(("m_", "alpha", "beta"))]:
        frame[c] = frame[c] + 1e-4 * rng.standard_normal(len(frame))
    return Log.from_frame(frame, sidecar={"torque_lead": 0.5})


def _close(a, b, rtol=1e-12):
    scale = max(np.abs(b).max(), 1e-300)
    assert np.abs(np.asarray(a) - np.asarray(b)).max() <= rtol * scale


def test_stretch_signals_equal_the_numpy_formulation(log):
    n = len(log.t)
    st = filtered_stretch(PROTOTYPE, log, 0, n, SETTINGS)
    dt = st.dt
    f = lowpass(np.concatenate([log.alpha, log.beta], axis=1), dt, SETTINGS.rows.filter)
    d = time_derivative(f, dt)
    dd = time_derivative(d, dt)
    alpha = np.clip(f[:, :2], -math.pi / 2, math.pi / 2)
    np.testing.assert_array_equal(st.alpha, alpha)
    _close(st.alpha_dot, d[:, :2])
    _close(st.beta_ddot, dd[:, 2:])
    chassis = odometry_with_slip(PROTOTYPE, alpha, d[:, :2], d[:, 2:])[0]
    _close(st.chassis_dot, chassis)
    # slip: the same angles, the steering rates of the lighter slip filter and the raw wheel rates
    fast = time_derivative(lowpass(log.alpha, dt, slip_filter(SETTINGS, dt)), dt)
    _, slip = odometry_with_slip(PROTOTYPE, alpha, fast, time_derivative(np.asarray(log.beta), dt))
    _close(st.slip, slip, 1e-9)
    _close(st.chassis_ddot, time_derivative(chassis, dt))
    q_dot = np.concatenate([chassis, d], axis=1)
    q_ddot = np.concatenate([time_derivative(chassis, dt), dd], axis=1)
    both = lowpass(np.concatenate([regressor_signals(q_dot, q_ddot, SETTINGS.rows.epsilon),
                                   align_torque(log.torque, 0.5)], axis=1), dt, SETTINGS.rows.filter)
    _close(st.signals, both[:, :21], 1e-10)
    _close(st.torque, both[:, 21:])


def test_modes_equal_the_rules_on_numpy(log):
    st = filtered_stretch(PROTOTYPE, log, 0, len(log.t), SETTINGS)
    mode, _ = _modes_and_virtual_angle(PROTOTYPE, st, SETTINGS)
    config = detect_mode(PROTOTYPE, st.alpha, SETTINGS.rows.mode_tolerance).astype(np.int8)
    H1 = kinematic_model(PROTOTYPE, Mode.PARKING, st.alpha[:1])[0]
    rest = row_max_abs(st.beta_dot - st.alpha_dot @ H1[5:].T) * PROTOTYPE.r < SETTINGS.rows.rest_speed
    steering = row_max_abs(st.alpha_dot) > SETTINGS.rows.steering_rest_rate
    expected = config.copy()
    expected[rest & steering] = int(Mode.PARKING)
    expected[~rest & (config == int(Mode.PARKING))] = NO_MODE
    straight = ~rest & steering & (config == int(Mode.STRAIGHT))
    on_icr = np.abs(icr_residual(PROTOTYPE, st.alpha)) <= SETTINGS.rows.mode_tolerance
    expected[straight] = np.where(on_icr[straight], int(Mode.CAR_LIKE), NO_MODE)
    expected[~rest & steering & np.isin(config, [int(Mode.LATERAL), int(Mode.ROTATION)])] = NO_MODE
    np.testing.assert_array_equal(mode, expected)
    assert set(np.unique(mode)) >= {int(Mode.PARKING), int(Mode.STRAIGHT), int(Mode.ROTATION)}


@pytest.mark.parametrize("steering_guard", [2.0, 4.0])  # the chassis' guard, and the steering's default
def test_projection_mask_and_guard_equal_projected_block(log, steering_guard):
    settings = SETTINGS.replace(steering_guard=steering_guard)
    st = filtered_stretch(PROTOTYPE, log, 0, len(log.t), settings)
    mode, av = _modes_and_virtual_angle(PROTOTYPE, st, SETTINGS)
    usable = ~st.edge & (mode != NO_MODE)
    usable[len(usable) // 3: len(usable) // 3 + 40] = False  # a hole: the guard acts inside a run
    mine = np.ones(st.n, dtype=bool)
    guards = {c: settings.rows.guard_samples(g, st.dt) for c, g in settings.rows.guards().items()}
    assert guards["x_ch"] == 25 and guards["alpha_l"] == round(12.5 * steering_guard)  # 2 ms samples, 40 rad/s
    blocks = _stretch_blocks(PROTOTYPE, st, mode, av, usable, None, settings, "r", mine)
    assert blocks
    for b in blocks:
        a, e = int(b.sample[0]), int(b.sample[-1]) + 1
        ref = projected_block(PROTOTYPE, b.mode, st.alpha[a:e], st.q_dot[a:e], st.signals[a:e], st.torque[a:e],
                              t=st.t[a:e], source="", segment="", stiction_threshold=SETTINGS.rows.thresholds(),
                              mode_tolerance=SETTINGS.rows.mode_tolerance, recording="r", sample=np.arange(a, e))
        _close(b.regressor, ref.regressor, 1e-11)
        _close(b.torque, ref.torque, 1e-9)
        _close(b.s_dot, ref.s_dot, 1e-9)  # sums of wheel rates that cancel: round-off of the q_dot scale
        _close(np.asarray(b.offset_regressor), np.asarray(ref.offset_regressor))
        for j, coordinate in enumerate(b.mode.coordinates):
            np.testing.assert_array_equal(b.keep[:, j], guarded_mask(ref.keep[:, j:j + 1] & usable[a:e, None],
                                                                     guards[coordinate])[:, 0])


def test_kept_rows_are_the_blocks_rows_in_order(log):
    blocks = log_rows(log, PROTOTYPE, SETTINGS).blocks
    reduction = reduce_blocks(blocks, 15, offsets=True)
    expected = [np.concatenate([b.regressor[b.keep[:, j], j], b.offset_regressor[b.keep[:, j], j],
                                b.torque[b.keep[:, j], j][:, None]], axis=1)
                for b in blocks for j in range(len(b.coordinates)) if b.keep[:, j].any()]
    np.testing.assert_array_equal(reduction.rows, np.concatenate(expected))
    stats = RowStatistics(15)
    row_statistics(blocks, stats, None, {}, offsets=True)
    for key, n in stats.counts.items():
        rows = np.concatenate([e for b, e in zip([(b, j) for b in blocks for j in range(len(b.coordinates))
                                                  if b.keep[:, j].any()], expected)
                               if (b[0].segment, b[0].coordinates[b[1]]) == key])
        assert n == rows.shape[0]
        P = stats.factor(key)
        np.testing.assert_allclose(P.T @ P, rows.T @ rows, atol=1e-10 * np.abs(rows.T @ rows).max())


def test_recording_breaks_equal_the_numpy_rules():
    rng = np.random.default_rng(2)
    n = 2000
    t = np.arange(n) * 0.002
    t[700:] += 0.01  # a dropout
    alpha = np.cumsum(rng.normal(0, 1e-3, (n, 2)), axis=0)
    beta = np.cumsum(rng.normal(0, 1e-2, (n, 4)), axis=0)
    alpha[1200:, 1] += 0.5  # a steering jump
    beta[1500:, 2] += 5.0  # an encoder reset
    bounds, notes = stretch_bounds(t, alpha, beta, SETTINGS)
    assert bounds == [(0, 700), (700, 1200), (1200, 1500), (1500, n)]
    assert "dropout" in notes[0] and "steering" in notes[1] and "wheel" in notes[2]
    kind = np.empty(n - 1, dtype=np.int8)
    assert recording_breaks(t, alpha, beta, 1.0, 10.0, 10.0, kind) == 0


@numba.njit(cache=False)
def _sincos_of(x, out):
    for i in range(x.size):
        out[i, 0], out[i, 1] = sincos_steering(x[i])


@hsettings(deadline=None)
@given(hst.lists(hst.floats(-math.pi / 2, math.pi / 2), min_size=1, max_size=50))
def test_sincos_of_a_steering_angle_is_within_one_ulp_of_numpy(angles):
    x = np.array(angles + [math.pi / 2, -math.pi / 2, math.pi / 4, 0.0, 1e-300])
    out = np.empty((x.size, 2))
    _sincos_of(x, out)
    for got, want in ((out[:, 0], np.sin(x)), (out[:, 1], np.cos(x))):
        assert np.all(np.abs(got - want) <= np.spacing(np.abs(want)))


def test_sincos_of_a_steering_angle_is_exact_on_most_of_a_grid():
    x = np.linspace(-math.pi / 2, math.pi / 2, 100_001)
    out = np.empty((x.size, 2))
    _sincos_of(x, out)
    assert np.mean(out[:, 0] == np.sin(x)) > 0.9 and np.mean(out[:, 1] == np.cos(x)) > 0.9
    assert np.max(np.abs(out[:, 1] - np.cos(x)) / np.spacing(np.abs(np.cos(x)))) <= 1.0


@given(hst.lists(hst.floats(0.0, 10.0), min_size=1, max_size=60))
def test_median_and_mad_equal_numpy(values):
    from agvdyn.identification.slip import median_and_mad

    x = np.array(values)
    med, mad = median_and_mad(x)
    assert med == np.median(x)
    assert mad == np.median(np.abs(x - np.median(x)))
