"""The model beyond the paper in the identification's row pass and regression (issue 30; the laws of
agvdyn.model_spec): the paper's path unchanged, the extension columns against a direct evaluation on the
same filtered signals, exact recovery of breakaway levels, centre offset and torque delay from model
logs whose torques follow the extended model, refusals by name, and the result's JSON and file."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings as hsettings, strategies as hst

from agvdyn.identification import (
    Filtering,
    IdentificationSettings,
    ImplausibleError,
    UnidentifiableError,
    equation_block,
    fit_blocks,
    identify,
    identify_model,
    log_rows,
    row_passes,
)
from agvdyn.identification.model_fit import MIN_SUPPORT_ROWS, extension_estimates
from agvdyn.identification.model_rows import delayed_torque
from agvdyn.identification.model_search import refused_levels
from agvdyn.identification.regression import Dependency, stacked_system
from agvdyn.identification.stretches import filtered_stretch, stretch_bounds
from agvdyn.io import Log
from agvdyn.kinematics import Mode, kinematic_model
from agvdyn.model_file import read_model_parameters
from agvdyn.model_spec import (PAPER_MODEL, ModelParameters, ModelSpec, breakaway_weight, joint_friction,
                               model_from_mapping)
from agvdyn.platform import EPSILON, PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, PlatformFileError
from agvdyn.signals import lowpass
from model_logs import identification_frame, lane_change_frame

P = PAPER_PARAMETERS
DT = 2e-3
SHORT = {"steer_left": 10.0, "steer_right": 10.0, "straight": 10.0, "rotation": 10.0}
FREE = [i for i, n in enumerate(PARAMETER_NAMES) if n != "B_w"]
STRIBECK = ModelSpec(friction="stribeck", stribeck_velocities=(0.05, 0.06, 0.08))
CENTRE = ModelSpec(com_offset=True)
BOTH = ModelSpec(friction="stribeck", com_offset=True, stribeck_velocities=(0.05, 0.06, 0.08))
TRUTH = ModelParameters(P, {"d_sl": 1.3 * P.d_cl, "d_sr": 1.25 * P.d_cr, "d_sw": 1.4 * P.d_cw, "w_sl": 0.05,
                            "w_sr": 0.06, "w_sw": 0.08, "x_c": 0.12, "y_c": -0.08}, spec=BOTH)
#: unexcited parameters reported (held, unbounded interval) instead of refused
REPORT = IdentificationSettings.from_flat(unexcited="report")
#: stiction thresholds below the Stribeck velocities: rows in the Stribeck range are kept
SLOW_ROWS = IdentificationSettings.from_flat(stiction_threshold=0.005, steering_threshold=0.005)
WHEELS = ("fl", "rl", "fr", "rr")


def extension_forces(q_dot: np.ndarray, q_ddot: np.ndarray, model: ModelParameters) -> np.ndarray:
    """Generalized forces (n, 9) the extensions add to Theta p, from agvdyn.model_spec's laws: the
    Stribeck friction minus the paper's per joint, and the chassis rows of the off-centre mass."""
    f = np.zeros_like(q_dot)
    if model.spec.stribeck:
        for rows, group in (([3], "l"), ([4], "r"), ([5, 6, 7, 8], "w")):
            d_v, d_c, d_s, w_s = model.friction(group)
            w = q_dot[:, rows]
            f[:, rows] += joint_friction(w, d_v, d_c, d_s, w_s) - joint_friction(w, d_v, d_c)
    if model.spec.com_offset:
        m, x_c, y_c = model.parameters.m_ch, model.extra["x_c"], model.extra["y_c"]
        w, w_dot = q_dot[:, 2], q_ddot[:, 2]
        a_x, a_y = q_ddot[:, 0] - q_dot[:, 1] * w, q_ddot[:, 1] + q_dot[:, 0] * w
        f[:, 0] += -m * x_c * w**2 - m * y_c * w_dot
        f[:, 1] += m * x_c * w_dot - m * y_c * w**2
        f[:, 2] += m * x_c * a_y - m * y_c * a_x
    return f


def extra_torques(exact: dict, model: ModelParameters) -> np.ndarray:
    """Motor torques (n, 4) whose generalized torques ``H_k^T B u`` are ``H_k^T`` of the extension's
    forces (minimum norm): added to the paper's, the log follows the extended model."""
    n, k = exact["s_dot"].shape
    H = np.broadcast_to(kinematic_model(PROTOTYPE, exact["mode"], exact["alpha"]), (n, 9, k))
    g = np.einsum("nik,ni->nk", H, extension_forces(exact["q_dot"], exact["q_ddot"], model))
    return np.einsum("nij,nj->ni", np.linalg.pinv(PROTOTYPE.i_G * np.swapaxes(H[:, 5:, :], 1, 2)), g)


