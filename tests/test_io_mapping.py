"""Mapping files: strict parsing (errors name the key), unit conversions and their inverses."""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.io import MappingError, Signal, mapping_from_dict, read_mapping
from agvdyn.io.mapping import Side, gear_ratio
from agvdyn.platform import PROTOTYPE, Geometry

MAPPINGS = Path(__file__).resolve().parents[1] / "examples" / "mappings"


@pytest.mark.parametrize("name", ["ros2_control", "identity", "csv_datalogger"])
def test_example_mappings_are_valid_and_round_trip(name):
    mapping = read_mapping(MAPPINGS / f"{name}.yaml")
    again = mapping_from_dict(mapping.to_dict())
    assert again.signals == mapping.signals
    assert again.segments == mapping.segments
    assert again.input == mapping.input


def base() -> dict:
    return yaml.safe_load((MAPPINGS / "ros2_control.yaml").read_text())


def table_base() -> dict:
    return yaml.safe_load((MAPPINGS / "csv_datalogger.yaml").read_text())


def edited(data: dict, path: str, value) -> dict:
    data = copy.deepcopy(data)
    keys = path.split(".")
    target = data
    for k in keys[:-1]:
        target = target[k]
    if value is DELETE:
        del target[keys[-1]]
    else:
        target[keys[-1]] = value
    return data


DELETE = object()


@pytest.mark.parametrize(
    ("make", "pattern"),
    [
        (lambda: edited(base(), "rates", 5), r"mine\.yaml: rates: unknown key"),
        (lambda: edited(base(), "signals.alpha_l.units", "deg"), r"signals\.alpha_l\.units: unknown key"),
        (lambda: edited(base(), "signals.alpha_x", "j"), r"signals\.alpha_x: unknown key"),
        (lambda: edited(base(), "signals.m_rr", DELETE), r"signals: missing \['m_rr'\]"),
        (lambda: edited(base(), "input", "rosbag"), r"input: 'rosbag': expected one of \['ros2_bag', 'table'\]"),
        (lambda: edited(base(), "input", DELETE), r"input: missing"),
        (lambda: edited(base(), "signals.alpha_l.unit", "grad"), r"signals\.alpha_l\.unit: 'grad': expected one of \['rad', 'deg', 'rev', 'counts'\]"),
        (lambda: edited(base(), "signals.m_fl.unit", "deg"), r"signals\.m_fl\.unit: 'deg': expected one of \['Nm', 'mNm', 'A'\]"),
        (lambda: edited(base(), "signals.beta_fl.unit", "counts"), r"signals\.beta_fl\.counts_per_rev: required when unit is counts"),
        (lambda: edited(base(), "signals.m_fl.unit", "A"), r"signals\.m_fl\.torque_constant: required when unit is A"),
        (lambda: edited(base(), "signals.alpha_r.sign", 2), r"signals\.alpha_r\.sign: 2: expected 1 or -1"),
        (lambda: edited(base(), "signals.alpha_r.side", "motor"), r"signals\.alpha_r\.side: only wheel angles"),
        (lambda: edited(base(), "signals.beta_rr.side", "gear"), r"signals\.beta_rr\.side: 'gear': expected one of \['wheel', 'motor'\]"),
        (lambda: edited(base(), "signals.beta_rr.scale", "x"), r"signals\.beta_rr\.scale: 'x' is not a finite number"),
        (lambda: edited(base(), "signals.beta_rr.column", "c"), r"signals\.beta_rr\.column: not allowed for input ros2_bag"),
        (lambda: edited(base(), "rate", -5), r"rate: -5: expected a number > 0"),
        (lambda: edited(base(), "i_G", 0), r"mine\.yaml: i_G: 0: expected a number > 0"),
        (lambda: edited(base(), "i_G", "25"), r"i_G: '25' is not a finite number"),
        (lambda: edited(base(), "stamps", "bag"), r"stamps: 'bag': expected one of \['header', 'receive'\]"),
        (lambda: edited(base(), "time", {"column": "t"}), r"time: only used with input table"),
        (lambda: edited(base(), "segments", [{"name": "steer_left", "start": 0, "end": 5}, {"name": "straight", "start": 4, "end": 8}]),
         r"segments: steer_left \[0\.0, 5\.0\) overlaps straight"),
        (lambda: edited(base(), "segments", [{"name": "wiggle", "start": 0, "end": 5}]), r"segments\[0\]\.name: 'wiggle': expected one of"),
        (lambda: edited(base(), "segments", [{"name": "straight", "start": 5, "end": 5}]), r"segments\[0\]: end 5\.0 <= start 5\.0"),
        (lambda: edited(base(), "segments", {"column": "phase"}), r"segments: a segment column exists only for tables"),
        (lambda: edited(table_base(), "topic", "/x"), r"topic: only used with input ros2_bag"),
        (lambda: edited(table_base(), "time.zone", "UTC"), r"time\.zone: unknown key"),
        (lambda: edited(table_base(), "time.unit", "min"), r"time\.unit: 'min': expected one of \['s', 'ms', 'us', 'ns'\]"),
        (lambda: edited(table_base(), "segments.names.5", "sideways"), r"segments\.names\.5: 'sideways': expected one of"),
        (lambda: edited(table_base(), "signals.alpha_l.counts_per_rev", 10), r"signals\.alpha_l\.counts_per_rev: only used with unit counts"),
    ],
)
def test_bad_mapping_errors_name_the_key(tmp_path, make, pattern):
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(make()))
    with pytest.raises(MappingError, match=pattern):
        read_mapping(path)


