"""Acceptance of issue 5: an identification log round-tripped through a ROS 2 bag written with
ros2_control joint names gives the same identified parameters as the original log (within 0.1 %).

The log is model data of the paper's identification sequence (tests/model_logs.py: steer_left,
steer_right, straight, rotation, with alignment at rest between them) with sensor noise added,
so that the identification works on realistic, not exact, signals. The bag carries no segment
column: the segments come back through time ranges in the mapping, as a user would write them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from agvdyn.identification import identify
from agvdyn.io import LOG_COLUMNS, Log, load_log, mapping_from_dict, read_mapping, write_bag
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE

from model_logs import identification_frame

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "mappings" / "ros2_control.yaml"
DURATIONS = {"steer_left": 6.0, "steer_right": 6.0, "straight": 6.0, "rotation": 6.0}


def noisy_identification_log(seed: int = 5) -> Log:
    frame, _ = identification_frame(DURATIONS, align=1.0)
    rng = np.random.default_rng(seed)
    n = len(frame)
    for col in ("alpha_l", "alpha_r"):
        frame[col] = np.clip(frame[col] + rng.normal(0, 2e-4, n), -np.pi / 2, np.pi / 2)
    for w in ("fl", "rl", "fr", "rr"):
        frame[f"beta_{w}"] += rng.normal(0, 2e-4, n)
        frame[f"m_{w}"] += rng.normal(0, 0.05, n)
    return Log.from_frame(frame, sidecar={"platform": PROTOTYPE.to_dict()})


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_acceptance_identification_through_a_ros2_bag(tmp_path, storage):
    log = noisy_identification_log()
    mapping = read_mapping(EXAMPLE)
    bag = write_bag(log, tmp_path / "ident_bag", mapping, storage, geometry=PROTOTYPE)
    # Segments as a user would write them in the mapping: time ranges of the recorded phases.
    dt = log.sample_time
    ranges = [{"name": r.name, "start": r.t_start, "end": r.t_end + dt / 2} for r in log.segment_runs()]
    data = mapping.to_dict()
    data["segments"] = ranges
    back = load_log(bag, mapping_from_dict(data), PROTOTYPE)

    np.testing.assert_array_equal(back.segments, log.segments)
    for col in LOG_COLUMNS:
        np.testing.assert_allclose(back.frame[col], log.frame[col], rtol=1e-12, atol=1e-12, err_msg=col)

    original = identify(log, PROTOTYPE)
    converted = identify(back, PROTOTYPE)
    p0 = original.parameters.to_vector()
    p1 = converted.parameters.to_vector()
    rel = np.abs(p1 / p0 - 1)
    assert rel.max() < 1e-3, dict(zip(PARAMETER_NAMES, rel))
    # The identification itself is meaningful (noise on, parameters near the truth).
    truth = PAPER_PARAMETERS.to_vector()
    free = [i for i, n in enumerate(PARAMETER_NAMES) if n != "B_w"]
    assert np.abs(p0[free] / truth[free] - 1).max() < 0.05