def model_frame(model: ModelParameters | None, *, lane: bool = False) -> tuple[pd.DataFrame, list[dict]]:
    """The identification sequence (and a lane change, car-like) with torques of ``model`` (None: the paper's)."""
    frame, exact = identification_frame(SHORT)
    parts = [frame[frame.segment == name].copy() for name in SHORT]
    if lane:
        lane_frame, lane_exact = lane_change_frame(t0=float(frame.t.iloc[-1]) + DT)
        parts.append(lane_frame)
        exact = exact + [lane_exact]
    if model is not None:
        for part, ex in zip(parts, exact):
            u = extra_torques(ex, model)
            for i, w in enumerate(WHEELS):
                part[f"m_{w}"] = part[f"m_{w}"].to_numpy() + u[:, i]
    return pd.concat(parts, ignore_index=True), exact


def noisy(frame: pd.DataFrame, seed: int = 7) -> Log:
    rng = np.random.default_rng(seed)
    frame = frame.copy()
    for c in [c for c in frame.columns if c.startswith(("m_", "alpha", "beta"))]:
        frame[c] = frame[c] + 1e-4 * rng.standard_normal(len(frame))
    return Log.from_frame(frame, sidecar={"torque_lead": 0.5})


@pytest.fixture(scope="module")
def paper_log():
    return noisy(model_frame(None, lane=True)[0])


@pytest.fixture(scope="module")
def extended():
    """Noise-free logs following the extended model TRUTH, and the paper's, with car-like rows."""
    frame, exact = model_frame(TRUTH, lane=True)
    return Log.from_frame(frame), exact, Log.from_frame(model_frame(None, lane=True)[0])


def _rel(a, b) -> float:
    """Largest difference relative to the largest value of b (arrays of one scale)."""
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(np.asarray(b))), 1e-300))


def _each(a, b) -> float:
    """Largest relative difference, element by element (parameters of different scales)."""
    return float(np.max(np.abs(np.asarray(a) / np.asarray(b) - 1)))


# --- (a) the paper's path ----------------------------------------------------------------------------------


def test_paper_model_and_a_zero_shift_are_the_paper_path(paper_log):
    """A spec without extensions is the paper's path; a delay of less than 1e-9 sample reads the same
    samples (no interpolation round-off): values, std, offsets and residuals equal to the last bit."""
    base = identify(paper_log, PROTOTYPE, keep_blocks=False)
    for model in (ModelSpec(), ModelSpec(friction="paper", delay=0.0, com_offset=False), ModelSpec(delay=1e-13)):
        other = identify(paper_log, PROTOTYPE, keep_blocks=False, model=model)
        assert np.array_equal(other.parameters.to_vector(), base.parameters.to_vector())
        assert other.std == base.std and other.offsets == base.offsets and other.offsets_std == base.offsets_std
        assert other.residual_rms == base.residual_rms and other.residual_ss == base.residual_ss
        assert other.extra == {} and other.extra_std == {} and other.model == model
    assert base.model == PAPER_MODEL and base.to_json_dict()["model"] == {
        "friction": "paper", "delay_s": 0.0, "delay_std_s": None, "com_offset": False}
    assert set(base.to_json_dict()["parameters"]) == set(PARAMETER_NAMES)


def test_residual_sums_are_the_residuals_per_coordinate(paper_log):
    """``residual_ss``: per coordinate group the residual sum of squares and the rows, the same
    residuals as ``residual_rms`` per (segment, coordinate)."""
    ident = identify(paper_log, PROTOTYPE, keep_blocks=False, model=BOTH, settings=REPORT)
    assert sum(n for _, n in ident.residual_ss.values()) == ident.n_rows
    counts = {}
    for b in log_rows(paper_log, PROTOTYPE, model=BOTH).blocks:
        for j, c in enumerate(b.coordinates):
            counts[f"{b.segment}:{c}"] = counts.get(f"{b.segment}:{c}", 0) + int(b.keep[:, j].sum())
    for group, (rss, rows) in ident.residual_ss.items():
        keys = [k for k in ident.residual_rms if k.rsplit(":", 1)[1] == group]
        assert rows == sum(counts[k] for k in keys)
        assert rss == pytest.approx(sum(ident.residual_rms[k] ** 2 * counts[k] for k in keys), rel=1e-9)


# --- (b) the extension columns ------------------------------------------------------------------------------


