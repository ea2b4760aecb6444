"""Wheel-slip scenario of the simulator: off by default, slip where and when configured, bursts in
the measured torques, the true slip in result and sidecar, settings round trip and errors."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import yaml

from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, WHEELS
from agvdyn.simulation import (
    SLIP_SCENARIO,
    SLIP_THRESHOLD,
    FrictionPatch,
    PlantSettings,
    SimulationSettings,
    SlipInterval,
    SlipSettings,
    TorqueBurst,
    plant_constants,
    read_settings,
    settings_from_dict,
    simulate,
)
from agvdyn.simulation._kernels import contact_points, patch_factors
from agvdyn.simulation.slip import slip_intervals

G = PROTOTYPE
STRIP = SLIP_SCENARIO.patches[0]


@pytest.fixture(scope="module")
def slipped():
    """The built-in identification experiment with the default slip scenario (`--slip`), seed 1."""
    return simulate("identification", settings=replace(SimulationSettings(), slip=SLIP_SCENARIO), seed=1)


@pytest.fixture(scope="module")
def ideal():
    """The identification experiment on the ideal plant, default settings otherwise (no slip scenario)."""
    return simulate("identification", settings=replace(SimulationSettings(), plant=PlantSettings().ideal()), seed=1)


def _samples(result, t0: float, t1: float) -> slice:
    return slice(int(np.searchsorted(result.t, t0 - 1e-9)), int(np.searchsorted(result.t, t1 - 1e-9)))


# --- off by default ---

def test_default_settings_have_no_slip_scenario(ideal):
    assert not SimulationSettings().slip.active
    assert SimulationSettings().slip == SlipSettings()
    np.testing.assert_array_equal(ideal.torque_burst, 0.0)
    # the tyres creep (the slip velocity carries the tyre force) but never slip
    assert ideal.slip_speed.shape == (ideal.t.size, 4)
    assert 0 < ideal.slip_speed.max() < 0.01
    assert ideal.slip_intervals() == []
    assert ideal.slip_intervals(threshold=0.01) == []
    assert ideal.sidecar()["slip_truth"] == []


def test_contact_points_and_patch_factors():
    """Contact points at the offset a along the axle (PLATFORM.md); patches by place and time, the
    smallest factor where they overlap."""
    c = plant_constants(G, PAPER_PARAMETERS, PlantSettings())
    pos = np.zeros((1, 9))
    cp = contact_points(c, pos)[0]
    half_l, half_b = G.l / 2, G.b / 2 + G.a
    np.testing.assert_allclose(cp, [[half_l, half_b], [-half_l, half_b], [half_l, -half_b], [-half_l, -half_b]])
    # turned by gamma = pi/2 about the origin after a shift to (1, 2), steering at 0.3 rad
    pos2 = np.zeros((1, 9))
    pos2[0, :5] = (1.0, 2.0, math.pi / 2, 0.3, -0.3)
    th = 0.3
    fl_body = np.array([G.l / 2 - G.a * math.sin(th), G.b / 2 + G.a * math.cos(th)])
    np.testing.assert_allclose(contact_points(c, pos2)[0, 0], [1.0 - fl_body[1], 2.0 + fl_body[0]], atol=1e-12)
    table = SlipSettings(patches=(
        FrictionPatch(0.5, x=(0.5, 1.0)),                    # the front wheels, always
        FrictionPatch(0.2, x=(0.5, 1.0), y=(0.0, 1.0), t=(1.0, 2.0)),   # fl during [1, 2) s
        FrictionPatch(0.3, t=(5.0, 6.0)),                     # whole floor during [5, 6) s
    )).patch_table()
    mu = np.zeros(4)
    for t, expected in ((0.0, [0.5, 1, 0.5, 1]), (1.5, [0.2, 1, 0.5, 1]), (2.0, [0.5, 1, 0.5, 1]),
                        (5.5, [0.3, 0.3, 0.3, 0.3])):
        patch_factors(c, pos[0], t, table, mu)
        np.testing.assert_array_equal(mu, expected)


# --- the scenario ---

def test_scenario_slips_at_the_configured_places_and_times(slipped):
    """`--slip` on identification: a few slip events, 50-200 samples, in straight and rotation, each
    right after a burst, with the front wheels on the slippery strip in the straight; none elsewhere."""
    events = slipped.slip_intervals()
    over = (slipped.slip_speed > SLIP_THRESHOLD).any(axis=1)
    assert 3 <= len(events) <= 6
    assert 50 <= over.sum() <= 200
    bursts = SLIP_SCENARIO.bursts
    for ev in events:
        assert isinstance(ev, SlipInterval) and ev.peak > SLIP_THRESHOLD
        causes = [b for b in bursts if b.t - 1e-9 <= ev.t_start <= b.t + b.duration]
        assert len(causes) == 1, ev
        assert ev.t_end <= causes[0].t + causes[0].duration + 0.1, ev
        segments = set(slipped.segment[_samples(slipped, ev.t_start, ev.t_end + 1e-3)].astype(str))
        assert segments <= {"straight", "rotation"}, ev
    # every slipping sample lies within 0.1 s after the start or end of a burst
    t_over = slipped.t[over]
    near = np.zeros(t_over.size, dtype=bool)
    for b in bursts:
        near |= (t_over >= b.t - 1e-9) & (t_over <= b.t + b.duration + 0.1)
    assert near.all(), t_over[~near]
    # straight: all-wheel bursts of 3 N m; only the front wheels on the strip slip
    x0, x1 = STRIP.x
    for t_burst, slips in ((67.0, True), (73.0, False), (75.5, True)):
        sl = _samples(slipped, t_burst, t_burst + 0.2)
        x = slipped.contact_points[sl.start, :, 0]
        on_strip = (x >= x0) & (x < x1)
        np.testing.assert_array_equal(on_strip, [slips, False, slips, False])
        peak = slipped.slip_speed[sl].max(axis=0)
        assert (peak[on_strip] > 0.1).all() and (peak[~on_strip] < 0.02).all(), (t_burst, peak)
    straight = [ev for ev in events if ev.t_start < 80]
    assert [round(ev.t_start, 1) for ev in straight] == [67.0, 75.5]
    assert all(ev.wheels == ("fl", "fr") for ev in straight)
    # rotation: a 12 N m burst on the normal floor and a 3 N m burst in the slippery time window
    rotation = [ev for ev in events if ev.t_start > 80]
    assert [round(ev.t_start, 1) for ev in rotation] == [96.0, 105.5]


def test_measured_torques_include_the_bursts(slipped):
    expected = SLIP_SCENARIO.burst_torques(slipped.t)
    np.testing.assert_array_equal(slipped.torque_burst, expected)
    # 80 ms of all wheels at 2 ms: 40 samples each
    assert (np.abs(expected[:, 0]) > 0).sum() == 3 * 40 + 30
    assert (np.abs(expected[:, 3]) > 0).sum() == 3 * 40 + 30
    assert (np.abs(expected[:, 1]) > 0).sum() == 3 * 40 + 30 + 30
    lim = slipped.settings.plant.torque_limit
    np.testing.assert_allclose(slipped.torque_applied, np.clip(slipped.torque_command, -lim, lim) + expected,
                               atol=1e-12)
    # the sensors measure what the motors apply: noise and offset only (0.02 N m each)
    assert np.abs(slipped.torque_measured - slipped.torque_applied).max() < 0.2
    log = slipped.log_frame()
    k = int(np.flatnonzero(expected[:, 0] == 12.0)[0])
    for i, w in enumerate(WHEELS):
        assert log[f"m_{w}"].iloc[k] == pytest.approx(slipped.torque_applied[k, i], abs=0.2)
        assert abs(log[f"m_{w}"].iloc[k] - slipped.torque_command[k, i]) > 5.0
    # a burst is not saturation of the drive; the controller's push back against the largest is
    saturated = np.flatnonzero((np.abs(slipped.torque_command) > lim).any(axis=1))
    assert saturated.size and (np.abs(slipped.t[saturated] - 96.03) < 0.2).all()
    n_rotation = int((slipped.segment == "rotation").sum())
    tracking = slipped.tracking().set_index("segment")
    assert tracking.loc["rotation", "saturated"] * n_rotation == pytest.approx(saturated.size)


def test_energy_balance_holds_with_slip(slipped):
    """Motor work (bursts included) = dissipated work + stop work + change of kinetic energy."""
    w_motor, w_diss, w_stop = slipped.work[-1]
    balance = slipped.energy[-1] - slipped.energy[0] + w_diss - w_stop - w_motor
    assert abs(balance) < 1e-3 * w_motor


def test_sidecar_records_scenario_and_truth(slipped):
    side = yaml.safe_load(yaml.safe_dump(slipped.sidecar(), sort_keys=False))
    assert settings_from_dict(side["settings"]) == slipped.settings
    truth = side["slip_truth"]
    assert truth == [ev.to_dict() for ev in slipped.slip_intervals()]
    assert [set(d) for d in truth] == [{"t_start", "t_end", "peak_mps", "wheels"}] * len(truth)
    assert all(set(d["wheels"]) <= set(WHEELS) for d in truth)
    assert side["slip_truth_threshold"] == SLIP_THRESHOLD


def test_slip_intervals_of_given_speeds():
    t = np.arange(10) * 0.01
    speed = np.zeros((10, 4))
    speed[2:4, 1] = (0.06, 0.2)
    speed[5, 3] = 0.07
    speed[9, 0] = 0.08
    assert slip_intervals(t, speed, 0.05, merge_gap=0.0) == [
        SlipInterval(0.02, 0.03, 0.2, ("rl",)), SlipInterval(0.05, 0.05, 0.07, ("rr",)),
        SlipInterval(0.09, 0.09, 0.08, ("fl",))]
    assert slip_intervals(t, speed, 0.05, merge_gap=0.02) == [
        SlipInterval(0.02, 0.05, 0.2, ("rl", "rr")), SlipInterval(0.09, 0.09, 0.08, ("fl",))]
    assert slip_intervals(t, speed, 0.5) == []
    with pytest.raises(ValueError, match="threshold=-1"):
        slip_intervals(t, speed, -1)


# --- settings ---

def test_settings_yaml_round_trip(tmp_path):
    custom = replace(SimulationSettings(), slip=SLIP_SCENARIO)
    path = tmp_path / "slip.yaml"
    path.write_text(yaml.safe_dump(custom.to_dict(), sort_keys=False), encoding="utf-8")
    assert read_settings(path) == custom
    # the documented short form: lists for intervals, wheels optional, unbounded sides omitted
    path.write_text("slip:\n  patches:\n    - {x: [1.75, 2.35], y: [-1.5, 1.5], mu_factor: 0.15}\n"
                    "    - {t: [105.4, 105.7], mu_factor: 0.15}\n"
                    "  bursts:\n    - {t: 67.0, torque: 3.0, duration: 0.08}\n"
                    "    - {t: 73.0, torque: 3.0, duration: 0.08}\n"
                    "    - {t: 75.5, torque: -3.0, duration: 0.08}\n"
                    "    - {t: 96.0, torque: 12.0, duration: 0.06}\n"
                    "    - {t: 105.5, torque: 3.0, duration: 0.06, wheels: [rl, fr]}\n", encoding="utf-8")
    assert read_settings(path).slip == SLIP_SCENARIO
    assert settings_from_dict({}).slip == SlipSettings() == settings_from_dict({"slip": None}).slip


@pytest.mark.parametrize("slip, words", [
    ({"patches": [{"mu_factor": 1.5}]}, ["patches[0]", "mu_factor=1.5"]),
    ({"patches": [{"mu_factor": 0.0}]}, ["patches[0]", "mu_factor=0.0"]),
    ({"patches": [{"x": [2.0, 1.0]}]}, ["patches[0]", "x=[2.0, 1.0]"]),
    ({"patches": [{"t": [-1.0, 1.0]}]}, ["patches[0]", "t=[-1.0, 1.0]"]),
    ({"patches": [{"y": 3}]}, ["patches[0]", "y=3"]),
    ({"patches": [{"mu": 0.1}]}, ["patches[0]", "unknown keys ['mu']"]),
    ({"bursts": [{"t": 1.0, "torque": 5.0}, {"t": 2.0, "torque": 5.0, "wheels": ["fl", "xx"]}]},
     ["bursts[1]", "wheels=['fl', 'xx']"]),
    ({"bursts": [{"t": 1.0, "torque": 5.0, "duration": 0}]}, ["bursts[0]", "duration=0"]),
    ({"bursts": [{"t": 1.0, "torque": "big"}]}, ["bursts[0]", "torque='big'"]),
    ({"bursts": [{"torque": 5.0}]}, ["bursts[0]", "'t'"]),
    ({"bursts": {"t": 1.0}}, ["bursts=", "expected a list"]),
    ({"floor": []}, ["slip", "unknown keys ['floor']"]),
    ([1, 2], ["slip", "[1, 2]"]),
])
def test_bad_slip_settings_are_named(slip, words):
    with pytest.raises(ValueError) as info:
        settings_from_dict({"slip": slip}, "run.yaml")
    message = str(info.value)
    assert message.startswith("run.yaml: slip")
    for w in words:
        assert w in message, message


def test_slip_settings_check_their_values():
    with pytest.raises(ValueError, match=r"mu_factor=2"):
        FrictionPatch(mu_factor=2)
    with pytest.raises(ValueError, match=r"wheels='front'"):
        TorqueBurst(t=1.0, torque=1.0, wheels="front")
    with pytest.raises(ValueError, match="patches"):
        SlipSettings(patches=({"mu_factor": 0.1},))
    assert TorqueBurst(1.0, 2.0, wheels="fl").wheels == ("fl",)


# --- command line ---

def test_cli_slip_flag(tmp_path):
    from typer.testing import CliRunner

    import agvdyn.cli  # noqa: F401
    from agvdyn.cli._app import app
    from agvdyn.io import read_log

    out = tmp_path / "slip.parquet"
    res = CliRunner().invoke(app, ["simulate", "identification", "--slip", "--seed", "1", "--quiet", "--out", str(out)])
    assert res.exit_code == 0, res.output
    side = read_log(out).sidecar
    assert settings_from_dict(side["settings"]).slip == SLIP_SCENARIO
    assert [round(d["t_start"], 1) for d in side["slip_truth"]] == [67.0, 75.5, 96.0, 105.5]
