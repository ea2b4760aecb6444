"""Breakaway (Stribeck) friction on the MuJoCo plant (issue 30; simulation/mujoco_friction.py).

MuJoCo runs the joints with its own dry-friction constraint (at the static level ``d_s = ratio d_c``,
stiffened so that a stuck joint stays stuck) plus an assist along the motion in ``qfrc_applied``. The
friction a joint feels is read from MuJoCo itself: the force of its ``mjCNSTR_FRICTION_DOF`` row
(``efc_force``; its Jacobian is the unit vector of the dof) plus the applied assist. Checked on the
vehicle on jacks (mujoco_lifted.lifted_model: no contact, the joints' own dynamics), with the assist
written once per 2 ms sample and two 1 ms MuJoCo steps, as mujoco_stepper does.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

mujoco = pytest.importorskip("mujoco")

from agvdyn.model_spec import breakaway_weight, joint_friction  # noqa: E402
from agvdyn.platform import PAPER_PARAMETERS as P, PROTOTYPE as G  # noqa: E402
from agvdyn.simulation import SimulationSettings, simulate  # noqa: E402
from agvdyn.simulation.mujoco_friction import BreakawayFriction, breakaway_friction  # noqa: E402
from agvdyn.simulation.mujoco_lifted import lifted_model  # noqa: E402
from agvdyn.simulation.mujoco_plant import MujocoVehicle  # noqa: E402
from agvdyn.simulation.payload import PayloadEvent  # noqa: E402
from agvdyn.simulation.plant import PlantSettings  # noqa: E402
from agvdyn.trajectories import experiment  # noqa: E402

VEHICLE = MujocoVehicle.generate(G, P)
SAMPLE_STEPS = 2  # 1 ms MuJoCo steps per 2 ms sample (EngineOptions.timestep)


def _on_jacks(ratio: float, w_s: float):
    model = lifted_model(VEHICLE)
    brk = breakaway_friction(model, PlantSettings().with_breakaway("all", ratio, w_s), "test")
    return model, mujoco.MjData(model), brk


def _dof(model, joint: str) -> int:
    return int(model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)])


def _run(model, data, brk, samples: int, torques: dict[int, float]) -> np.ndarray:
    """Samples of (rate the assist used, rate after the step, MuJoCo's friction force + assist) per dof
    of ``torques`` (dof -> external torque, N m, added to the assist's row of qfrc_applied), one row per
    MuJoCo step: (steps, len(torques), 3)."""
    dofs = list(torques)
    rows = []
    for _ in range(samples):
        brk.assist(data.qvel, data.qfrc_applied)
        held = data.qvel[dofs].copy()
        assist = data.qfrc_applied[dofs].copy()
        for dof, tau in torques.items():
            data.qfrc_applied[dof] += tau
        for _ in range(SAMPLE_STEPS):
            mujoco.mj_step(model, data)
            n = data.nefc
            rows_of = (data.efc_type[:n] == mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF)
            force = [data.efc_force[:n][rows_of & (data.efc_id[:n] == dof)].sum() for dof in dofs]
            rows.append(np.stack([held, data.qvel[dofs].copy(), np.array(force) + assist], axis=1))
    return np.array(rows)


@pytest.mark.parametrize("ratio, w_s", [(1.5, 0.1), (1.3, 0.05)])
def test_sliding_friction_is_the_stribeck_law(ratio, w_s):
    """A wheel driven at 1.1 d_s breaks away and runs up to 2-3.5 rad/s: the friction MuJoCo applies
    (constraint + assist) is ``d_c + (d_s - d_c) exp(-(w/w_s)^2)`` against the motion
    (model_spec.joint_friction, epsilon -> 0) at the rate the assist was computed from, to 1e-9 N m (the
    constraint saturated at d_s while sliding); at the rate after the step within the law's change
    over the 2 ms hold, ``max|law'| |dw|`` with ``max|law'| = (d_s - d_c) sqrt(2/e) / w_s``."""
    model, data, brk = _on_jacks(ratio, w_s)
    wheel = _dof(model, "wheel_fl")
    d_c, d_s = P.d_cw, ratio * P.d_cw
    rec = _run(model, data, brk, 1500, {wheel: 1.1 * d_s})[:, 0]
    held, now, force = rec.T
    sliding = held > 0.01  # above MuJoCo's creep (~4e-4 rad/s) and the tanh's epsilon of the comparison
    for rate in (0.02, w_s / 2, w_s, 2 * w_s, 1.0):  # the run passes through these
        assert ((held > 0.8 * rate) & (held < 1.25 * rate)).any(), rate
    law = joint_friction(held[sliding], 0.0, d_c, d_s, w_s, epsilon=1e-12)
    np.testing.assert_allclose(-force[sliding], law, rtol=0, atol=1e-9)
    slope = (d_s - d_c) * np.sqrt(2 / np.e) / w_s
    law_now = joint_friction(now[sliding], 0.0, d_c, d_s, w_s, epsilon=1e-12)
    assert np.all(np.abs(-force[sliding] - law_now) <= slope * np.abs(now - held)[sliding] + 1e-9)
    assert held[-1] > 2.0 and -force[-1] == pytest.approx(d_c, abs=1e-9)  # fast: the paper's d_c


def test_stuck_below_the_breakaway_torque_and_sliding_above():
    """Held by a torque between d_c and d_s a joint stays stuck: after a start transient (the steering
    pair, whose rear joint follows through MuJoCo's soft equality: up to ~0.012 rad/s in the first
    steps, measured; bound 0.2 w_s) it creeps below 1e-3 rad/s (1 % of w_s) and turns less than 3 mrad
    in 2 s; above d_s it breaks away (the steering runs to its stop). Wheels: d_s of one joint; left steering:
    the coupled pair steer_fl + steer_rl (torque on steer_fl) holds up to the group's d_sl."""
    ratio, w_s = 1.5, 0.1
    cases = {"wheel_fl": ratio * P.d_cw, "steer_fl": ratio * P.d_cl}
    for joint, d_s in cases.items():
        for share, stuck in ((0.8, True), (0.97, True), (1.05, False)):
            model, data, brk = _on_jacks(ratio, w_s)
            dof = _dof(model, joint)
            qpos = int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)])
            start = data.qpos[qpos]
            rec = _run(model, data, brk, 1000, {dof: share * d_s})[:, 0]
            turned = abs(data.qpos[qpos] - start)
            if stuck:
                late = np.abs(rec[100:, 1]).max()  # after 0.1 s
                assert late < 1e-3 and turned < 3e-3 and np.abs(rec[:, 1]).max() < 0.2 * w_s, (joint, share, late, turned)
            else:
                assert rec[:, 1].max() > 0.5 and turned > 0.1, (joint, share, rec[:, 1].max(), turned)