@pytest.mark.parametrize("filtering", [Filtering.PARALLEL, Filtering.LITERAL])
def test_model_channels_are_the_laws_on_the_once_filtered_rates(paper_log, filtering):
    """The added channels are ``e tanh`` of each joint's once-filtered rate and ``gamma_dot^2``, through
    the same second filter as Theta in PARALLEL filtering (none in LITERAL); the paper's channels stay
    bit-identical."""
    settings = IdentificationSettings.from_flat(filtering=filtering)
    (a, b), *_ = stretch_bounds(paper_log.t, paper_log.alpha, paper_log.beta, settings)[0]
    paper = filtered_stretch(PROTOTYPE, paper_log, a, b, settings)
    st = filtered_stretch(PROTOTYPE, paper_log, a, b, settings, model=BOTH)
    assert np.array_equal(st.signals, paper.signals) and np.array_equal(st.torque, paper.torque)
    assert np.array_equal(st.q_dot, paper.q_dot) and np.array_equal(st.edge, paper.edge)
    rates = st.q_dot[:, 3:9]
    w_s = np.array([0.05, 0.06, 0.08, 0.08, 0.08, 0.08])
    law = np.column_stack([np.exp(-(rates / w_s) ** 2) * np.tanh(rates / EPSILON), st.q_dot[:, 2] ** 2])
    expected = lowpass(law, st.dt, settings.rows.filter) if filtering is Filtering.PARALLEL else law
    assert st.extra.shape == (b - a, 7)
    assert _rel(st.extra, expected) < 1e-12


def _stretches(log: Log, model: ModelSpec) -> list:
    settings = IdentificationSettings()
    return [filtered_stretch(PROTOTYPE, log, a, b, settings, model=model)
            for a, b in stretch_bounds(log.t, log.alpha, log.beta, settings)[0]]


def test_model_columns_equal_a_direct_evaluation(paper_log):
    """Every block's extension columns are ``H_k^T`` of the filtered channels (numpy, per sample, car-like
    rows with their own H_2; the centre-of-mass columns in car-like rows only: the other modes have no
    rotation with translation), the d_c columns lose the breakaway share, every other column and the
    kept rows are the paper's; the stacked system carries them after the offsets."""
    blocks = log_rows(paper_log, PROTOTYPE, model=BOTH).blocks
    paper = log_rows(paper_log, PROTOTYPE).blocks
    stretches = _stretches(paper_log, BOTH)
    assert {b.mode for b in blocks} >= {Mode.PARKING, Mode.STRAIGHT, Mode.ROTATION, Mode.CAR_LIKE}
    assert len(blocks) == len(paper)
    d_c = [PARAMETER_NAMES.index(n) for n in ("d_cl", "d_cr", "d_cw")]
    others = [i for i in range(11) if i not in d_c]
    for b, p in zip(blocks, paper):
        assert np.array_equal(b.keep, p.keep) and np.array_equal(b.torque, p.torque)
        assert np.array_equal(b.regressor[..., others], p.regressor[..., others])
        st = stretches[int(b.recording.rsplit("#", 1)[1])]
        j = b.sample - st.rows.start
        H = np.broadcast_to(kinematic_model(PROTOTYPE, b.mode, st.alpha[j]), (j.size, 9, len(b.coordinates)))
        S, E = st.signals[j], st.extra[j]
        expected = np.stack([H[:, 3] * E[:, :1], H[:, 4] * E[:, 1:2], np.einsum("nwk,nw->nk", H[:, 5:], E[:, 2:6]),
                             -H[:, 0] * E[:, 6:7] + H[:, 1] * S[:, 2:3] + H[:, 2] * S[:, 1:2],
                             -H[:, 0] * S[:, 2:3] - H[:, 1] * E[:, 6:7] - H[:, 2] * S[:, 0:1]], axis=2)
        if b.mode is not Mode.CAR_LIKE:
            expected[..., 3:] = 0.0
        scale = max(np.abs(expected).max(), 1e-300)
        assert np.abs(b.model_regressor - expected).max() <= 1e-12 * scale, b.segment
        assert _rel(b.regressor[..., d_c] + b.model_regressor[..., :3], p.regressor[..., d_c]) < 1e-13
    A, _ = stacked_system(blocks, offsets=True)
    A0, _ = stacked_system(paper, offsets=True)
    assert A.shape[1] == 11 + 4 + 5 and np.array_equal(A[:, 11:15], A0[:, 11:15])
    assert np.array_equal(A[:, 15:], np.concatenate([b.model_regressor[b.keep] for b in blocks]))


def test_stacked_and_normal_equations_give_the_same_extended_fit(paper_log):
    blocks = log_rows(paper_log, PROTOTYPE, model=BOTH).blocks
    a = fit_blocks(blocks, PROTOTYPE, model=BOTH, settings=REPORT)
    b = fit_blocks(blocks, PROTOTYPE, model=BOTH, settings=REPORT, stacked=True)
    assert _each(a.parameters.to_vector(), b.parameters.to_vector()) < 1e-9
    for n in ("d_sl", "d_sr", "d_sw", "y_c"):
        assert a.extra[n] == pytest.approx(b.extra[n], rel=1e-7, abs=1e-9)
        assert a.extra_std[n] == pytest.approx(b.extra_std[n], rel=1e-6)
    with pytest.raises(ValueError, match="model columns"):  # rows of one model, fit of another
        fit_blocks(blocks, PROTOTYPE, model=STRIBECK)


