"""Validation on an unseen lane change (mode 2): NRMSE definition and sensitivity."""
from __future__ import annotations

import json

import numpy as np
import pytest

from agvdyn.identification import IdentificationSettings
from agvdyn.io import Log, write_log
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
