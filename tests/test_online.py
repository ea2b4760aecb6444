"""Online payload tracking (issue 31): causal rows, the tracker's update, change detection on
simulated payload steps, ``agvdyn track``, and identify's split test (identification/change.py).

Margins: on 20 seeds of ``driving`` with +10..60 % steps (docs/online.md) the m_ch error 3 s after
detection was at most 2.1 % and the latency after the first excited motion at most ~1.3 s but
for routes whose first motion after the step hardly accelerates; the tests use one seed each and
assert with about 1.5x those figures."""
from __future__ import annotations

import json

import numpy as np
import pytest

from agvdyn.io import load_log
from agvdyn.online import TrackerSettings, track
from agvdyn.online.rows import OnlineRows, causal_lowpass, group_delay
from agvdyn.online.tracker import TrackerState, run_tracker
from agvdyn.platform import PAPER_PARAMETERS as P, PROTOTYPE
from agvdyn.row_rules import FilterSettings
from agvdyn.simulation import SimulationSettings, simulate
from agvdyn.simulation.payload import PayloadEvent
from agvdyn.trajectories import experiment

STEP = PayloadEvent(30.0, 0.4 * P.m_ch, 0.0, 0.0, 0.4 * P.m_ch * (1.2 ** 2 + 0.8 ** 2) / 12)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A 70 s shift without and with a +40 % pick-up at 30 s (seed 2)."""
    root = tmp_path_factory.mktemp("online")
    traj = experiment("driving", duration=70, seed=2)
    out = {}
    for name, payload in (("free", ()), ("step", (STEP,))):
        path = root / f"{name}.parquet"
        simulate(traj, settings=SimulationSettings(payload=payload), seed=2).write(path)
        out[name] = path
    return out


def test_causal_filter_starts_at_rest_and_delays_by_its_group_delay():
    sos = FilterSettings().sos(2e-3)
    x = np.full((50, 2), 3.0)
    np.testing.assert_allclose(causal_lowpass(x, sos), 3.0, rtol=1e-12)
    assert group_delay(sos, 2e-3) == pytest.approx(2.613 / 40.0, rel=0.02)  # order 4: sum 1/sin of the pole angles
    t = np.arange(4000) * 2e-3
    ramp = np.column_stack([t, t])
    late = ramp[-1, 0] - causal_lowpass(ramp, sos)[-1, 0]
    assert late == pytest.approx(group_delay(sos, 2e-3), rel=1e-3)  # a ramp lags by exactly the delay


def _synthetic(n: int, theta: np.ndarray, step_at: int, step: np.ndarray, seed: int = 0) -> OnlineRows:
    """Rows of straight runs and rotations, z = phi . theta + bias + noise, theta stepping at ``step_at``."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 2e-3
    phi = np.zeros((n, 2))
    kind = np.zeros(n, dtype=np.int8)
    phase = (t // 2.0).astype(int) % 2  # 2 s of translation, 2 s of rotation
    acc = 0.4 * np.sin(2 * np.pi * t / 2.0)
    phi[phase == 0, 0] = acc[phase == 0]
    phi[phase == 1, 1] = acc[phase == 1]
    kind[phase == 0], kind[phase == 1] = 1, 5
    true = np.where(np.arange(n)[:, None] >= step_at, theta + step, theta)
    z = np.einsum("ni,ni->n", phi, true) + np.where(kind == 1, 7.0, 12.0) + rng.normal(0, 2.0, n)
    return OnlineRows(t, phi, z, kind, 0.0, 0, 2e-3)


def test_tracker_detects_a_step_resets_and_keeps_quiet_without_one():
    theta = np.array([P.m_ch, P.C_ch])
    st = TrackerSettings(correlation=1.0, rotation_correlation=1.0)  # white noise: every row independent
    rows = _synthetic(40000, theta, 20000, np.array([0.2 * P.m_ch, 0.15 * P.C_ch]))
    est, var, nis, flag, events = run_tracker(rows, TrackerState.initial(P, {}, st), st, theta)
    assert [e.parameter for e in events] == ["m_ch", "C_ch"] or [e.parameter for e in events] == ["C_ch", "m_ch"]
    for e in events:
        assert 40.0 <= e.t_detected < 44.0 and e.t_change_estimate <= e.t_detected and e.sign == 1
    np.testing.assert_allclose(est[-1, :2], theta * (1.2, 1.15), rtol=2e-3)
    assert np.all(var[:, :2] > 0) and np.nanmean(nis) == pytest.approx(1.0, abs=0.2)
    quiet = _synthetic(40000, theta, 40000, np.zeros(2), seed=1)
    assert run_tracker(quiet, TrackerState.initial(P, {}, st), st, theta)[4] == []


def test_payload_step_is_tracked_on_the_simulator(logs):
    free = track([load_log(logs["free"])], PROTOTYPE, P)
    assert free.events == ()
    assert abs(free.final()["m_ch"]["value"] / P.m_ch - 1) < 0.01
    res = track([load_log(logs["step"])], PROTOTYPE, P)
    m_events = [e for e in res.events if e.parameter == "m_ch"]
    assert len(m_events) == 1 and all(e.t_detected > STEP.t for e in res.events)
    e = m_events[0]
    assert e.t_detected - e.t_change_estimate < 1.5 and e.after_std > 0
    est, std = res.value_at(e.t_detected + 3.0)
    assert abs(est[0] / (P.m_ch + STEP.mass) - 1) < 0.03 and 0 < std[0] < 0.03 * P.m_ch
    assert abs(res.final()["m_ch"]["value"] / (P.m_ch + STEP.mass) - 1) < 0.01


def test_table_is_decimated_without_losing_events(logs):
    res = track([load_log(logs["step"])], PROTOTYPE, P)
    tab = res.table(5.0)
    assert list(tab) == ["t", "m_ch", "m_ch_std", "C_ch", "C_ch_std", "nis", "event"]
    assert np.median(np.diff(tab["t"])) == pytest.approx(0.2)
    assert int(np.bitwise_or.reduce(tab["event"])) == int(np.bitwise_or.reduce(res.event)) != 0
    assert np.all(tab["m_ch_std"] > 0) and np.all(tab["C_ch_std"] > 0)


def test_cli_track(logs, tmp_path):
    from typer.testing import CliRunner

    from agvdyn.cli import app
    from agvdyn.platform import write_parameters

    params = tmp_path / "params.yaml"
    write_parameters(params, P)
    out = tmp_path / "track.parquet"
    res = CliRunner().invoke(app, ["track", str(logs["step"]), "--params", str(params), "--out", str(out), "--json",
                                   "--rate", "2"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout[res.stdout.index("{"):])  # a warning on stderr may be mixed in
    assert {"final", "events", "group_delay", "latency"} <= set(data)
    assert data["events"] and {"t_detected", "t_change_estimate", "before", "after"} <= set(data["events"][0])
    import pandas as pd

    assert list(pd.read_parquet(out).columns) == ["t", "m_ch", "m_ch_std", "C_ch", "C_ch_std", "nis", "event"]
    again = CliRunner().invoke(app, ["track", str(logs["step"]), "--params", str(params), "--out", str(params)])
    assert again.exit_code == 2


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    """Identification logs (seed 1) without and with +250 kg picked up off-centre at 64 s (mid straight)."""
    from agvdyn.identification import identify, load_logs

    root = tmp_path_factory.mktemp("change")
    out = {}
    for name, payload in (("free", ()), ("step", (PayloadEvent(64.0, 250.0, 0.2, 0.1, 40.0),))):
        path = root / f"{name}.parquet"
        simulate("identification", settings=SimulationSettings(payload=payload), seed=1).write(path)
        out[name] = identify(load_logs([path]), PROTOTYPE)
    return out


def test_identify_change_detector_names_the_time(identified):
    """Split test: effect-free statistic 1.5 (seeds 1-3: <= 1.6), the step 16.7 against the threshold 8."""
    from agvdyn.identification.change import parameter_change

    free = identified["free"]
    assert parameter_change(free.blocks, free.parameters.to_vector()) == []
    step = identified["step"]
    found = parameter_change(step.blocks, step.parameters.to_vector())
    assert len(found) == 1
    assert abs(found[0].t - 64.0) < 2.0
    assert found[0].size["m_ch"] == pytest.approx(250.0, rel=0.3)
    assert json.dumps(found[0].to_dict())


def test_identify_warns_and_reports_parameter_change(identified):
    """identify itself (on the rows it keeps per recording, not the blocks): the load step is named in
    a warning and in ``parameter_change`` (time within 2 s, the size of m_ch within 30 %, C_ch untested
    where one side has no rotation: None, never a zero std); the effect-free log gives null and no warning."""
    free, step = identified["free"], identified["step"]
    assert free.parameter_change is None and not any("parameter change" in w for w in free.warnings)
    change = step.parameter_change
    assert change is not None and abs(change["t"] - 64.0) < 2.0
    assert change["size"]["m_ch"] == pytest.approx(250.0, rel=0.3) and change["std"]["m_ch"] > 0
    assert change["std"]["C_ch"] is None or change["std"]["C_ch"] > 0
    assert any("parameter change" in w and "agvdyn track" in w for w in step.warnings)
    assert json.loads(json.dumps(step.to_json_dict()))["parameter_change"]["t"] == change["t"]