# --- (c) recovery of the extended model ---------------------------------------------------------------------


def test_regression_stage_recovers_the_extended_model_exactly(extended):
    """Exact signals, torques of TRUTH: every parameter, the breakaway levels and y_c to round-off; x_c,
    which no motion mode sees, held at 0 with an unbounded interval and the reason, not refused."""
    _, exact, _ = extended
    blocks = [equation_block(PROTOTYPE, e["mode"], e["alpha"], e["q_dot"], e["q_ddot"],
                             e["u"] + extra_torques(e, TRUTH), t=e["t"], segment=str(i), model=BOTH)
              for i, e in enumerate(exact)]
    ident = fit_blocks(blocks, PROTOTYPE, model=BOTH)
    assert _each(ident.parameters.to_vector()[FREE], P.to_vector()[FREE]) < 1e-9
    for n in ("d_sl", "d_sr", "d_sw"):
        assert ident.extra[n] == pytest.approx(TRUTH.extra[n], rel=1e-9)
    assert ident.extra["y_c"] == pytest.approx(TRUTH.extra["y_c"], abs=1e-9)
    assert ident.extra["x_c"] == 0.0 and ident.extra_std["x_c"] == math.inf
    assert any(w.startswith("not identifiable: x_c is not seen") for w in ident.warnings)
    assert ident.to_json_dict()["parameters"]["x_c"] == {"value": 0.0, "std": None, "unit": "m", "ci95": [None, None],
                                                         "identified": False}


def test_x_c_cancels_in_every_mode(extended):
    """Why x_c is held, not estimated: along every motion mode's directions the chassis terms of
    m_ch x_c, ``-n_x w^2 + n_y w_dot + n_g a_y``, vanish (car-like: the reference point has no lateral
    velocity, ``a_y = v_x w``, ``w = kappa v_x``); the centripetal force is the rolling constraints'.
    y_c's terms do not: car-like turns determine it."""
    _, exact, _ = extended
    for e in exact:
        block = equation_block(PROTOTYPE, e["mode"], e["alpha"], e["q_dot"], e["q_ddot"], e["u"], model=CENTRE)
        x_c, y_c = block.model_regressor[..., 0], block.model_regressor[..., 1]
        scale = np.abs(e["q_dot"][:, :3]).max() ** 2 + np.abs(e["q_ddot"][:, :3]).max()
        assert np.abs(x_c).max() <= 1e-9 * scale
        if e["mode"] is Mode.CAR_LIKE:
            assert np.abs(y_c).max() > 1e-3 * scale


def test_pipeline_recovers_the_extended_model_from_a_noise_free_log(extended):
    """Log -> filters -> rows -> regression on torques of TRUTH: the paper's parameters as on the paper's
    log (1e-4), the breakaway levels within 1e-4 and y_c within 1e-5 m; on the paper's log the same
    model gives d_s = d_c and y_c = 0."""
    log, _, paper_log = extended
    ident = identify(log, PROTOTYPE, model=BOTH, settings=REPORT, keep_blocks=False)
    assert _each(ident.parameters.to_vector()[FREE], P.to_vector()[FREE]) < 1e-4
    for n in ("d_sl", "d_sr", "d_sw"):
        assert ident.extra[n] == pytest.approx(TRUTH.extra[n], rel=1e-4)
        assert 0 < ident.extra_std[n] < 1e-3 * ident.extra[n]
    assert ident.extra["y_c"] == pytest.approx(-0.08, abs=1e-5)
    assert ident.extra_std["y_c"] < 1e-4 and ident.extra_std["x_c"] == math.inf
    effect_free = identify(paper_log, PROTOTYPE, model=BOTH, settings=REPORT, keep_blocks=False)
    for n, c in (("d_sl", "d_cl"), ("d_sr", "d_cr"), ("d_sw", "d_cw")):
        assert effect_free.extra[n] == pytest.approx(getattr(P, c), rel=1e-4)
    assert abs(effect_free.extra["y_c"]) < 1e-5
    paper = identify(log, PROTOTYPE, keep_blocks=False, settings=REPORT)  # the paper's model on the same log
    assert _each(paper.parameters.to_vector()[FREE], P.to_vector()[FREE]) > 0.1


