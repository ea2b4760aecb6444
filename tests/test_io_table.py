"""Tables with their own column names and units (degrees, encoder counts, currents), via a mapping."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from agvdyn.io import LogError, MappingError, load_log, mapping_from_dict, read_log, read_mapping, write_log
from agvdyn.io.log import LOG_COLUMNS
from agvdyn.platform import Geometry, PROTOTYPE

MAPPINGS = Path(__file__).resolve().parents[1] / "examples" / "mappings"
DATALOGGER = MAPPINGS / "csv_datalogger.yaml"
CPR, KT = 4096, 0.12
W = 2 * math.pi


def truth(s: np.ndarray) -> dict[str, np.ndarray]:
    """SI signals of our schema as smooth functions of time s."""
    out = {"alpha_l": 0.6 * np.sin(W * 0.25 * s), "alpha_r": -0.5 * np.sin(W * 0.15 * s + 0.3)}
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        out[f"beta_{w}"] = (2.0 + 0.5 * k) * s + 0.2 * np.sin(W * 0.4 * s + k)
        out[f"m_{w}"] = 0.8 * np.sin(W * 0.3 * s + 0.5 * k) + 0.1
    return out


def datalogger_csv(path: Path, t: np.ndarray, i_G: float = PROTOTYPE.i_G) -> dict[str, np.ndarray]:
    """Write the CSV that examples/mappings/csv_datalogger.yaml describes; return the SI truth."""
    tr = truth(t)
    frame = pd.DataFrame({"time_ms": t * 1e3, "steer_L_deg": np.degrees(tr["alpha_l"]), "steer_R_deg": np.degrees(tr["alpha_r"])})
    sign = {"fl": 1, "rl": 1, "fr": -1, "rr": -1}
    for w in ("fl", "rl", "fr", "rr"):
        motor_rev = tr[f"beta_{w}"] * i_G / W
        frame[f"enc_{w.upper()}"] = np.round(sign[w] * motor_rev * CPR).astype(np.int64)  # integer counts
        frame[f"cur_{w.upper()}"] = sign[w] * tr[f"m_{w}"] / KT
    phase = np.where(t < t[len(t) // 3], 1, np.where(t < t[2 * len(t) // 3], 0, 4))
    frame["phase"] = phase
    frame.to_csv(path, index=False)
    return tr


def load(path, mapping=DATALOGGER, platform=PROTOTYPE, **kw):
    """load_log with the prototype's gear ratio (the data logger's encoders are on the motor side)."""
    return load_log(path, mapping, platform, **kw)


def test_datalogger_csv_in_degrees_counts_and_currents(tmp_path):
    t = np.arange(1500) * 0.002
    tr = datalogger_csv(tmp_path / "plc.csv", t)
    log = load(tmp_path / "plc.csv", DATALOGGER)
    np.testing.assert_array_equal(log.t, t * 1e3 * 1e-3)
    for col in ("alpha_l", "alpha_r"):
        np.testing.assert_allclose(log.frame[col], tr[col], atol=1e-12)
    # Encoder quantisation: at most half a count on the motor side.
    half_count = 0.5 * W / CPR / PROTOTYPE.i_G
    for w in ("fl", "rl", "fr", "rr"):
        err = np.abs(log.frame[f"beta_{w}"] - tr[f"beta_{w}"]).max()
        assert err <= half_count * (1 + 1e-9)
        assert err > half_count / 10  # the quantisation is really there, not silently bypassed
        np.testing.assert_allclose(log.frame[f"m_{w}"], tr[f"m_{w}"], atol=1e-12)
    runs = [(r.name, r.start, r.stop) for r in log.segment_runs()]
    assert runs == [("steer_left", 0, 500), ("align", 500, 1000), ("rotation", 1000, 1500)]
    assert log.sidecar["conversion"]["resampled"] is False


def test_gear_ratio_comes_from_the_platform(tmp_path):
    t = np.arange(200) * 0.002
    other = Geometry(l=1.2, b=0.8, a=0.05, r=0.1, i_G=10.0)
    tr = datalogger_csv(tmp_path / "plc.csv", t, i_G=10.0)
    log = load_log(tmp_path / "plc.csv", DATALOGGER, platform=other)
    np.testing.assert_allclose(log.frame["beta_fl"], tr["beta_fl"], atol=0.5 * W / CPR / 10.0 * (1 + 1e-9))
    assert log.sidecar["conversion"]["i_G"] == 10.0
    # No gear ratio assumed: refused, naming the signals that need it and both ways to give it.
    with pytest.raises(MappingError) as err:
        load_log(tmp_path / "plc.csv", DATALOGGER)
    text = str(err.value)
    assert "csv_datalogger.yaml" in text and "beta_fl ('enc_FL', side: motor)" in text and "beta_rr" in text
    assert "m_fl" not in text  # motor-side currents need no gear ratio
    assert "--platform FILE" in text and "'i_G: <ratio>'" in text
    data = read_mapping(DATALOGGER).to_dict()
    data["i_G"] = 10.0
    by_mapping = load_log(tmp_path / "plc.csv", mapping_from_dict(data))
    np.testing.assert_array_equal(by_mapping.beta, log.beta)
    assert by_mapping.sidecar["conversion"]["i_G_source"] == "mapping"
    with pytest.raises(MappingError, match=r"declares i_G: 10 but the platform prototype has i_G = 25"):
        load_log(tmp_path / "plc.csv", mapping_from_dict(data), PROTOTYPE)


def test_irregular_csv_resampled_onto_a_uniform_time_base(tmp_path):
    rng = np.random.default_rng(3)
    t = 10.0 + np.arange(2000) * 0.002 + rng.uniform(-4e-4, 4e-4, 2000)
    tr = datalogger_csv(tmp_path / "plc.csv", t)
    data = read_mapping(DATALOGGER).to_dict()
    data["rate"] = 500.0
    log = load(tmp_path / "plc.csv", mapping_from_dict(data))
    np.testing.assert_allclose(np.diff(log.t), 0.002, rtol=1e-9)
    assert log.t[0] == pytest.approx(t[0], abs=1e-12)
    ref = truth(log.t)
    h = np.diff(t).max()
    bound_alpha = h**2 / 8 * 0.6 * (W * 0.25) ** 2
    assert np.abs(log.frame["alpha_l"] - ref["alpha_l"]).max() <= bound_alpha * 1.001
    bound_m = h**2 / 8 * 0.8 * (W * 0.3) ** 2
    assert np.abs(log.frame["m_rr"] - ref["m_rr"]).max() <= bound_m * 1.001
    assert log.sidecar["conversion"]["resampled"] is True
    # Segment of each new sample: that of the latest source row at or before it.
    assert log.segments[0] == "steer_left" and log.segments[-1] == "rotation"


def test_identity_mapping_equals_reading_our_schema(tmp_path):
    t = np.arange(300) * 0.002
    frame = pd.DataFrame({"t": t, **truth(t)})
    frame["segment"] = ["straight"] * 150 + ["rotation"] * 150
    path = write_log(tmp_path / "ours.csv", frame)
    direct = read_log(path)
    mapped = load_log(path, MAPPINGS / "identity.yaml")
    for col in LOG_COLUMNS:
        np.testing.assert_array_equal(mapped.frame[col], direct.frame[col])
    np.testing.assert_array_equal(mapped.segments, direct.segments)


def test_parquet_table_with_other_names(tmp_path):
    t = np.arange(100) * 0.01
    tr = truth(t)
    frame = pd.DataFrame({"time": t, **{f"x_{k}": v for k, v in tr.items()}})
    frame.to_parquet(tmp_path / "x.parquet")
    mapping = mapping_from_dict({"input": "table", "time": {"column": "time"}, "signals": {k: f"x_{k}" for k in tr}})
    log = load_log(tmp_path / "x.parquet", mapping)
    for col, v in tr.items():
        np.testing.assert_array_equal(log.frame[col], v)


def test_missing_column_names_the_mapping_key(tmp_path):
    t = np.arange(50) * 0.002
    datalogger_csv(tmp_path / "plc.csv", t)
    frame = pd.read_csv(tmp_path / "plc.csv").rename(columns={"enc_RL": "encRL"})
    frame.to_csv(tmp_path / "plc.csv", index=False)
    with pytest.raises(LogError, match=r"plc\.csv: missing columns 'enc_RL' \(mapping key signals\.beta_rl\); columns found: .*'encRL'"):
        load(tmp_path / "plc.csv", DATALOGGER)


def test_non_numeric_source_value_names_column_and_line(tmp_path):
    t = np.arange(50) * 0.002
    datalogger_csv(tmp_path / "plc.csv", t)
    frame = pd.read_csv(tmp_path / "plc.csv").astype({"cur_FR": object})
    frame.loc[7, "cur_FR"] = "ERR"
    frame.to_csv(tmp_path / "plc.csv", index=False)
    with pytest.raises(LogError, match=r"column 'cur_FR', row 7 \(line 9 of the file\): value 'ERR' is not a number"):
        load(tmp_path / "plc.csv", DATALOGGER)


def test_decreasing_source_time(tmp_path):
    t = np.arange(50) * 0.002
    t[20] = t[18]
    datalogger_csv(tmp_path / "plc.csv", t)
    with pytest.raises(LogError, match=r"column 'time_ms', row 20 \(line 22 of the file\): decreasing time"):
        load(tmp_path / "plc.csv", DATALOGGER)


def test_unknown_translated_segment(tmp_path):
    t = np.arange(60) * 0.002
    datalogger_csv(tmp_path / "plc.csv", t)
    frame = pd.read_csv(tmp_path / "plc.csv")
    frame.loc[30, "phase"] = 9
    frame.to_csv(tmp_path / "plc.csv", index=False)
    with pytest.raises(LogError, match=r"column 'segment', row 30 .*unknown segment name '9'"):
        load(tmp_path / "plc.csv", DATALOGGER)


def test_degrees_without_mapping_are_refused(tmp_path):
    t = np.arange(50) * 0.002
    tr = truth(t)
    tr["alpha_l"] = np.degrees(tr["alpha_l"]) + 10
    pd.DataFrame({"t": t, **tr}).to_csv(tmp_path / "deg.csv", index=False)
    with pytest.raises(LogError, match="beyond the mechanical stop .*expected radians"):
        load_log(tmp_path / "deg.csv")


def test_bag_mapping_on_a_table_is_refused(tmp_path):
    t = np.arange(50) * 0.002
    datalogger_csv(tmp_path / "plc.csv", t)
    with pytest.raises(LogError, match="mapping with input: table"):
        load_log(tmp_path / "plc.csv", MAPPINGS / "ros2_control.yaml")


# --- real logs: time units, dropouts, steering stops ------------------------------------------

@pytest.mark.parametrize(("declared", "suggested", "words"), [
    ("s", "ms", "too long (time in milliseconds?)"),  # a column in ms declared as s: steps of 2 "s"
    ("ms", "s", "too short"),  # a column in s declared as ms: steps of 2 us
])
def test_declared_time_unit_that_makes_the_step_implausible(tmp_path, declared, suggested, words):
    t = np.arange(300) * 0.002
    datalogger_csv(tmp_path / "plc.csv", t)
    frame = pd.read_csv(tmp_path / "plc.csv")
    frame["time_ms"] = t * 1e3 if suggested == "ms" else t  # the column's real unit
    frame.to_csv(tmp_path / "plc.csv", index=False)
    data = read_mapping(DATALOGGER).to_dict()
    data["time"]["unit"] = declared
    with pytest.raises(LogError) as err:
        load(tmp_path / "plc.csv", mapping_from_dict(data))
    text = str(err.value)
    assert f"column 'time_ms' with time.unit: {declared}" in text and words in text
    assert f"time: {{column: time_ms, unit: {suggested}}}" in text
    assert "np.float64" not in text


def test_table_with_a_dropout_is_read_with_a_time_gap(tmp_path):
    t = np.arange(1500) * 0.002
    t[800:] += 0.1  # 0.1 s missing at 500 Hz
    datalogger_csv(tmp_path / "plc.csv", t)
    log = load(tmp_path / "plc.csv")
    assert log.stretches() == (slice(0, 800), slice(800, 1500))
    assert log.sidecar["conversion"]["notes"] == []


def test_resampled_table_leaves_out_the_points_inside_a_gap(tmp_path):
    rng = np.random.default_rng(5)
    t = np.arange(1500) * 0.002 + rng.uniform(-3e-4, 3e-4, 1500)
    t = np.delete(t, np.arange(700, 750))  # 0.1 s missing
    datalogger_csv(tmp_path / "plc.csv", t)
    data = read_mapping(DATALOGGER).to_dict()
    data["rate"] = 500.0
    log = load(tmp_path / "plc.csv", mapping_from_dict(data))
    (a, b), = log.gaps()
    assert a < t[699] + 0.002 and b > t[700] - 0.002 and b - a > 0.09
    assert a >= t[699] - 0.002 and b <= t[700] + 0.002
    first, second = log.stretches()
    np.testing.assert_allclose(np.diff(log.t[first]), 0.002, rtol=1e-9)
    np.testing.assert_allclose(np.diff(log.t[second]), 0.002, rtol=1e-9)
    (note,) = log.sidecar["conversion"]["notes"]
    assert note.startswith("all 10 signals: no sample between t = ") and "not interpolated over" in note and "left out" in note
    ref = truth(log.t)
    h = 0.0026  # longest interval of the jittered rows outside the dropout: nothing bridged the 0.1 s
    assert np.abs(log.frame["alpha_l"] - ref["alpha_l"]).max() <= h**2 / 8 * 0.6 * (W * 0.25) ** 2 * 1.001


def test_table_steering_within_the_stop_tolerance_is_clipped(tmp_path):
    t = np.arange(300) * 0.002
    datalogger_csv(tmp_path / "plc.csv", t)
    frame = pd.read_csv(tmp_path / "plc.csv")
    frame.loc[[5, 6], "steer_R_deg"] = -90.3  # 5 mrad beyond the stop
    frame.to_csv(tmp_path / "plc.csv", index=False)
    before = (tmp_path / "plc.csv").read_bytes()
    log = load(tmp_path / "plc.csv")
    assert log.clipped == {"alpha_l": 0, "alpha_r": 2} and log.alpha[5, 1] == -math.pi / 2
    assert log.sidecar["conversion"]["clipped_to_stops"] == {"alpha_l": 0, "alpha_r": 2}
    assert (tmp_path / "plc.csv").read_bytes() == before
    frame.loc[5, "steer_R_deg"] = -92.0
    frame.to_csv(tmp_path / "plc.csv", index=False)
    with pytest.raises(LogError, match=r"column 'alpha_r', row 5 \(t = 0\.01 s\): steering angle -1\.6057 rad is beyond the mechanical stop -1\.5708 rad"):
        load(tmp_path / "plc.csv")
    assert load(tmp_path / "plc.csv", stop_tolerance=0.05).clipped["alpha_r"] == 2