@hsettings(max_examples=50, deadline=None)
@given(w=st.floats(-20.0, 20.0), ratio=st.floats(1.0, 3.0), w_s=st.floats(0.005, 0.5), d_c=st.floats(0.0, 20.0))
def test_assist_complements_the_static_level_to_the_law(w, ratio, w_s, d_c):
    """ratio d_c less the assist is the Stribeck level at any rate; the assist points along the motion
    and stays below the static level (the net friction dissipates)."""
    brk = BreakawayFriction(np.array([0]), np.array([(ratio - 1) * d_c]), np.array([w_s]))
    a = float(brk.assist_torques(np.array([w]))[0])
    assert a * w >= 0 and abs(a) <= (ratio - 1) * d_c * (1 + 1e-12)
    if w != 0:
        level = d_c + (ratio * d_c - d_c) * float(breakaway_weight(w, w_s))  # model_spec's Stribeck level
        assert ratio * d_c - abs(a) == pytest.approx(level, rel=1e-12, abs=1e-12)


def test_sidecar_carries_the_breakaway_truth_of_a_mujoco_run():
    """A MuJoCo run with breakaway in groups l and w: true_model friction stribeck with d_s = ratio d_c
    of each group (d_sr = d_cr: ratio 1) and the groups' w_s; also with a payload from t = 0 (both
    wrappers together); the same run without breakaway: the paper's parameters, no true_model. The
    breakaway changes the motion (the friction acts)."""
    traj = experiment("driving", duration=3, seed=2)
    base = SimulationSettings()
    brk = replace(base, plant=base.plant.with_breakaway("l", 1.5, 0.1).with_breakaway("w", 1.3, 0.05))
    plain, run = (simulate(traj, engine="mujoco", seed=2, settings=s) for s in (base, brk))
    side = run.sidecar()
    assert side["true_model"] == {"friction": "stribeck", "delay_s": 0.0, "com_offset": False,
                                  "stribeck_velocities": [0.1, 0.01, 0.05]}
    truth = side["true_parameters"]
    assert truth["d_sl"] == pytest.approx(1.5 * P.d_cl, rel=1e-12) and truth["d_sr"] == pytest.approx(P.d_cr)
    assert truth["d_sw"] == pytest.approx(1.3 * P.d_cw, rel=1e-12) and truth["w_sw"] == 0.05
    assert "true_model" not in plain.sidecar()
    assert not any(k.startswith(("d_s", "w_s")) for k in plain.sidecar()["true_parameters"])
    assert not np.array_equal(plain.log_frame()["beta_fl"].to_numpy(), run.log_frame()["beta_fl"].to_numpy())
    loaded = simulate(traj, engine="mujoco", seed=2,
                      settings=replace(brk, payload=(PayloadEvent(0.0, 150.0, 0.15, -0.1, 10.0),)))
    model = loaded.sidecar()
    assert model["true_model"]["friction"] == "stribeck" and model["true_model"]["com_offset"]
    assert model["true_parameters"]["d_sw"] == truth["d_sw"] and model["true_parameters"]["m_ch"] > P.m_ch