def test_breakaway_below_zero_is_refused_and_below_sliding_warned():
    """A breakaway level is a friction: below zero it is refused by name; below the sliding level it is
    what the data say, with a warning (the wheels: their rows reach into the Stribeck range)."""
    levels = {"d_sl": P.d_cl, "d_sr": P.d_cr, "d_sw": 0.7 * P.d_cw, "w_sl": 0.05, "w_sr": 0.06, "w_sw": 0.08}
    log = Log.from_frame(model_frame(ModelParameters(P, levels, spec=STRIBECK))[0])
    ident = identify(log, PROTOTYPE, model=STRIBECK, keep_blocks=False, settings=SLOW_ROWS)
    assert ident.rows.stribeck_support["w"] >= MIN_SUPPORT_ROWS
    assert ident.extra["d_sw"] == pytest.approx(0.7 * P.d_cw, rel=1e-4)
    assert any(w.startswith("d_sw = ") and "below the sliding level d_cw" in w for w in ident.warnings)
    assert not any(w.startswith(("d_sl = ", "d_sr = ")) for w in ident.warnings)
    negative = Log.from_frame(model_frame(ModelParameters(P, {**levels, "d_sw": -0.5 * P.d_cw}, spec=STRIBECK))[0])
    with pytest.raises(ImplausibleError, match="d_sw = "):
        identify(negative, PROTOTYPE, model=STRIBECK, keep_blocks=False, settings=SLOW_ROWS)


def test_a_refused_breakaway_level_is_held_and_the_model_fitted_again(tmp_path):
    """identify refuses an impossible breakaway level by name; identify_model holds it at the paper's law
    (ModelSpec.held), fits again and says why: the level at d_c with an unbounded interval, the refusal's
    reason a warning, the fit the same as one asked to hold it, and the held level in the JSON's model and
    in the parameter file (read back). (Exact model data: the misfit the held level leaves makes the
    steering's parameters noisy, reported here, refused by the default settings.)"""
    levels = {"d_sl": P.d_cl, "d_sr": P.d_cr, "d_sw": -0.5 * P.d_cw, "w_sl": 0.05, "w_sr": 0.06, "w_sw": 0.08}
    log = Log.from_frame(model_frame(ModelParameters(P, levels, spec=STRIBECK))[0])
    settings = SLOW_ROWS.replace(unexcited="report")
    with pytest.raises(ImplausibleError, match="d_sw = "):
        identify(log, PROTOTYPE, model=STRIBECK, keep_blocks=False, settings=settings)
    ident = identify_model(log, PROTOTYPE, model=STRIBECK, keep_blocks=False, settings=settings)
    assert ident.model.held == ("d_sw",)
    assert ident.extra["d_sw"] == ident.parameters.d_cw and ident.extra_std["d_sw"] == math.inf
    assert sum(w.startswith("d_sw not determined by these data, held at the paper's law") and "d_sw = " in w
               for w in ident.warnings) == 1 and sum(w.startswith("d_sw") for w in ident.warnings) == 1
    with pytest.raises(UnidentifiableError, match="C_l"):  # the default settings refuse what the misfit leaves
        identify_model(log, PROTOTYPE, model=STRIBECK, keep_blocks=False, settings=SLOW_ROWS)
    asked = identify(log, PROTOTYPE, model=STRIBECK.replace(held=("d_sw",)), keep_blocks=False, settings=settings)
    assert asked.parameters == ident.parameters and asked.extra == ident.extra
    assert ident.to_json_dict()["model"]["held"] == ["d_sw"]
    assert ident.to_json_dict()["parameters"]["d_sw"]["identified"] is False
    read = read_model_parameters(ident.write(tmp_path / "held.yaml"))
    assert read.spec.held == ("d_sw",) and read.value("d_sw") == read.parameters.d_cw
    bad = tmp_path / "bad.yaml"
    bad.write_text((tmp_path / "held.yaml").read_text().replace("- d_sw", "- d_cw"))
    with pytest.raises(PlatformFileError, match=r"bad.yaml: model: held: 'd_cw': expected a list of some of"):
        read_model_parameters(bad)


def test_steering_levels_held_with_their_unexcited_coulomb_columns(paper_log):
    """The chassis segments alone: the steering's levels (no rows in their Stribeck range) are tied to d_cl,
    d_cr, which no row excites; reported, both are held together (was: a ValueError from the tie's
    lost target) and the Stribeck fit is the paper's."""
    settings = REPORT.replace(segments=("straight", "rotation"))
    ident = identify(paper_log, PROTOTYPE, model=STRIBECK, keep_blocks=False, settings=settings)
    paper = identify(paper_log, PROTOTYPE, keep_blocks=False, settings=settings)
    assert ident.parameters.to_vector() == pytest.approx(paper.parameters.to_vector(), rel=1e-9)
    assert ident.extra["d_sl"] == ident.parameters.d_cl == 0.0 and ident.extra_std["d_sl"] == math.inf


