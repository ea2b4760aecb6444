"""Validation on an unseen lane change (mode 2): NRMSE definition and sensitivity; the model beyond
the paper (issue 30): Stribeck friction, an off-centre load and a torque delay predicted through the
same rows as the identification."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from agvdyn.identification import IdentificationSettings
from agvdyn.io import Log, write_log
from agvdyn.model_file import write_model_parameters
from agvdyn.model_spec import ModelParameters, ModelSpec
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, ParameterFile, write_parameters
from agvdyn.validation import nrmse, validate, write_validation
from model_logs import lane_change_frame


@pytest.fixture(scope="module")
def lane_log(tmp_path_factory):
    frame, _ = lane_change_frame(10.0)
    path = tmp_path_factory.mktemp("val") / "lane.csv"
    write_log(path, frame)
    return path


def test_nrmse_definition():
    measured = np.array([1.0, -1.0, 1.0, -1.0])
    assert nrmse(measured, measured) == 0.0
    assert nrmse(measured, np.zeros(4)) == pytest.approx(1.0)
    assert nrmse(measured, 0.5 * measured) == pytest.approx(0.5)
    assert np.isnan(nrmse(np.zeros(3), np.ones(3)))


def test_true_parameters_predict_the_lane_change(lane_log):
    val = validate(lane_log, PAPER_PARAMETERS, PROTOTYPE)
    assert set(val.nrmse) == {"lane_change:alpha_v", "lane_change:x_ch"}
    # noise-free model data: only filter edges and derivative errors remain
    assert max(val.nrmse.values()) < 5e-3
    assert max(val.nrmse_moving.values()) < 1e-4
    assert (val.table["n_moving"] < val.table["n_rows"]).all()


def test_wrong_parameters_are_seen(lane_log, tmp_path):
    wrong = PAPER_PARAMETERS.replace(m_ch=1.1 * PAPER_PARAMETERS.m_ch, d_vw=1.5 * PAPER_PARAMETERS.d_vw)
    path = write_parameters(tmp_path / "wrong.yaml", ParameterFile(wrong))
    val = validate(lane_log, path, PROTOTYPE)
    assert val.nrmse["lane_change:x_ch"] > 0.02
    out = write_validation(tmp_path / "val.json", val)
    data = json.loads(out.read_text())
    assert data["nrmse"]["lane_change:x_ch"] == pytest.approx(val.nrmse["lane_change:x_ch"])


def test_literal_filtering_option(lane_log):
    val = validate(lane_log, PAPER_PARAMETERS, PROTOTYPE, settings=IdentificationSettings.from_flat(filtering="literal"))
    assert max(val.nrmse_moving.values()) < 1e-3
    frame = val.torques_frame()
    assert {"measured", "model", "kept", "coordinate"} <= set(frame.columns)


def test_log_without_motion_mode_is_refused():
    """The chassis moves with steering angles of no motion mode (alpha_l off the ICR relation)."""
    frame, _ = lane_change_frame(4.0)
    frame["alpha_l"] = frame["alpha_l"] + 0.3
    with pytest.raises(ValueError, match="no row in a motion mode"):
        validate(Log.from_frame(frame), PAPER_PARAMETERS, PROTOTYPE)


def test_labels_are_hints_for_validation_too():
    """A lane change labelled 'align' is still validated as the car-like motion it is."""
    frame, _ = lane_change_frame(4.0)
    frame["segment"] = "align"
    val = validate(Log.from_frame(frame), PAPER_PARAMETERS, PROTOTYPE)
    assert val.nrmse_moving["align:x_ch"] < 0.05


# --- the model beyond the paper (issue 30) --------------------------------------------------------------


P = PAPER_PARAMETERS
BREAKAWAY = {"d_sl": 1.4 * P.d_cl, "d_sr": 1.3 * P.d_cr, "d_sw": 1.5 * P.d_cw, "w_sl": 0.05, "w_sr": 0.05, "w_sw": 0.1}
OFFSET = {"x_c": 0.15, "y_c": -0.1}
EXTENDED = ModelParameters(P, {**BREAKAWAY, **OFFSET}, spec=ModelSpec(friction="stribeck", com_offset=True))


def _delayed(frame, samples: int):
    """The torque columns lagging the angles by whole samples: logged(t) = applied(t - samples dt)."""
    out = frame.copy()
    columns = ["m_fl", "m_rl", "m_fr", "m_rr"]
    out[columns] = np.concatenate([np.repeat(frame[columns].to_numpy()[:1], samples, axis=0),
                                   frame[columns].to_numpy()[:-samples]])
    return out


@pytest.fixture(scope="module")
def extended_lane_log():
    """An exact lane change of the extended model (breakaway on every joint group, load off centre)."""
    frame, _ = lane_change_frame(10.0, params=EXTENDED)
    return Log.from_frame(frame)


def test_paper_model_as_model_parameters_validates_identically(lane_log):
    val = validate(lane_log, P, PROTOTYPE)
    as_model = validate(lane_log, ModelParameters(P), PROTOTYPE)
    pd.testing.assert_frame_equal(val.table, as_model.table, check_exact=True)
    assert val.to_json_dict()["model"] == {"friction": "paper", "delay_s": 0.0, "com_offset": False}


def test_extended_model_predicts_its_own_lane_change(extended_lane_log):
    """The true extended model predicts as well as the paper's does its own data; the paper's model with
    the same 11 parameters misses the breakaway and the offset."""
    extended = validate(extended_lane_log, EXTENDED, PROTOTYPE)
    paper = validate(extended_lane_log, P, PROTOTYPE)
    assert max(extended.nrmse_moving.values()) < 2e-4
    assert max(paper.nrmse_moving.values()) > 20 * max(extended.nrmse_moving.values())
    frame = extended.torques_frame()
    kept = frame[frame["kept"]]
    assert np.abs(kept["measured"] - kept["model"]).max() < 1e-3 * np.abs(kept["measured"]).max()
    assert extended.to_json_dict()["model"] == {"friction": "stribeck", "delay_s": 0.0, "com_offset": True}


@pytest.mark.parametrize("effect", ["stribeck", "com_offset"])
def test_each_extension_alone_explains_its_effect(effect):
    extra = BREAKAWAY if effect == "stribeck" else OFFSET
    spec = ModelSpec(friction="stribeck") if effect == "stribeck" else ModelSpec(com_offset=True)
    model = ModelParameters(P, extra, spec=spec)
    frame, _ = lane_change_frame(10.0, params=model)
    log = Log.from_frame(frame)
    right, wrong = validate(log, model, PROTOTYPE), validate(log, P, PROTOTYPE)
    assert max(right.nrmse_moving.values()) < 2e-4 < max(wrong.nrmse_moving.values())


def test_delay_compares_the_measured_torque_shifted(lane_log):
    """Torque columns 3 samples (6 ms) late: the paper's model sees a worse fit; the model with
    delay_s = 6 ms reads the measured torques 6 ms later and finds the undelayed fit again."""
    frame, _ = lane_change_frame(10.0)
    log = Log.from_frame(_delayed(frame, 3))
    undelayed = validate(lane_log, P, PROTOTYPE)
    paper = validate(log, P, PROTOTYPE)
    delayed = ModelParameters(P, delay_s=0.006, spec=ModelSpec(delay=0.006))
    fixed = validate(log, delayed, PROTOTYPE)
    assert max(paper.nrmse_moving.values()) > 10 * max(undelayed.nrmse_moving.values())
    for key, value in fixed.nrmse_moving.items():
        assert value < 2 * undelayed.nrmse_moving[key] + 1e-5, key
    assert fixed.to_json_dict()["model"]["delay_s"] == 0.006


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_parameter_file_with_a_model_block(extended_lane_log, tmp_path, suffix):
    path = write_model_parameters(tmp_path / f"model{suffix}", ParameterFile(P, geometry=PROTOTYPE),
                                  EXTENDED.spec, EXTENDED.extra, {})
    from_file = validate(extended_lane_log, path, PROTOTYPE)
    direct = validate(extended_lane_log, EXTENDED, PROTOTYPE)
    pd.testing.assert_frame_equal(from_file.table, direct.table, check_exact=True)
    assert from_file.model.spec.stribeck and from_file.model.extra["x_c"] == 0.15


def test_model_block_errors_name_the_file(tmp_path, lane_log):
    path = tmp_path / "bad.yaml"
    write_parameters(path, ParameterFile(P))
    path.write_text(path.read_text() + "model: {friction: coulomb}\n")
    with pytest.raises(ValueError, match=r"bad\.yaml: model: friction='coulomb'"):
        validate(lane_log, path, PROTOTYPE)


def test_cli_validate_reads_the_model_block(tmp_path):
    """`agvdyn validate --params FILE` predicts with the file's model: the extended model explains its
    own lane change, the paper's file with the same 11 parameters does not."""
    from typer.testing import CliRunner

    import agvdyn.cli  # noqa: F401  (registers the commands)
    from agvdyn.cli._app import app

    frame, _ = lane_change_frame(10.0, params=EXTENDED)
    log = write_log(tmp_path / "lane.csv", frame)
    model = write_model_parameters(tmp_path / "model.yaml", ParameterFile(P, geometry=PROTOTYPE), EXTENDED.spec,
                                   EXTENDED.extra, {})
    paper = write_parameters(tmp_path / "paper.yaml", ParameterFile(P, geometry=PROTOTYPE))
    runs = {}
    for name, params in (("model", model), ("paper", paper)):
        result = CliRunner().invoke(app, ["validate", str(log), "--params", str(params), "--json"])
        assert result.exit_code == 0, result.output
        runs[name] = json.loads(result.stdout)
    assert runs["model"]["model"] == {"friction": "stribeck", "delay_s": 0.0, "com_offset": True}
    assert runs["paper"]["model"]["friction"] == "paper"
    ours, theirs = (runs[k]["nrmse_without_stiction"]["lane_change:x_ch"] for k in ("model", "paper"))
    assert ours < 1e-3 < theirs