def test_not_yaml_and_not_a_mapping(tmp_path):
    (tmp_path / "a.yaml").write_text("input: [unclosed")
    with pytest.raises(MappingError, match="not valid YAML"):
        read_mapping(tmp_path / "a.yaml")
    (tmp_path / "b.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(MappingError, match="top level: expected a mapping"):
        read_mapping(tmp_path / "b.yaml")


def test_unit_factors():
    i_G = 25.0
    deg = Signal("alpha_l", "x", "deg")
    assert deg.to_si(np.array([90.0]), i_G)[0] == pytest.approx(math.pi / 2)
    counts = Signal("beta_fl", "x", "counts", side=Side.MOTOR, counts_per_rev=4096)
    assert counts.to_si(np.array([4096.0 * 25]), i_G)[0] == pytest.approx(2 * math.pi)  # 25 motor turns = 1 wheel turn
    wheel_torque = Signal("m_fl", "x", "Nm", side=Side.WHEEL)
    assert wheel_torque.to_si(np.array([50.0]), i_G)[0] == pytest.approx(2.0)
    current = Signal("m_fl", "x", "A", side=Side.MOTOR, torque_constant=0.2, sign=-1.0)
    assert current.to_si(np.array([10.0]), i_G)[0] == pytest.approx(-2.0)
    milli = Signal("m_rr", "x", "mNm", side=Side.MOTOR, offset=0.5)
    assert milli.to_si(np.array([1000.0]), i_G)[0] == pytest.approx(1.5)


@settings(max_examples=60, deadline=None)
@given(
    quantity=st.sampled_from(["alpha_l", "beta_rr", "m_fr"]),
    sign=st.sampled_from([1.0, -1.0]),
    scale=st.floats(0.01, 100.0),
    offset=st.floats(-10.0, 10.0),
    side=st.sampled_from([Side.WHEEL, Side.MOTOR]),
    i_G=st.floats(1.0, 100.0),
    raw=st.lists(st.floats(-1e4, 1e4), min_size=1, max_size=5),
)
def test_from_si_inverts_to_si(quantity, sign, scale, offset, side, i_G, raw):
    unit = {"alpha_l": "deg", "beta_rr": "counts", "m_fr": "A"}[quantity]
    sig = Signal(
        quantity, "x", unit, sign, scale, offset,
        side=None if quantity == "alpha_l" else side,
        counts_per_rev=2048.0 if unit == "counts" else None,
        torque_constant=0.3 if unit == "A" else None,
    )
    raw = np.array(raw)
    np.testing.assert_allclose(sig.from_si(sig.to_si(raw, i_G), i_G), raw, rtol=1e-9, atol=1e-7)


def test_gear_ratio_key_and_which_signals_need_it():
    bag = mapping_from_dict(base())
    assert bag.i_G is None
    assert bag.gear_quantities == ("m_fl", "m_rl", "m_fr", "m_rr")  # wheel-side torques
    table = mapping_from_dict(table_base())
    assert table.gear_quantities == ("beta_fl", "beta_rl", "beta_fr", "beta_rr")  # motor-side encoders
    with_ratio = mapping_from_dict(edited(base(), "i_G", 18.5))
    assert with_ratio.i_G == 18.5 and mapping_from_dict(with_ratio.to_dict()).i_G == 18.5
    assert gear_ratio(with_ratio) == (18.5, "mapping")
    assert gear_ratio(bag, PROTOTYPE) == (25.0, "platform prototype")
    other = Geometry(l=1.2, b=0.8, a=0.05, r=0.1, i_G=18.5, name="mine")
    assert gear_ratio(with_ratio, other) == (18.5, "platform mine")  # both, agreeing
    with pytest.raises(MappingError, match=r"declares i_G: 18\.5 but the platform prototype has i_G = 25"):
        gear_ratio(with_ratio, PROTOTYPE)
    with pytest.raises(MappingError, match=r"m_fl \('front_left_wheel_joint', side: wheel\).*--platform FILE.*'i_G: <ratio>'"):
        gear_ratio(bag)
    no_gear = mapping_from_dict(edited(table_base(), "signals.beta_fl.side", "wheel"))
    for q in ("beta_rl", "beta_fr", "beta_rr"):
        no_gear = mapping_from_dict(edited(no_gear.to_dict(), f"signals.{q}.side", "wheel"))
    assert no_gear.gear_quantities == () and gear_ratio(no_gear) == (None, None)
    with pytest.raises(MappingError, match="needs the gear ratio"):
        Signal("beta_fl", "x", "rad", side=Side.MOTOR).to_si(np.zeros(1), None)
    assert Signal("beta_fl", "x", "rad", side=Side.WHEEL).to_si(np.ones(1), None)[0] == 1.0