def test_a_level_at_an_undetermined_stribeck_velocity_is_held():
    """Effect-free model data, w_s searched: the wheels' profile does not rise (no breakaway to see), so the
    level fitted at the w_sw found is no static level; it is held with why (never a finite std at an
    undetermined w_s); the steering groups are held for want of rows, said once each, as before. With
    unexcited="report" the level is not held but reported with an unbounded interval."""
    log = noisy(model_frame(None)[0])
    ident = identify_model(log, PROTOTYPE, model=ModelSpec(friction="stribeck"), keep_blocks=False, settings=SLOW_ROWS)
    assert ident.model.held == ("d_sw",) and ident.extra["d_sw"] == ident.parameters.d_cw
    assert all(ident.extra_std[n] == math.inf for n in ("d_sl", "d_sr", "d_sw", "w_sw"))
    assert sum(w.startswith("d_sw not determined by these data") and "Stribeck velocity w_sw" in w
               for w in ident.warnings) == 1
    assert [sum(w.startswith(n) for w in ident.warnings) for n in ("d_sl", "d_sr", "d_sw")] == [1, 1, 1]
    reported = identify_model(log, PROTOTYPE, model=ModelSpec(friction="stribeck"), keep_blocks=False,
                              settings=SLOW_ROWS.replace(unexcited="report"))  # not held: reported unbounded
    assert reported.model.held == () and reported.extra_std["d_sw"] == math.inf
    assert any(w.startswith("d_sw not determined by these data (interval unbounded)") for w in reported.warnings)


def test_only_the_breakaway_levels_of_a_refusal_are_held():
    refusal = UnidentifiableError([Dependency("d_sl", (), math.nan, relative_std=1.12),
                                   Dependency("C_l", (), math.nan, relative_std=0.7)])
    assert list(refused_levels(refusal, STRIBECK)) == ["d_sl"] and "112 %" in refused_levels(refusal, STRIBECK)["d_sl"]
    assert refused_levels(refusal, STRIBECK.replace(held=("d_sl",))) == {}
    assert refused_levels(ValueError("d_sl"), STRIBECK) == {}


@pytest.mark.parametrize("held, match", [(("d_cl",), "expected a list of some of"), ("d_sw", "expected a list"),
                                         (("d_sw",), "only with friction: stribeck")])
def test_held_levels_are_breakaway_levels_of_a_stribeck_model(held, match):
    friction = "paper" if match.startswith("only") else "stribeck"
    with pytest.raises(ValueError, match=match):
        ModelSpec(friction=friction, held=held)
    spec = ModelSpec(friction="stribeck", held=["d_sw", "d_sl"])
    assert spec.held == ("d_sl", "d_sw") and spec.free_stribeck_names == ("w_sr",)
    assert model_from_mapping(spec.to_dict()) == spec and "held" not in ModelSpec(friction="stribeck").to_dict()


def test_breakaway_without_rows_in_the_stribeck_range_is_undetermined():
    """The default stiction thresholds keep no steering row slower than w_s: the steering's breakaway
    columns hold only the filter's tails (which on stick-slip data fit garbage), so d_sl, d_sr are
    reported at the paper's law with an unbounded interval and a warning naming them, never a finite
    number; the wheels, which roll slowly in the chassis motions, keep theirs."""
    levels = {"d_sl": 1.3 * P.d_cl, "d_sr": 1.3 * P.d_cr, "d_sw": P.d_cw, "w_sl": 0.05, "w_sr": 0.06, "w_sw": 0.08}
    log = Log.from_frame(model_frame(ModelParameters(P, levels, spec=STRIBECK))[0])
    ident = identify(log, PROTOTYPE, model=STRIBECK, keep_blocks=False)
    support = ident.rows.stribeck_support
    assert support["l"] < MIN_SUPPORT_ROWS and support["r"] < MIN_SUPPORT_ROWS
    for name, coulomb in (("d_sl", "d_cl"), ("d_sr", "d_cr")):
        assert ident.extra_std[name] == math.inf
        assert ident.extra[name] == getattr(ident.parameters, coulomb)
        assert any(w.startswith(f"{name} not determined") for w in ident.warnings)
    assert ident.rows.to_dict()["stribeck_support"] == support


# --- (d) the torque delay -----------------------------------------------------------------------------------


def _delayed(frame: pd.DataFrame, shift: float) -> Log:
    """The log whose torque columns lag by ``shift`` samples: the torque logged at t acted at t - shift dt."""
    out = frame.copy()
    cols = [f"m_{w}" for w in WHEELS]
    n = len(frame)
    u = frame[cols].to_numpy()
    out[cols] = np.column_stack([np.interp(np.arange(n) - shift, np.arange(n), u[:, i]) for i in range(4)])
    return Log.from_frame(out)