def test_without_breakaway_nothing_changes():
    """Ratio 1 everywhere: the model is left untouched (no assist). (Runs without breakaway were compared
    bit for bit with those before mujoco_friction.py on the machine it was written on; a stored hash is
    not a test that holds on every CPU.)"""
    model = VEHICLE.model()
    before = [model.dof_frictionloss.copy(), model.dof_solref.copy(), model.dof_solimp.copy()]
    assert breakaway_friction(model, PlantSettings().with_breakaway("all", 1.0, 0.3)) is None
    for a, b in zip(before, [model.dof_frictionloss, model.dof_solref, model.dof_solimp]):
        np.testing.assert_array_equal(a, b)


def test_breakaway_on_jacks_is_refused_on_mujoco():
    """The lifted MuJoCo run has MuJoCo's dry friction only: breakaway there is refused by name, never
    silently left out (our plant runs it)."""
    settings = SimulationSettings()
    settings = replace(settings, plant=settings.plant.with_breakaway("w", 1.3, 0.05))
    with pytest.raises(ValueError, match="lifted_wheel.*breakaway friction runs on the driving MuJoCo plant"):
        simulate("lifted-wheel", engine="mujoco", settings=settings)


def test_cli_simulate_mujoco_with_breakaway(tmp_path):
    """``agvdyn simulate --engine mujoco --breakaway``: runs (no longer refused) and the sidecar carries
    the truth; a bad group is still a named error."""
    from typer.testing import CliRunner

    from agvdyn.cli import app
    from agvdyn.io import read_log

    plan = tmp_path / "plan.yaml"
    plan.write_text("segments:\n  - name: straight\n    mode: straight\n"
                    "    fourier: {base_frequency: 2.0, a: [0.3, -0.1], b: [0.1, 0.2]}\n", encoding="utf-8")
    out = tmp_path / "run.parquet"
    runner = CliRunner()
    res = runner.invoke(app, ["simulate", str(plan), "--out", str(out), "--quiet", "--engine", "mujoco",
                              "--breakaway", "w=1.3:0.05"])
    assert res.exit_code == 0, res.output
    side = read_log(out).sidecar
    assert side["engine"] == "mujoco" and side["true_model"]["friction"] == "stribeck"
    assert side["true_parameters"]["d_sw"] == pytest.approx(1.3 * P.d_cw, rel=1e-12)
    res = runner.invoke(app, ["simulate", str(plan), "--out", str(tmp_path / "bad.parquet"), "--quiet",
                              "--engine", "mujoco", "--breakaway", "q=1.2"])
    assert res.exit_code == 2 and "unknown joint group 'q'" in res.output
