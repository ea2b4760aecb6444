"""ROS 2 bags written with the rosbags writer (sqlite3 and MCAP), read back through a mapping.

The source signals are smooth known functions sampled at irregular stamps, with steering and
wheel joints in separate messages. Linear interpolation onto the uniform time base has the
error bound h^2/8 max|f''| (h: longest stamp interval); the tests check against that bound.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from agvdyn.io._convert import Series, resample, uniform_grid
from agvdyn.io import Log, LogError, MappingError, load_log, mapping_from_dict, read_mapping, write_bag
from agvdyn.io.log import LOG_COLUMNS
from agvdyn.platform import PROTOTYPE

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "mappings" / "ros2_control.yaml"
TS = get_typestore(Stores.ROS2_HUMBLE)
JS = TS.types["sensor_msgs/msg/JointState"]
HEADER = TS.types["std_msgs/msg/Header"]
TIME = TS.types["builtin_interfaces/msg/Time"]
START_NS = 1_731_000_000_123_456_789
I_G = PROTOTYPE.i_G

STEERING = ["front_left_steering_joint", "rear_left_steering_joint", "front_right_steering_joint", "rear_right_steering_joint"]
WHEELS = ["front_left_wheel_joint", "rear_left_wheel_joint", "front_right_wheel_joint", "rear_right_wheel_joint"]
W = 2 * math.pi


# Source signals (functions of seconds since START_NS) and bounds of their second derivatives.
def alpha_l(s): return 0.5 * np.sin(W * 0.3 * s)
def alpha_r(s): return 0.4 * np.sin(W * 0.2 * s + 0.5)
def wheel_angle(s, k): return (4.0 + k) * s + 0.3 * np.sin(W * 0.5 * s + k)          # wheel side, rad
def wheel_torque(s, k): return 20.0 * np.sin(W * 0.4 * s + 0.7 * k) + 5.0             # wheel side, N m


FPP = {"alpha": 0.5 * (W * 0.3) ** 2, "beta": 0.3 * (W * 0.5) ** 2, "m": 20.0 * (W * 0.4) ** 2 / I_G}


def joint_state(stamp_ns: int, names, position, effort):
    return JS(
        header=HEADER(stamp=TIME(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="base_link"),
        name=list(names), position=np.asarray(position, dtype=float), velocity=np.array([], dtype=float),
        effort=np.asarray(effort, dtype=float),
    )


def irregular_stamps(rng, n: int, period_ns: int = 2_000_000, jitter_ns: int = 400_000, offset_ns: int = 0) -> np.ndarray:
    return START_NS + offset_ns + np.arange(n) * period_ns + rng.integers(-jitter_ns, jitter_ns + 1, n)


def write_source_bag(
    path: Path,
    storage: str = "sqlite3",
    *,
    duration: float = 3.0,
    seed: int = 1,
    rear_sign: float = -1.0,
    wheel_names=WHEELS,
    topic_type: str = "sensor_msgs/msg/JointState",
    zero_stamps: bool = False,
    drop_wheel: slice | None = None,
    swap_steering: int | None = None,
    steering_period_ns: int = 2_000_000,
) -> dict:
    """Steering and wheel joints in separate messages at irregular, independent stamps."""
    rng = np.random.default_rng(seed)
    n = int(duration / 0.002)
    st = irregular_stamps(rng, int(duration * 1e9 / steering_period_ns), period_ns=steering_period_ns,
                          jitter_ns=steering_period_ns // 5)
    wt = irregular_stamps(rng, n, offset_ns=700_000)
    if drop_wheel is not None:
        wt = np.delete(wt, np.arange(n)[drop_wheel])
    header = {int(ns): int(ns) for ns in np.concatenate([st, wt])}
    if swap_steering is not None:  # two header stamps out of order; receive order unchanged
        a, b = int(st[swap_steering]), int(st[swap_steering + 1])
        header[a], header[b] = b, a
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    events = []
    for ns in st:
        s = (ns - START_NS) / 1e9
        a_l, a_r = alpha_l(s), alpha_r(s)
        events.append((int(ns), STEERING, [a_l, rear_sign * a_l, a_r, rear_sign * a_r], [np.nan] * 4))
    for ns in wt:
        s = (ns - START_NS) / 1e9
        events.append((int(ns), wheel_names, [wheel_angle(s, k) for k in range(4)], [wheel_torque(s, k) for k in range(4)]))
    events.sort(key=lambda e: e[0])
    latency = 150_000  # receive time = stamp + 0.15 ms
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        conn = writer.add_connection("/joint_states", topic_type, typestore=TS)
        other = writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=TS)
        for i, (ns, names, pos, eff) in enumerate(sorted(events, key=lambda e: e[0])):
            if topic_type == "sensor_msgs/msg/JointState":
                msg = joint_state(0 if zero_stamps else header[ns], names, pos, eff)
                data = TS.serialize_cdr(msg, "sensor_msgs/msg/JointState")
            else:
                data = TS.serialize_cdr(TS.types[topic_type](data="x"), topic_type)
            writer.write(conn, ns + latency * (not zero_stamps), data)
            if i % 50 == 0:
                twist = TS.types["geometry_msgs/msg/Twist"]
                vec = TS.types["geometry_msgs/msg/Vector3"]
                writer.write(other, ns + 1, TS.serialize_cdr(twist(linear=vec(x=1.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)), "geometry_msgs/msg/Twist"))
    h_max = max(np.diff(np.sort(st)).max(), np.diff(np.sort(wt)).max()) / 1e9
    return {"h_max": h_max}


def load(path, mapping=EXAMPLE, platform=PROTOTYPE, **kw) -> Log:
    """load_log with the prototype's gear ratio (the example mapping's torques are wheel side)."""
    return load_log(path, mapping, platform, **kw)


def expected(log: Log) -> dict[str, np.ndarray]:
    s = (log.sidecar["conversion"]["t0_ns"] - START_NS) / 1e9 + log.t
    out = {"alpha_l": alpha_l(s), "alpha_r": alpha_r(s)}
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        out[f"beta_{w}"] = wheel_angle(s, k)
        out[f"m_{w}"] = wheel_torque(s, k) / I_G
    return out


def assert_matches_source(log: Log, h_max: float) -> None:
    exp = expected(log)
    for col, want in exp.items():
        bound = h_max**2 / 8 * FPP[col.split("_")[0]] * 1.001 + 1e-9
        err = np.abs(log.frame[col].to_numpy() - want).max()
        assert err <= bound, f"{col}: error {err:.3g} > bound {bound:.3g}"


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_bag_with_split_irregular_messages_matches_the_source(tmp_path, storage):
    info = write_source_bag(tmp_path / "run", storage)
    log = load(tmp_path / "run", EXAMPLE)
    conv = log.sidecar["conversion"]
    assert conv["rate"] == pytest.approx(500.0, rel=1e-9)
    assert set(conv["joint_rates"]) == set(STEERING + WHEELS)
    assert all(r == pytest.approx(500.0, rel=1e-3) for r in conv["joint_rates"].values())
    assert conv["time"] == "header stamp"
    assert conv["notes"] == []
    assert "linear interpolation" in conv["method"]
    np.testing.assert_allclose(np.diff(log.t), 0.002, rtol=1e-9)
    assert log.t[0] == 0.0
    assert 2.99 < log.duration < 3.0
    assert conv["coupling_max_deviation"]["heading_rl"] < 1e-5
    assert_matches_source(log, info["h_max"])


def test_bag_single_storage_files_are_accepted(tmp_path):
    write_source_bag(tmp_path / "a", "sqlite3", duration=0.5)
    write_source_bag(tmp_path / "b", "mcap", duration=0.5)
    la = load(tmp_path / "a" / "a.db3", EXAMPLE)
    lb = load(tmp_path / "b" / "b.mcap", EXAMPLE)
    np.testing.assert_allclose(la.alpha, lb.alpha)


def test_explicit_rate_is_used(tmp_path):
    info = write_source_bag(tmp_path / "run", "sqlite3", duration=1.0)
    data = read_mapping(EXAMPLE).to_dict()
    data["rate"] = 250.0
    log = load(tmp_path / "run", mapping_from_dict(data))
    assert log.sample_time == pytest.approx(0.004)
    assert_matches_source(log, info["h_max"])


def test_zero_header_stamps_fall_back_to_receive_time(tmp_path):
    info = write_source_bag(tmp_path / "run", "mcap", duration=1.0, zero_stamps=True)
    log = load(tmp_path / "run", EXAMPLE)
    conv = log.sidecar["conversion"]
    assert conv["time"] == "bag receive time"
    assert "zero" in conv["notes"][0]
    assert_matches_source(log, info["h_max"])


def test_missing_joint_is_named(tmp_path):
    names = ["front_left_wheel_joint", "rear_left_wheel_joint", "front_right_wheel", "rear_right_wheel_joint"]
    write_source_bag(tmp_path / "run", duration=0.2, wheel_names=names)
    with pytest.raises(LogError, match=r"joint 'front_right_wheel_joint' \(beta_fr\) not found on /joint_states; joints found: .*'front_right_wheel'"):
        load(tmp_path / "run", EXAMPLE)


def test_wrong_topic_type(tmp_path):
    write_source_bag(tmp_path / "run", duration=0.1, topic_type="std_msgs/msg/String")
    with pytest.raises(LogError, match=r"topic '/joint_states' has message type std_msgs/msg/String: expected sensor_msgs/msg/JointState"):
        load(tmp_path / "run", EXAMPLE)


def test_missing_topic(tmp_path):
    write_source_bag(tmp_path / "run", duration=0.1)
    data = read_mapping(EXAMPLE).to_dict()
    data["topic"] = "/robot/joint_states"
    with pytest.raises(LogError, match=r"no topic '/robot/joint_states' in the bag; topics found: .*'/joint_states'"):
        load(tmp_path / "run", mapping_from_dict(data))


def test_non_monotonic_stamp(tmp_path):
    write_source_bag(tmp_path / "run", duration=0.5, swap_steering=100)
    with pytest.raises(LogError, match=r"joint 'front_left_steering_joint': header stamp of message #\d+ goes back"):
        load(tmp_path / "run", EXAMPLE)


def test_gap_too_large_to_resample_becomes_a_time_gap(tmp_path):
    """A dropout is not interpolated over: its points of the time base are left out, and noted."""
    info = write_source_bag(tmp_path / "run", duration=1.0, drop_wheel=slice(200, 220))
    log = load(tmp_path / "run", EXAMPLE)
    conv = log.sidecar["conversion"]
    (note,) = conv["notes"]
    assert "joint 'front_left_wheel_joint' position (beta_fl)" in note and "joint 'rear_right_wheel_joint' effort (m_rr)" in note
    assert re.search(r"no sample between t = 0\.39\d+ s and t = 0\.4[34]\d+ s \(log time; 0 = header stamp \d+ ns\)", note)
    assert "points of the time base left out" in note
    assert np.diff(log.t).min() == pytest.approx(0.002)
    (a, b), = log.gaps()
    assert 0.38 < a < 0.40 and 0.42 < b < 0.45
    first, second = log.stretches()
    assert first.stop == second.start and log.t[first.stop - 1] == a and log.t[second.start] == b
    # Nothing is interpolated across the dropout: the error bound holds with the interval of the
    # regular stamps (2 ms +- 2 x 0.4 ms jitter), not with the 40 ms of the dropout.
    assert info["h_max"] > 0.03
    assert_matches_source(log, 0.0028)
    with pytest.raises(LogError, match=r"gap of 0\.0\d+ s"):
        load(tmp_path / "run", EXAMPLE, max_gap_samples=5)  # a caller can still refuse gaps


def test_broken_mirror_coupling(tmp_path):
    write_source_bag(tmp_path / "run", duration=0.5, rear_sign=+1.0)
    with pytest.raises(LogError, match=r"rear_left_steering_joint \(heading_rl\).*mirror coupling.*wrong mapping .* or a broken steering coupling"):
        load(tmp_path / "run", EXAMPLE)


def test_bag_without_mapping_is_refused(tmp_path):
    write_source_bag(tmp_path / "run", duration=0.1)
    with pytest.raises(LogError, match="needs a mapping"):
        load_log(tmp_path / "run")


def test_segments_from_time_ranges(tmp_path):
    write_source_bag(tmp_path / "run", duration=1.0)
    data = read_mapping(EXAMPLE).to_dict()
    data["segments"] = [{"name": "steer_left", "start": 0.0, "end": 0.4}, {"name": "straight", "start": 0.5, "end": 2.0}]
    log = load(tmp_path / "run", mapping_from_dict(data))
    runs = log.segment_runs()
    assert [r.name for r in runs] == ["steer_left", "straight"]
    assert runs[0].t_start == 0.0 and runs[0].t_end < 0.4 <= log.t[runs[0].stop]
    assert log.t[runs[1].start] >= 0.5 > log.t[runs[1].start - 1]


def smooth_log(n: int = 600, dt: float = 0.002) -> Log:
    import pandas as pd

    t = np.arange(n) * dt
    data = {"t": t, "alpha_l": alpha_l(t), "alpha_r": alpha_r(t)}
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        data[f"beta_{w}"] = wheel_angle(t, k)
        data[f"m_{w}"] = wheel_torque(t, k) / I_G
    frame = pd.DataFrame(data)
    frame["segment"] = ["steer_left"] * (n // 2) + ["rotation"] * (n - n // 2)
    return Log.from_frame(frame)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_write_bag_round_trip(tmp_path, storage):
    log = smooth_log()
    mapping = read_mapping(EXAMPLE)
    path = write_bag(log, tmp_path / "out", mapping, storage, platform=PROTOTYPE)
    back = load(path, mapping)
    assert back.sidecar["conversion"]["rate"] == pytest.approx(500.0)
    np.testing.assert_allclose(back.t, log.t, atol=1e-12)
    for col in LOG_COLUMNS[1:]:
        np.testing.assert_allclose(back.frame[col], log.frame[col], rtol=1e-12, atol=1e-12, err_msg=col)
    with pytest.raises(LogError, match="exists already"):
        write_bag(log, path, mapping, storage, platform=PROTOTYPE)


def test_unreadable_bag(tmp_path):
    bag = tmp_path / "broken"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 99}\n")
    with pytest.raises(LogError, match=r"broken: cannot be read as a ROS 2 bag"):
        load(bag, EXAMPLE)
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file")
    with pytest.raises(LogError, match=r"junk\.mcap: cannot be read as a ROS 2 bag"):
        load(tmp_path / "junk.mcap", EXAMPLE)


def test_receive_times_on_request(tmp_path):
    info = write_source_bag(tmp_path / "run", "sqlite3", duration=0.5)
    data = read_mapping(EXAMPLE).to_dict()
    data["stamps"] = "receive"
    by_receive = load(tmp_path / "run", mapping_from_dict(data))
    by_header = load(tmp_path / "run", EXAMPLE)
    assert by_receive.sidecar["conversion"]["time"] == "bag receive time"
    assert by_receive.sidecar["conversion"]["t0_ns"] - by_header.sidecar["conversion"]["t0_ns"] == 150_000  # the latency
    assert_matches_source(by_header, info["h_max"])


def test_mixed_zero_and_real_header_stamps(tmp_path):
    path = tmp_path / "run"
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=TS)
        for k in range(20):
            ns = START_NS + k * 2_000_000
            msg = joint_state(0 if k == 7 else ns, STEERING + WHEELS, np.zeros(8), np.zeros(8))
            writer.write(conn, ns, TS.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
    with pytest.raises(LogError, match=r"message #7 on /joint_states .* has a zero header stamp while others have stamps"):
        load(path, EXAMPLE)


def test_joint_without_the_needed_field(tmp_path):
    write_source_bag(tmp_path / "run", duration=0.2)
    data = read_mapping(EXAMPLE).to_dict()
    data["signals"]["m_fl"] = {"joint": "front_left_steering_joint"}  # steering joints publish no effort (NaN)
    with pytest.raises(LogError, match=r"joint 'front_left_steering_joint' \(m_fl\) never has an effort value"):
        load(tmp_path / "run", mapping_from_dict(data))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    slope=st.floats(-50, 50),
    intercept=st.floats(-10, 10),
    jitter=st.floats(0.0, 0.45),
)
def test_resampling_reproduces_linear_signals_exactly(seed, slope, intercept, jitter):
    """Linear interpolation is exact on straight lines, whatever the stamps: a property of the method."""
    rng = np.random.default_rng(seed)
    period = 0.002
    times = np.arange(300) * period + rng.uniform(-jitter, jitter, 300) * period
    series = {"x": Series("x", times, intercept + slope * times), "y": Series("y", times[::2] + 1e-4, -slope * times[::2])}
    grid = uniform_grid(series, period)
    out = resample(series, grid)
    np.testing.assert_allclose(out["x"], intercept + slope * grid, rtol=0, atol=1e-9 * (1 + abs(slope)))
    assert grid[0] >= max(times[0], times[0] + 1e-4) - 1e-15 and grid[-1] <= times[-1] + 1e-15


def test_write_bag_takes_the_gear_ratio_from_the_sidecar(tmp_path):
    other = PROTOTYPE.__class__(l=1.2, b=0.8, a=0.05, r=0.1, i_G=10.0, name="other")
    log = smooth_log()
    log = Log(None, log.frame, {"platform": other.to_dict()})
    bag = write_bag(log, tmp_path / "bag", EXAMPLE)  # mapping as a file, platform from the sidecar
    with_other = load(bag, EXAMPLE, other)
    with_proto = load(bag, EXAMPLE)
    np.testing.assert_allclose(with_other.torque, log.torque, atol=1e-12)
    np.testing.assert_allclose(with_proto.torque, log.torque * 10.0 / 25.0, atol=1e-12)
    np.testing.assert_allclose(with_proto.beta, log.beta, atol=1e-12)  # wheel side in this mapping: no i_G


def test_upsampling_a_slow_bag_keeps_the_source_interval_as_gap_limit(tmp_path):
    """A 100 Hz bag resampled at 500 Hz: gaps are judged against the 10 ms source interval."""
    path = tmp_path / "slow"
    rng = np.random.default_rng(2)
    stamps = START_NS + np.arange(200) * 10_000_000 + rng.integers(-1_000_000, 1_000_000, 200)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=TS)
        for ns in stamps:
            s = (ns - START_NS) / 1e9
            pos = [alpha_l(s), -alpha_l(s), alpha_r(s), -alpha_r(s), *(wheel_angle(s, k) for k in range(4))]
            eff = [np.nan] * 4 + [wheel_torque(s, k) for k in range(4)]
            writer.write(conn, int(ns), TS.serialize_cdr(joint_state(int(ns), STEERING + WHEELS, pos, eff), "sensor_msgs/msg/JointState"))
    data = read_mapping(EXAMPLE).to_dict()
    data["rate"] = 500.0
    log = load(path, mapping_from_dict(data))
    assert log.sample_time == pytest.approx(0.002)
    assert log.sidecar["conversion"]["max_gap"] == pytest.approx(0.05, rel=1e-3)
    assert_matches_source(log, np.diff(stamps).max() / 1e9)


# --- real logs: split publishers, joints at other rates, gear ratio, steering stops ----------

@pytest.mark.parametrize("offset_ns", [0, 700_000])
def test_joints_split_over_two_publishers_give_their_own_rate(tmp_path, offset_ns):
    """Two JointState publishers at 500 Hz each, interleaved on one topic: the time base is 500 Hz."""
    log = smooth_log(n=1000)
    mapping = read_mapping(EXAMPLE)
    bag = write_bag(log, tmp_path / "split", mapping, "mcap", platform=PROTOTYPE,
                    groups=[STEERING, WHEELS], group_offsets_ns=[0, offset_ns])
    back = load(bag, mapping)
    conv = back.sidecar["conversion"]
    assert conv["messages"] == 2000  # two messages per sample
    assert conv["rate"] == pytest.approx(500.0, rel=1e-9)
    assert back.sample_time == pytest.approx(0.002, rel=1e-9)
    assert all(r == pytest.approx(500.0, rel=1e-9) for r in conv["joint_rates"].values())
    np.testing.assert_allclose(np.diff(back.t), 0.002, rtol=1e-9)
    if offset_ns == 0:  # same stamps: the log comes back exactly
        np.testing.assert_allclose(back.t, log.t, atol=1e-12)
        for col in LOG_COLUMNS[1:]:
            np.testing.assert_allclose(back.frame[col], log.frame[col], rtol=1e-12, atol=1e-12, err_msg=col)


def test_joints_at_different_rates_need_a_rate_in_the_mapping(tmp_path):
    info = write_source_bag(tmp_path / "run", duration=1.0, steering_period_ns=10_000_000)  # steering at 100 Hz
    with pytest.raises(LogError) as err:
        load(tmp_path / "run", EXAMPLE)
    text = str(err.value)
    assert "publish at different rates" in text and "'front_left_wheel_joint' 500 Hz" in text
    assert re.search(r"'front_left_steering_joint' (99\.9\d|100(\.0\d)?) Hz", text)
    assert "rate: 500" in text and "np.float64" not in text
    data = read_mapping(EXAMPLE).to_dict()
    data["rate"] = 500.0
    log = load(tmp_path / "run", mapping_from_dict(data))
    assert log.sidecar["conversion"]["rate"] == 500.0
    assert log.sidecar["conversion"]["max_gap"] == pytest.approx(0.05, rel=1e-2)  # 5 intervals of the slowest joint
    assert log.gaps() == ()
    assert info["h_max"] < 0.015


def test_bag_needs_a_gear_ratio_for_wheel_side_torques(tmp_path):
    write_source_bag(tmp_path / "run", duration=0.3)
    with pytest.raises(MappingError) as err:
        load_log(tmp_path / "run", EXAMPLE)  # no platform; the example mapping gives no i_G
    text = str(err.value)
    assert "m_fl ('front_left_wheel_joint', side: wheel)" in text and "m_rr" in text and "beta_fl" not in text
    assert "--platform FILE" in text and "i_G:" in text
    data = read_mapping(EXAMPLE).to_dict()
    data["i_G"] = PROTOTYPE.i_G
    by_mapping = load_log(tmp_path / "run", mapping_from_dict(data))
    by_platform = load(tmp_path / "run", EXAMPLE)
    np.testing.assert_array_equal(by_mapping.torque, by_platform.torque)
    assert by_mapping.sidecar["conversion"]["i_G"] == 25.0 and by_mapping.sidecar["conversion"]["i_G_source"] == "mapping"
    assert by_platform.sidecar["conversion"]["i_G_source"] == "platform prototype"
    assert load(tmp_path / "run", mapping_from_dict(data)).torque.shape[1] == 4  # both, agreeing
    other = PROTOTYPE.__class__(l=1.2, b=0.8, a=0.05, r=0.1, i_G=10.0, name="other")
    with pytest.raises(MappingError, match=r"i_G: the mapping declares i_G: 25 but the platform other has i_G = 10"):
        load_log(tmp_path / "run", mapping_from_dict(data), other)
    # A mapping whose signals need no gear ratio works without a platform.
    data = read_mapping(EXAMPLE).to_dict()
    for w in ("fl", "rl", "fr", "rr"):
        data["signals"][f"m_{w}"]["side"] = "motor"
    log = load_log(tmp_path / "run", mapping_from_dict(data))
    assert log.sidecar["conversion"]["i_G"] is None


def test_write_bag_refuses_without_a_gear_ratio(tmp_path):
    with pytest.raises(MappingError, match="need the gear ratio i_G"):
        write_bag(smooth_log(), tmp_path / "bag", EXAMPLE)  # no platform, none in the sidecar or mapping
    assert not (tmp_path / "bag").exists()


def test_bag_steering_within_the_stop_tolerance_is_clipped(tmp_path):
    frame = smooth_log().frame.copy()
    frame.loc[100:104, "alpha_l"] = math.pi / 2 + 0.005
    assert Log.from_frame(frame).clipped == {"alpha_l": 5, "alpha_r": 0}
    raw = Log(None, frame)  # unchecked: the measured (unclipped) angles go into the bag
    assert raw.clipped == {"alpha_l": 0, "alpha_r": 0}
    bag = write_bag(raw, tmp_path / "bag", EXAMPLE, platform=PROTOTYPE)
    back = load(bag)
    assert back.clipped == {"alpha_l": 5, "alpha_r": 0}
    assert back.sidecar["conversion"]["clipped_to_stops"] == {"alpha_l": 5, "alpha_r": 0}
    assert back.alpha[:, 0].max() == math.pi / 2
    with pytest.raises(LogError, match=r"converted with .*column 'alpha_l', row 100 \(t = 0\.2 s\): steering angle 1\.5758 rad"):
        load(bag, stop_tolerance=0.001)