@pytest.fixture(scope="module")
def sequence():
    frame, _ = model_frame(None)
    return frame, identify(Log.from_frame(frame), PROTOTYPE, keep_blocks=False)


@pytest.mark.parametrize("shift, tolerance", [(3, 1e-6), (2.5, 2e-4), (-2, 1e-6)])
def test_delay_undoes_a_lag_of_the_torque_columns(sequence, shift, tolerance):
    """Torque columns lagging by ``shift`` samples (a whole number: exact; half: interpolated twice)
    identified with ``delay = shift dt`` give the unlagged log's parameters; without it the inertias move
    by percents. The rows read past the stretch join its edges."""
    frame, base = sequence
    log = _delayed(frame, shift)
    ident = identify(log, PROTOTYPE, keep_blocks=False, model=ModelSpec(delay=shift * DT))
    assert _each(ident.parameters.to_vector()[FREE], base.parameters.to_vector()[FREE]) < tolerance
    assert ident.rows.edge == base.rows.edge + math.ceil(abs(shift)) * base.rows.stretches
    assert ident.to_json_dict()["model"]["delay_s"] == shift * DT
    lagging = identify(log, PROTOTYPE, keep_blocks=False, settings=REPORT)
    assert abs(lagging.parameters.C_l / base.parameters.C_l - 1) > 0.01


@hsettings(max_examples=60, deadline=None)
@given(hst.floats(-6.0, 6.0), hst.integers(8, 40))
def test_delayed_torque_reads_the_samples_later(shift, n):
    """Exact on a linear ramp (linear interpolation), whole shifts are the samples themselves, and the
    rows whose time leaves the stretch are counted at the end they leave."""
    ramp = np.column_stack([np.arange(n) * k + 1.0 for k in (1.0, -2.0, 0.5, 3.0)])
    out, front, back = delayed_torque(ramp, shift)
    inside = slice(front, n - back)
    expected = (np.arange(n)[:, None] + shift) * np.array([1.0, -2.0, 0.5, 3.0]) + 1.0
    assert np.allclose(out[inside], expected[inside], rtol=0, atol=1e-9)
    assert front == min(n, max(0, -math.floor(shift))) and back == min(n, max(0, math.ceil(shift)))
    whole = round(shift)
    shifted, _, _ = delayed_torque(ramp, float(whole))
    rows = np.arange(max(0, -whole), min(n, n - whole))
    assert np.array_equal(shifted[rows], ramp[rows + whole])


# --- (e) refusals -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("model, match", [
    (ModelSpec(delay="auto"), r"delay='auto' must be searched.*identify_model"),
    (ModelSpec(friction="stribeck"), r"stribeck_velocities=None must be searched"),
    ("stribeck", r"expected an agvdyn.model_spec.ModelSpec"),
])
def test_unresolved_model_is_refused_by_name(paper_log, model, match):
    with pytest.raises(ValueError, match=match):
        identify(paper_log, PROTOTYPE, model=model)
    with pytest.raises(ValueError, match=match):
        log_rows(paper_log, PROTOTYPE, model=model)


def test_rows_of_another_model_are_refused(paper_log):
    """Row passes given to identify must carry the model's columns (the compiled gather writes where
    the columns say): rows of the paper's model for an extended fit are a named error."""
    with pytest.raises(ValueError, match="made for another model"):
        identify(paper_log, PROTOTYPE, model=BOTH, rows=row_passes([paper_log], PROTOTYPE))
    rows = row_passes([paper_log], PROTOTYPE, model=BOTH)
    ident = identify(paper_log, PROTOTYPE, model=BOTH, rows=rows, settings=REPORT, keep_blocks=False)
    again = identify(paper_log, PROTOTYPE, model=BOTH, settings=REPORT, keep_blocks=False)
    assert ident.extra == again.extra and ident.extra_std == again.extra_std


def test_centre_offset_without_car_like_rows_is_refused_or_reported():
    """Straight and rotation alone do not see the centre of mass (no rotation with translation): y_c is
    refused naming what excites it, or (unexcited="report") held with an unbounded interval, never a
    number from the noise of the yaw rate in straight motion."""
    log = noisy(model_frame(None)[0])
    with pytest.raises(UnidentifiableError, match="car-like turns") as info:
        identify(log, PROTOTYPE, model=CENTRE, keep_blocks=False)
    assert [d.name for d in info.value.dependencies] == ["y_c"]
    assert "its regressor column is zero" in str(info.value)
    ident = identify(log, PROTOTYPE, model=CENTRE, keep_blocks=False, settings=REPORT)
    assert ident.extra_std == {"x_c": math.inf, "y_c": math.inf}
    assert any(w.startswith("not identified, 95 % interval unbounded") and "y_c" in w for w in ident.warnings)


