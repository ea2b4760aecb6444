"""Issue 27, stage settings: IdentificationSettings as one object per stage (rows, fit, uncertainty), its flat
``to_dict`` keys unchanged, the CLI's option defaults equal to the fields', and one row mask shared by the
planner and the identification."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import typer.main

from agvdyn.cli import _defaults, app
from agvdyn.identification import (
    EstimatorName,
    FitSettings,
    IdentificationSettings,
    RowSettings,
    UncertaintyMethod,
    UncertaintySettings,
    Unexcited,
)
from agvdyn.identification.estimators import ESTIMATORS
from agvdyn.identification.rows import NO_MODE, _modes_and_virtual_angle, _stretch_blocks
from agvdyn.identification.stretches import filtered_stretch
from agvdyn.io import Log
from agvdyn.platform import PROTOTYPE
from agvdyn.row_rules import guarded_mask, row_mask
from agvdyn.trajectories import planner as pl
from model_logs import identification_frame

#: The keys of ``IdentificationSettings.to_dict()`` in their order: written into parameter files and JSON.
TO_DICT_KEYS = (
    "filter_cutoff_rad_s", "filter_order", "derivative", "filtering", "segments", "slip_threshold", "torque_offsets",
    "torque_lead", "plausibility", "stiction_threshold", "steering_threshold", "stiction_guard", "steering_guard",
    "mode_tolerance", "epsilon", "rank_tolerance", "sample_jitter", "rest_speed", "steering_rest_rate", "edge_guard",
    "slip_spread", "slip_floor", "slip_guard", "slip_cutoff", "stretch_gap", "steering_jump_rate", "wheel_jump_rate",
    "max_inflation", "max_relative_std", "unexcited", "estimator", "robust_loss", "bounds", "uncertainty",
    "bandwidth", "bandwidth_factor", "min_bandwidth", "bootstrap_replicates", "seed",
)


def test_to_dict_keys_and_default_values_are_unchanged():
    out = IdentificationSettings().to_dict()
    assert tuple(out) == TO_DICT_KEYS
    assert out == {
        "filter_cutoff_rad_s": 40.0, "filter_order": 4, "derivative": "central", "filtering": "parallel",
        "segments": None, "slip_threshold": None, "torque_offsets": True, "torque_lead": None, "plausibility": True,
        "stiction_threshold": 0.05, "steering_threshold": 0.1, "stiction_guard": 2.0, "steering_guard": 4.0,
        "mode_tolerance": 0.02, "epsilon": 0.01, "rank_tolerance": 1e-6, "sample_jitter": 0.05, "rest_speed": 0.01,
        "steering_rest_rate": 0.02, "edge_guard": 10.0, "slip_spread": 10.0, "slip_floor": 0.025, "slip_guard": 0.1,
        "slip_cutoff": 250.0, "stretch_gap": 3.0, "steering_jump_rate": 20.0, "wheel_jump_rate": 1000.0,
        "max_inflation": 100.0, "max_relative_std": 0.5, "unexcited": None, "estimator": "wls",
        "robust_loss": "tukey", "bounds": [], "uncertainty": "jackknife", "bandwidth": None, "bandwidth_factor": 2.0,
        "min_bandwidth": 50, "bootstrap_replicates": 200, "seed": 0,
    }
    assert all(not isinstance(v, (EstimatorName, UncertaintyMethod, Unexcited)) for v in out.values())  # plain YAML


def test_flat_names_build_the_stages_and_to_dict_gives_them_back():
    changes = {"stiction_threshold": 0.07, "steering_guard": 3, "segments": ("straight",), "slip_threshold": math.inf,
               "torque_lead": 0.5, "filtering": "literal", "estimator": "bounded", "bounds": [("C_l", 0, 1)],
               "unexcited": "report", "torque_offsets": False, "rank_tolerance": 1e-7, "uncertainty": "hac",
               "bandwidth": 60, "seed": 3, "bootstrap_replicates": 40}
    s = IdentificationSettings.from_flat(**changes)
    assert s.rows.steering_guard == 3 and s.rows.segments == ("straight",) and s.fit.estimator is EstimatorName.BOUNDED
    assert s.fit.unexcited is Unexcited.REPORT and s.uncertainty.method is UncertaintyMethod.HAC
    assert s.rows.filtering.value == "literal" and s.fit.reports_unexcited
    out = s.to_dict()
    assert tuple(out) == TO_DICT_KEYS
    for key, value in changes.items():
        expected = {"segments": ["straight"], "bounds": [["C_l", 0.0, 1.0]]}.get(key, value)
        assert out[key] == expected, key
    assert s.replace(estimator="ols").fit.estimator is EstimatorName.OLS and s.fit.estimator is EstimatorName.BOUNDED
    assert IdentificationSettings.from_flat() == IdentificationSettings()
    with pytest.raises(TypeError, match="stiction_gard"):
        IdentificationSettings.from_flat(stiction_gard=2)


def test_choices_are_enums_that_raise_on_anything_else():
    assert [e.value for e in EstimatorName] == list(ESTIMATORS)
    assert _defaults.ESTIMATORS == tuple(e.value for e in EstimatorName)
    for stage, key, bad in ((FitSettings, "estimator", "lasso"), (FitSettings, "robust_loss", "cauchy"),
                            (FitSettings, "unexcited", "ignore"), (UncertaintySettings, "method", "delta"),
                            (RowSettings, "filtering", "smooth")):
        with pytest.raises(ValueError, match=bad):
            stage(**{key: bad})
    with pytest.raises(ValueError, match="unknown segment names"):
        IdentificationSettings(rows=RowSettings(segments=("straigth",)))
    with pytest.raises(TypeError, match="RowSettings"):
        IdentificationSettings(rows=FitSettings())  # type: ignore[arg-type]


def _field(settings: IdentificationSettings, path: str):
    value = settings
    for part in path.split("."):
        value = getattr(value, part)
    return value.value if hasattr(value, "value") else value


@pytest.mark.parametrize("command", ["identify", "validate", "report"])
def test_every_cli_identification_option_defaults_to_its_settings_field(command):
    group = typer.main.get_command(app)
    params = {p.name: p for p in group.commands[command].params}
    defaults = IdentificationSettings()
    checked = [name for name in _defaults.OPTION_FIELDS if name in params]
    for name in checked:
        assert params[name].default == _field(defaults, _defaults.OPTION_FIELDS[name]), (command, name)
    row_options = [n for n, path in _defaults.OPTION_FIELDS.items() if path.startswith("rows.")
                   and n not in ("segments", "slip_threshold", "torque_lead")]
    assert set(row_options) <= set(checked)  # every command sets the row rules it predicts with
    if command != "validate":
        assert set(checked) == set(_defaults.OPTION_FIELDS)


def test_cli_settings_at_their_defaults_are_the_library_defaults():
    from agvdyn.cli.identify_commands import _settings

    assert _settings() == IdentificationSettings()
    s = _settings(steering_guard=2.0, estimator="ols", uncertainty="classic", segments="straight, rotation")
    assert s == IdentificationSettings.from_flat(steering_guard=2.0, estimator="ols", uncertainty="classic",
                                                 segments=("straight", "rotation"))


def test_the_planner_takes_the_identifications_row_rules():
    ident, plan = IdentificationSettings(), pl.PlanSettings()
    assert plan.rows == ident.rows
    assert plan.steering_weights_guard == 2.0 and plan.guard("alpha_l", weights=True) == 0.05  # stop 23-24
    rows = RowSettings(steering_guard=6.0, stiction_threshold=0.08)
    other = pl.PlanSettings(rows=rows)
    assert other.guard("alpha_r") == rows.seconds(6.0) and other.threshold("y_ch") == 0.08
    assert other.guard_samples("alpha_r", 0.002) == rows.guard_samples(6.0, 0.002) == 75
    assert not hasattr(pl.evaluation, "_guarded") and pl.evaluation.row_mask is row_mask


@pytest.fixture(scope="module")
def stretch():
    frame, _ = identification_frame({"steer_left": 4.0, "steer_right": 4.0, "straight": 5.0, "rotation": 5.0},
                                    align=0.5)
    rng = np.random.default_rng(3)
    for c in [c for c in frame.columns if c.startswith(("m_", "alpha", "beta"))]:
        frame[c] = frame[c] + 1e-4 * rng.standard_normal(len(frame))
    return Log.from_frame(frame, sidecar={"torque_lead": 0.5})


@pytest.mark.parametrize("steering_guard", [2.0, 4.0])
def test_planner_and_identification_keep_the_same_rows_of_the_same_signals(stretch, steering_guard):
    """The identification's compiled row pass keeps, run by run, exactly the rows :func:`row_mask` keeps with
    the planner's thresholds and guards (``PlanSettings(rows=settings.rows)``) on the same filtered signals."""
    settings = IdentificationSettings.from_flat(steering_guard=steering_guard)
    plan = pl.PlanSettings(rows=settings.rows)
    st = filtered_stretch(PROTOTYPE, stretch, 0, len(stretch.t), settings)
    mode, av = _modes_and_virtual_angle(PROTOTYPE, st, settings)
    usable = ~st.edge & (mode != NO_MODE)
    usable[len(usable) // 2: len(usable) // 2 + 30] = False  # a hole inside a run
    blocks = _stretch_blocks(PROTOTYPE, st, mode, av, usable, None, settings, "r", np.ones(st.n, dtype=bool))
    assert blocks and sum(int(b.keep.sum()) for b in blocks) > 1000
    for b in blocks:
        a, e = int(b.sample[0]), int(b.sample[-1]) + 1
        for j, coordinate in enumerate(b.mode.coordinates):
            expected = row_mask(b.s_dot[:, j], plan.threshold(coordinate), plan.guard_samples(coordinate, st.dt),
                                usable[a:e])
            np.testing.assert_array_equal(b.keep[:, j], expected, err_msg=f"{b.mode} {coordinate}")


def test_row_mask_is_the_guarded_stiction_mask():
    v = np.array([0.0, 0.2, 0.3, 0.3, 0.01, 0.3, 0.3, 0.3, 0.3, 0.3, -0.4, 0.3])
    usable = np.ones(v.size, dtype=bool)
    usable[8] = False
    assert row_mask(v, 0.1, 0).tolist() == (np.abs(v) >= 0.1).tolist()
    assert row_mask(v, 0.1, 1, usable).tolist() == guarded_mask((np.abs(v) >= 0.1) & usable, 1).tolist()
    assert row_mask(v, 0.1, 1, usable).tolist() == [False, False, True, False, False, False, True, False, False,
                                                    False, True, False]


def test_each_stage_default_is_defined_once():
    ident = IdentificationSettings()
    for stage in ("rows", "fit", "uncertainty"):
        assert getattr(ident, stage) == type(getattr(ident, stage))()
    assert {f.name for f in dataclasses.fields(IdentificationSettings)} == {"rows", "fit", "uncertainty"}