# --- the result: JSON, parameter file, uncertainty ----------------------------------------------------------


def test_json_and_parameter_file_carry_the_model(extended, tmp_path):
    log, _, _ = extended
    ident = identify(log, PROTOTYPE, model=BOTH, settings=REPORT, keep_blocks=False)
    out = ident.to_json_dict()
    assert out["model"] == {"friction": "stribeck", "delay_s": 0.0, "delay_std_s": None, "com_offset": True}
    entries = out["parameters"]
    for n in ("d_sl", "d_sr", "d_sw", "y_c"):
        assert entries[n]["value"] == ident.extra[n] and entries[n]["unit"] in ("N m", "m")
        assert entries[n]["identified"] is True and entries[n]["std"] == ident.extra_std[n]
        assert entries[n]["ci95"][0] < entries[n]["value"] < entries[n]["ci95"][1]
    assert entries["w_sl"] == {"value": 0.05, "std": None, "unit": "rad/s"}
    assert set(ident.to_frame().index) == set(PARAMETER_NAMES) | set(ident.extra)
    for suffix in (".yaml", ".json"):
        path = ident.write(tmp_path / f"p{suffix}")
        read = read_model_parameters(path)
        assert read.spec == BOTH and read.delay_s == 0.0
        assert read.extra == pytest.approx(ident.extra, rel=1e-15)
        assert read.parameters == ident.parameters
    paper = identify(log, PROTOTYPE, settings=REPORT, keep_blocks=False)
    read = read_model_parameters(paper.write(tmp_path / "paper.yaml"))
    assert read.spec == PAPER_MODEL and read.extra == {} and read.parameters == paper.parameters
    bad = tmp_path / "bad.yaml"
    bad.write_text((tmp_path / "p.yaml").read_text().replace("friction: stribeck", "friction: dry"))
    with pytest.raises(PlatformFileError, match=r"bad.yaml: model: friction='dry'"):
        read_model_parameters(bad)


def test_extension_columns_get_the_uncertainty_methods_std(paper_log):
    """Every uncertainty method gives the extension columns a std like the others (finite where the data
    determine them, inf for the held x_c)."""
    for method in ("classic", "hac", "jackknife", "bootstrap"):
        ident = identify(paper_log, PROTOTYPE, model=BOTH, keep_blocks=False,
                         settings=REPORT.replace(uncertainty=method, bootstrap_replicates=20))
        assert all(0 < ident.extra_std[n] < math.inf for n in ("d_sl", "d_sr", "d_sw", "y_c")), method
        assert set(ident.extra_std) == {"d_sl", "d_sr", "d_sw", "x_c", "y_c"} and ident.extra_std["x_c"] == math.inf


@hsettings(max_examples=25, deadline=None)
@given(hst.floats(-150.0, 150.0), hst.floats(300.0, 1500.0), hst.floats(0.05, 0.9), hst.floats(0.0, 0.3))
def test_centre_std_is_the_delta_method(a, m, rho, rel):
    """x_c = (m_ch x_c) / m_ch: its std from the covariance of the two columns against Monte Carlo of
    the ratio (small spread: the linearisation holds); inf when either column is undetermined."""
    names = list(PARAMETER_NAMES) + ["x_c", "y_c"]
    theta = np.r_[P.to_vector(), a, 0.0]
    theta[PARAMETER_NAMES.index("m_ch")] = m
    sd = np.array([0.002 * m, 0.5 + rel * abs(a)]) * 0.01
    cov2 = np.array([[sd[0] ** 2, rho * sd[0] * sd[1]], [rho * sd[0] * sd[1], sd[1] ** 2]])
    free = ["m_ch", "x_c", "y_c"]
    cov = np.zeros((3, 3))
    cov[:2, :2] = cov2
    cov[2, 2] = 1.0
    std = dict(zip(free, np.sqrt(np.diag(cov))))
    extra, extra_std = extension_estimates(CENTRE, names, theta, free, cov, std)
    assert extra["x_c"] == a / m
    draws = np.random.default_rng(0).multivariate_normal([m, a], cov2, 20000)
    assert extra_std["x_c"] == pytest.approx(np.std(draws[:, 1] / draws[:, 0]), rel=0.05)
    assert extension_estimates(CENTRE, names, theta, free, cov, {**std, "m_ch": math.inf})[1]["x_c"] == math.inf
    held = extension_estimates(CENTRE, names, theta, ["m_ch", "y_c"], cov[np.ix_([0, 2], [0, 2])], std)
    assert held[1]["x_c"] == math.inf
