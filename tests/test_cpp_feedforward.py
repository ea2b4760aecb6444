"""The C++ feed-forward (cpp/, agvdyn.ffcpp) against the Python reference (agvdyn.dynamics).

Shared test vectors (cpp/tests/vectors.json, STYLE.md rule 9) are current and met by the extension;
``agvdyn feedforward --engine cpp`` equals ``--engine python`` to 1e-9 relative on the built-in
experiments and on a trajectory file; both engines refuse the same inputs; the C++ reader reads the
parameter files agvdyn writes; ``import agvdyn`` never needs the extension.

Without the extension these tests are skipped, unless AGVDYN_REQUIRE_CPP=1 (set by ``make test``).
"""
from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import agvdyn.cli  # noqa: F401  (registers the commands)
from agvdyn import ffcpp
from agvdyn.cli._app import app
from agvdyn.dynamics import feedforward_torques
from agvdyn.kinematics import Mode, joint_motion
from agvdyn.model_spec import ModelParameters, ModelSpec
from agvdyn.platform import (
    PAPER_PARAMETERS,
    PAPER_STD,
    PROTOTYPE,
    Geometry,
    ParameterFile,
    Parameters,
    read_parameters,
    write_parameters,
)

ROOT = Path(__file__).resolve().parents[1]
VECTORS = ROOT / "cpp" / "tests" / "vectors.json"
TORQUES = ["m_fl", "m_rl", "m_fr", "m_rr"]
RELATIVE = 1e-9
runner = CliRunner()

if not ffcpp.available():
    if os.environ.get("AGVDYN_REQUIRE_CPP") == "1":
        raise RuntimeError(f"AGVDYN_REQUIRE_CPP=1 but {ffcpp.__name__}._core is missing: reinstall with `pip install -e .`")
    pytest.skip("the C++ extension agvdyn.ffcpp._core is not built", allow_module_level=True)


def _load_generator():
    spec = importlib.util.spec_from_file_location("make_vectors", ROOT / "cpp" / "tests" / "make_vectors.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def vectors() -> dict:
    return json.loads(VECTORS.read_text(encoding="utf-8"))


def _models(vectors):
    return [(Geometry(**m["geometry"], name=m["name"]), Parameters(**m["parameters"])) for m in vectors["models"]]


def _close(actual: np.ndarray, reference: np.ndarray, relative: float, absolute: float) -> float:
    """Largest deviation relative to the row's largest reference value; asserts the vectors' rule per row."""
    actual, reference = np.atleast_2d(actual), np.atleast_2d(reference)
    scale = np.abs(reference).max(axis=1)
    dev = np.abs(actual - reference).max(axis=1)
    bad = dev > relative * scale + absolute
    assert not bad.any(), (f"row {int(np.argmax(bad))}: {actual[bad][0]} vs {reference[bad][0]} "
                           f"(deviation {dev[bad][0]:.3g})")
    return float(np.max(dev / np.where(scale > 0, scale, 1.0)))


def test_vectors_file_is_current():
    """The committed vectors are what cpp/tests/make_vectors.py computes with the Python model now."""
    fresh = json.loads(json.dumps(_load_generator().vectors()))  # NaN/inf as the file writes them
    stored = json.loads(VECTORS.read_text(encoding="utf-8"))
    assert stored["models"] == fresh["models"] and stored["settings"] == fresh["settings"]
    assert len(stored["cases"]) == len(fresh["cases"]) >= 200
    for old, new in zip(stored["cases"], fresh["cases"]):
        assert (old["model"], old["mode"]) == (new["model"], new["mode"])
        for key in ("alpha", "s_dot", "s_ddot", "q_dot", "q_ddot", "u"):
            np.testing.assert_allclose(old[key], new[key], rtol=1e-12, atol=1e-14,
                                       err_msg=f"{key}: regenerate with `.venv/bin/python cpp/tests/make_vectors.py`")
    assert [(c["mode"], c["status"]) for c in stored["invalid"]] == [(c["mode"], c["status"]) for c in fresh["invalid"]]
    assert stored["extended_models"] == fresh["extended_models"]
    assert len(stored["extended_cases"]) == len(fresh["extended_cases"]) >= 200
    for old, new in zip(stored["extended_cases"], fresh["extended_cases"]):
        assert (old["model"], old["mode"]) == (new["model"], new["mode"])
        for key in ("alpha", "s_dot", "s_ddot", "q_dot", "q_ddot", "u"):
            np.testing.assert_allclose(old[key], new[key], rtol=1e-12, atol=1e-14,
                                       err_msg=f"{key}: regenerate with `.venv/bin/python cpp/tests/make_vectors.py`")


def _extended_models(vectors) -> list[tuple[Geometry, ModelParameters]]:
    vehicles = _models(vectors)
    out = []
    for m in vectors["extended_models"]:
        geom, params = vehicles[m["vehicle"]]
        spec = ModelSpec(friction=m["model"]["friction"], delay=m["model"]["delay_s"], com_offset=m["model"]["com_offset"])
        out.append((geom, ModelParameters(params, m["extra"], m["model"]["delay_s"], spec)))
    return out


def test_extension_meets_the_extended_model_vectors(vectors):
    """Stribeck friction per joint group, an off-centre centre of mass and a delay: the C++ library
    through the extension equals the stored Python torques (1e-9 relative), and the models differ
    from the paper's on these cases (the vectors test something)."""
    tol = vectors["tolerance"]
    models = _extended_models(vectors)
    worst, changed = 0.0, 0.0
    for (index, label), group in pd.DataFrame(vectors["extended_cases"]).groupby(["model", "mode"]):
        geom, model = models[index]
        alpha, s_dot, s_ddot = (np.array(group[k].tolist()) for k in ("alpha", "s_dot", "s_ddot"))
        u = ffcpp.feedforward_torques(geom, model, label, alpha, s_dot, s_ddot)
        reference = np.array(group["u"].tolist())
        worst = max(worst, _close(u, reference, tol["relative"], tol["absolute"]))
        paper = feedforward_torques(geom, model.parameters, label, alpha, s_dot, s_ddot)
        changed = max(changed, float(np.max(np.abs(paper - reference) / np.abs(reference).max())))
    assert worst < 1e-10
    assert changed > 0.05
    print(f"extended vectors: largest deviation {worst:.3g} of the largest torque")


def test_random_extended_models_agree_with_the_reference():
    from conftest import configurations

    rng = np.random.default_rng(30)
    p = PAPER_PARAMETERS
    extra = {"d_sl": 1.3 * p.d_cl, "d_sr": 0.9 * p.d_cr, "d_sw": 1.5 * p.d_cw, "w_sl": 0.05, "w_sr": 0.2,
             "w_sw": 0.02, "x_c": -0.2, "y_c": 0.15}
    for spec in (ModelSpec(friction="stribeck"), ModelSpec(com_offset=True),
                 ModelSpec(friction="stribeck", com_offset=True, delay=0.004)):
        wanted = {k: v for k, v in extra.items() if k in spec.linear_names or (spec.stribeck and k.startswith("w_s"))}
        model = ModelParameters(p, wanted, float(spec.delay), spec)
        for mode in Mode:
            alpha = configurations(PROTOTYPE, mode, 1000, rng)
            s_dot = rng.uniform(-1, 1, (1000, mode.dof)) * 10.0 ** rng.uniform(-2.5, 0, (1000, 1))
            s_ddot = rng.uniform(-2, 2, (1000, mode.dof))
            reference = feedforward_torques(PROTOTYPE, model, mode, alpha, s_dot, s_ddot)
            _close(ffcpp.feedforward_torques(PROTOTYPE, model, mode, alpha, s_dot, s_ddot), reference, RELATIVE, 1e-12)


def test_paper_model_as_model_parameters_is_the_paper_model():
    rng = np.random.default_rng(6)
    alpha = np.zeros((50, 2))
    s_dot, s_ddot = rng.normal(size=(2, 50, 1))
    u = ffcpp.feedforward_torques(PROTOTYPE, PAPER_PARAMETERS, "2s", alpha, s_dot, s_ddot)
    assert np.array_equal(ffcpp.feedforward_torques(PROTOTYPE, ModelParameters(PAPER_PARAMETERS), "2s", alpha, s_dot,
                                                    s_ddot), u)


def test_cpp_model_refuses_a_bad_extension():
    core = ffcpp.extension()
    args = ((1.2, 0.8, 0.05, 0.1, 25.0), list(PAPER_PARAMETERS.to_vector()), 0.01, 0.02, 1e-6)
    with pytest.raises(ValueError, match="Stribeck velocities > 0"):
        core.Model(*args, stribeck=True, d_s=(1.0, 1.0, 1.0), w_s=(0.1, 0.0, 0.1))
    with pytest.raises(ValueError, match="invalid_model"):
        core.Model(*args, com_offset=True, x_c=math.nan)


def test_extension_meets_the_vectors(vectors):
    tol = vectors["tolerance"]
    models = _models(vectors)
    worst = 0.0
    for (index, label), group in pd.DataFrame(vectors["cases"]).groupby(["model", "mode"]):
        geom, params = models[index]
        alpha, s_dot, s_ddot = (np.array(group[k].tolist()) for k in ("alpha", "s_dot", "s_ddot"))
        u = ffcpp.feedforward_torques(geom, params, label, alpha, s_dot, s_ddot)
        worst = max(worst, _close(u, np.array(group["u"].tolist()), tol["relative"], tol["absolute"]))
        q_dot, q_ddot = ffcpp.joint_motion(geom, label, alpha, s_dot, s_ddot)
        _close(q_dot, np.array(group["q_dot"].tolist()), tol["relative"], tol["absolute"])
        _close(q_ddot, np.array(group["q_ddot"].tolist()), tol["relative"], tol["absolute"])
    assert worst < 1e-12  # round-off: both evaluate the same formulas


@pytest.mark.parametrize("index", range(11))
def test_both_engines_refuse_the_same_inputs(vectors, index):
    case = vectors["invalid"][index]
    geom, params = _models(vectors)[case["model"]]
    args = (geom, params, case["mode"], np.array([case["alpha"]]), np.array([case["s_dot"]]), np.array([case["s_ddot"]]))
    with pytest.raises(ValueError):
        feedforward_torques(*args)
    with pytest.raises(ValueError) as cpp_error:
        ffcpp.feedforward_torques(*args)
    message = str(cpp_error.value)
    if case["status"] == "non_finite_input" and not np.isfinite(case["alpha"]).all():
        return  # refused while checking the inputs in Python, before the C++ call
    assert case["status"] in message or "expected finite" in message, message


def test_random_configurations_agree_with_the_reference():
    """Beyond the stored vectors: many random configurations on the prototype, every mode."""
    from conftest import configurations

    rng = np.random.default_rng(5)
    for mode in Mode:
        alpha = configurations(PROTOTYPE, mode, 2000, rng)
        s_dot = rng.uniform(-1, 1, (2000, mode.dof))
        s_ddot = rng.uniform(-2, 2, (2000, mode.dof))
        reference = feedforward_torques(PROTOTYPE, PAPER_PARAMETERS, mode, alpha, s_dot, s_ddot)
        u = ffcpp.feedforward_torques(PROTOTYPE, PAPER_PARAMETERS, mode, alpha, s_dot, s_ddot)
        _close(u, reference, RELATIVE, 1e-12)
        q_ref = joint_motion(PROTOTYPE, mode, alpha, s_dot, s_ddot)
        for mine, ref in zip(ffcpp.joint_motion(PROTOTYPE, mode, alpha, s_dot, s_ddot), q_ref):
            _close(mine, ref, RELATIVE, 1e-12)


# --- the command line: --engine cpp equals --engine python ------------------------------------------------

def _trajectory_csv(path: Path) -> Path:
    """A trajectory file (docs/simulation.md CSV format) through modes 2, 1, 3, 1, 4, 1, sampled at 20 ms."""
    from agvdyn.trajectories import identification_sequence, lane_change, lateral_experiment

    segments = [*lane_change(speed=0.6, offset=0.8, length=5.0).segments, *lateral_experiment().segments,
                *identification_sequence().segments[6:9]]
    frames, t0 = [], 0.0
    for seg in segments:
        idx = np.arange(0, seg.n_samples, 10)
        frame = pd.DataFrame({"t": t0 + seg.t[idx], "mode": seg.mode.label, "alpha_l": seg.alpha[idx, 0],
                              "alpha_r": seg.alpha[idx, 1], "x_ch": 0.0, "y_ch": 0.0, "gamma_ch": 0.0})
        column = {Mode.CAR_LIKE: ("x_ch", 1), Mode.STRAIGHT: ("x_ch", 0), Mode.LATERAL: ("y_ch", 0),
                  Mode.ROTATION: ("gamma_ch", 0)}.get(seg.mode)
        if column is not None:
            frame[column[0]] = seg.s[idx, column[1]]
        frames.append(frame)
        t0 = float(frame["t"].iloc[-1]) + 0.02
    pd.concat(frames).to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def params_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cpp") / "params.yaml"
    write_parameters(path, ParameterFile(PAPER_PARAMETERS.replace(m_ch=910.0, d_cw=4.4), geometry=PROTOTYPE))
    return path


def _table(tmp_path: Path, experiment: str, params: Path, engine: str) -> pd.DataFrame:
    out = tmp_path / f"ff_{engine}.parquet"
    result = runner.invoke(app, ["feedforward", experiment, "--params", str(params), "--out", str(out),
                                 "--engine", engine])
    assert result.exit_code == 0, result.output
    return pd.read_parquet(out)


@pytest.mark.parametrize("experiment", ["identification", "lane-change", "lateral", "trajectory-file"])
def test_cli_engines_agree(tmp_path, params_file, experiment):
    if experiment == "trajectory-file":
        experiment = str(_trajectory_csv(tmp_path / "trajectory.csv"))
    python = _table(tmp_path, experiment, params_file, "python")
    cpp = _table(tmp_path, experiment, params_file, "cpp")
    pd.testing.assert_frame_equal(python.drop(columns=TORQUES), cpp.drop(columns=TORQUES))
    _close(cpp[TORQUES].to_numpy(), python[TORQUES].to_numpy(), RELATIVE, 1e-12)
    assert set(python["mode"]) >= ({"1", "2s", "4"} if "identification" in experiment else {"1"} if "lateral" in
                                   experiment else set())


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> Path:
    """A parameter file of a model beyond the paper (as `agvdyn identify --model` writes it)."""
    from agvdyn.model_file import write_model_parameters

    p = PAPER_PARAMETERS.replace(m_ch=910.0, d_cw=4.4)
    extra = {"d_sl": 1.3 * p.d_cl, "d_sr": 1.2 * p.d_cr, "d_sw": 1.4 * p.d_cw, "w_sl": 0.05, "w_sr": 0.05,
             "w_sw": 0.02, "x_c": 0.15, "y_c": -0.1}
    spec = ModelSpec(friction="stribeck", com_offset=True, delay=0.004)
    path = tmp_path_factory.mktemp("cpp_model") / "model.yaml"
    return write_model_parameters(path, ParameterFile(p, geometry=PROTOTYPE), spec, extra, {"d_sl": 0.2})


def test_cli_feedforward_uses_the_extended_model(tmp_path, params_file, model_file):
    """A model block changes the torques (the extended model's, equal in both engines) and nothing else."""
    from agvdyn.model_file import read_model_parameters
    from agvdyn.simulation import feedforward_table

    python = _table(tmp_path, "lane-change", model_file, "python")
    cpp = _table(tmp_path, "lane-change", model_file, "cpp")
    (tmp_path / "paper").mkdir()
    paper = _table(tmp_path / "paper", "lane-change", params_file, "python")
    _close(cpp[TORQUES].to_numpy(), python[TORQUES].to_numpy(), RELATIVE, 1e-12)
    pd.testing.assert_frame_equal(python.drop(columns=TORQUES), paper.drop(columns=TORQUES))
    assert np.abs(python[TORQUES].to_numpy() - paper[TORQUES].to_numpy()).max() > 0.05
    reference = feedforward_table("lane-change", read_model_parameters(model_file), PROTOTYPE)
    np.testing.assert_array_equal(python[TORQUES].to_numpy(), reference[TORQUES].to_numpy())


def test_cpp_reader_reads_a_model_block(model_file, tmp_path):
    from agvdyn.model_file import read_model_parameters

    python = read_model_parameters(model_file)
    cpp = ffcpp.read_parameter_file(model_file)
    assert cpp["model"] == {"friction": "stribeck", "delay_s": 0.004, "com_offset": True}
    assert cpp["extra"] == python.extra
    assert cpp["parameters"] == python.parameters.to_dict()
    plain = write_parameters(tmp_path / "plain.json", ParameterFile(PAPER_PARAMETERS))
    assert ffcpp.read_parameter_file(plain)["model"] is None and ffcpp.read_parameter_file(plain)["extra"] == {}
    bad = tmp_path / "bad.yaml"
    bad.write_text(model_file.read_text().replace("com_offset: true", "com_offset: maybe"))
    with pytest.raises(ValueError, match=r"bad\.yaml: model\.com_offset=maybe: expected true or false"):
        ffcpp.read_parameter_file(bad)
    missing = tmp_path / "missing.yaml"
    missing.write_text("\n".join(line for line in model_file.read_text().splitlines() if "x_c" not in line))
    with pytest.raises(ValueError, match=r"missing parameters \[x_c\]"):
        ffcpp.read_parameter_file(missing)


def test_cli_names_a_missing_extension(tmp_path, params_file, monkeypatch):
    def missing():
        raise ffcpp.CppEngineUnavailable("the C++ feed-forward engine is not available: test")

    monkeypatch.setattr(ffcpp, "extension", missing)
    result = runner.invoke(app, ["feedforward", "lateral", "--params", str(params_file), "--out",
                                 str(tmp_path / "ff.csv"), "--engine", "cpp"])
    assert result.exit_code == 2
    assert "error: the C++ feed-forward engine is not available" in result.stderr
    assert not (tmp_path / "ff.csv").exists()


def test_missing_module_is_a_named_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "agvdyn.ffcpp._core", None)  # import fails as if never built
    monkeypatch.delattr(ffcpp, "_core", raising=False)
    with pytest.raises(ffcpp.CppEngineUnavailable, match=r"pip install -e \.") as info:
        ffcpp.extension()
    assert isinstance(info.value, ImportError)
    assert not ffcpp.available()


def test_engine_choice_is_checked():
    from agvdyn.simulation import feedforward_table

    with pytest.raises(ValueError, match=r"engine='rust': expected one of \['python', 'cpp'\]"):
        feedforward_table("lateral", engine="rust")


def test_import_does_not_need_the_extension():
    code = ("import sys; import agvdyn, agvdyn.cli, agvdyn.simulation, agvdyn.ffcpp; "
            "assert 'agvdyn.ffcpp._core' not in sys.modules, 'imported eagerly'")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


# --- parameter files: the C++ reader reads what agvdyn writes ---------------------------------------------

def _identify_like(geometry: Geometry | None) -> ParameterFile:
    """A parameter file with the extras `agvdyn identify` writes (nested mappings, lists of mappings,
    long strings, None, empty collections)."""
    extra = {
        "condition_number_unscaled": 1234.5,
        "residual_rms": {"alpha_l": 0.12, "x_ch": 3.4},
        "n_rows": 12000,
        "estimator": "wls",
        "settings": {"cutoff": 40.0, "segments": None, "modes": ["1", "2s", "4"],
                     "note": "a long explanation " * 8 + "that PyYAML folds: with a colon # and a hash"},
        "sources": ["/data/run 1.parquet", "C:\\logs\\run #2.parquet", "it's quoted"],
        "torque_offsets": {},
        "slip_events": [{"t_start": 1.5, "t_end": 1.75, "wheels": ["fl", "rl"]}, {"t_start": 3.0, "t_end": 3.1,
                                                                                   "wheels": []}],
        "warnings": [],
    }
    params = Parameters.from_vector(PAPER_PARAMETERS.to_vector() * np.linspace(0.9, 1.1, 11) + 1e-13)
    return ParameterFile(params, dict(PAPER_STD), ("B_w",), 11.56, extra, geometry=geometry)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
@pytest.mark.parametrize("geometry", [PROTOTYPE, Geometry(l=1.0, b=0.7, a=-0.04, r=0.09, i_G=20.0, name="small: b"), None])
def test_cpp_reader_reads_what_agvdyn_writes(tmp_path, suffix, geometry):
    path = write_parameters(tmp_path / f"params{suffix}", _identify_like(geometry))
    python = read_parameters(path)
    cpp = ffcpp.read_parameter_file(path)
    assert cpp["parameters"] == python.parameters.to_dict()  # exact: both parse the shortest repr
    if geometry is None:
        assert cpp["platform"] is None
    else:
        assert cpp["platform"] == geometry.to_dict()


def test_cpp_reader_reads_the_flat_forms(tmp_path):
    flat = tmp_path / "flat.yaml"
    flat.write_text("# hand-written\n" + "".join(f"{k}: {v!r}\n" for k, v in PAPER_PARAMETERS.to_dict().items()))
    assert ffcpp.read_parameter_file(flat)["parameters"] == read_parameters(flat).parameters.to_dict()
    nested = tmp_path / "nested.json"
    nested.write_text(json.dumps({k: {"value": v} for k, v in PAPER_PARAMETERS.to_dict().items()}))
    assert ffcpp.read_parameter_file(nested)["parameters"] == PAPER_PARAMETERS.to_dict()


@pytest.mark.parametrize(("text", "message"), [
    ("parameters:\n  C_l: {value: 1.0}\n", "missing parameters [d_vl, d_cl"),
    ("parameters: [1, 2]\n", "'parameters' must be a mapping"),
    ("- 1\n", "expected a mapping at the top level"),
    ("{\"C_l\": ", "line 1"),
])
def test_cpp_reader_names_the_problem(tmp_path, text, message):
    path = tmp_path / ("bad.json" if text.startswith("{") else "bad.yaml")
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        ffcpp.read_parameter_file(path)
    assert str(info.value).startswith(str(path)) and message in str(info.value)


# --- the example control loop (built by `make cpp`, which `make test` runs first) -------------------------

CONTROL_LOOP = ROOT / "build" / "cpp" / "control_loop"


@pytest.mark.skipif(not CONTROL_LOOP.exists(), reason="build/cpp/control_loop not built (make cpp)")
@pytest.mark.parametrize("which", ["paper", "extended"])
def test_example_control_loop_reproduces_a_feedforward_table(tmp_path, params_file, model_file, which):
    """The example loop reads the parameter file's model (a model block: the extended model's torques)."""
    params_file = params_file if which == "paper" else model_file
    table = tmp_path / "lane.csv"
    result = runner.invoke(app, ["feedforward", "lane-change", "--params", str(params_file), "--out", str(table)])
    assert result.exit_code == 0, result.output
    run = subprocess.run([str(CONTROL_LOOP), "--free-run", "--check", "1e-4", str(params_file), str(table)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    out = pd.read_csv(pd.io.common.StringIO(run.stdout))
    reference = pd.read_csv(table)
    assert len(out) == len(reference)
    scale = np.abs(reference[TORQUES].to_numpy()).max()
    assert np.abs(out[TORQUES].to_numpy() - reference[TORQUES].to_numpy()).max() < 1e-4 * scale
    assert math.isclose(out["t"].iloc[-1], reference["t"].iloc[-1], abs_tol=1e-6)


# --- the payload tracker (agvdyn_ff::PayloadTracker against agvdyn.online.tracker) --------------------

TRACKER_VECTORS = ROOT / "cpp" / "tests" / "tracker_vectors.json"
TRACKER_OUTPUTS = ["m_ch", "C_ch", "m_ch_std", "C_ch_std", "nis"]


@pytest.fixture(scope="module")
def tracker_vectors() -> tuple[dict, pd.DataFrame]:
    data = json.loads(TRACKER_VECTORS.read_text(encoding="utf-8"))
    return data, pd.read_csv(TRACKER_VECTORS.parent / data["sequence"])


def _tracker_logs(table: pd.DataFrame) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    return [(g["kind"].to_numpy(np.int64), np.ascontiguousarray(g[["phi_m", "phi_C"]].to_numpy()),
             np.ascontiguousarray(g["z"].to_numpy())) for _, g in table.groupby("log", sort=True)]


def _relative(actual: np.ndarray, reference: np.ndarray) -> float:
    """Largest |x - ref| / max(|ref|, 1) (the vectors' rule); NaN exactly where the reference has NaN."""
    actual, reference = np.asarray(actual, dtype=float), np.asarray(reference, dtype=float)
    assert np.array_equal(np.isnan(actual), np.isnan(reference))
    ok = ~np.isnan(reference)
    return float(np.max(np.abs(actual[ok] - reference[ok]) / np.maximum(np.abs(reference[ok]), 1.0), initial=0.0))


def test_tracker_vectors_are_current(tracker_vectors):
    """The stored outputs are what the Python tracker computes now on the stored rows."""
    data, table = tracker_vectors
    generator = _load_generator()
    outputs, events, final = generator.run_python_tracker(_tracker_logs(table), data["dt"], data["nominal"],
                                                          data["nominal_std"])
    assert len(table) == sum(data["logs"]) >= 5000 and table["log"].nunique() == len(data["logs"])
    assert _relative(outputs[:, :5], table[TRACKER_OUTPUTS].to_numpy()) < 1e-12, \
        "regenerate with `.venv/bin/python cpp/tests/make_vectors.py --tracker`"
    assert np.array_equal(outputs[:, 5], table["event"].to_numpy())
    assert [(e["log"], e["sample"], e["start"], e["parameter"], e["sign"]) for e in events] == \
        [(e["log"], e["sample"], e["start"], e["parameter"], e["sign"]) for e in data["events"]]
    assert {(e["parameter"], e["sign"]) for e in events} == {(0, 1), (0, -1), (1, 1)}  # steps of both kinds and signs
    for key in ("theta", "P", "R", "n_rows", "g"):
        assert _relative(final[key], data["final"][key]) < 1e-12, key


def test_cpp_tracker_meets_the_vectors(tracker_vectors):
    """Every output of every sample, the events and the final state through the extension: 1e-9 relative."""
    data, table = tracker_vectors
    core = ffcpp.extension()
    tracker = core.PayloadTracker(tuple(data["nominal"]), tuple(data["nominal_std"]), data["dt"], data["settings"])
    parts, events = [], []
    for index, (kind, phi, z) in enumerate(_tracker_logs(table)):
        if index:
            tracker.begin_log()
        n = kind.size
        theta, var, nis, flag = np.zeros((n, 8)), np.zeros((n, 8)), np.zeros(n), np.zeros(n, dtype=np.int64)
        status, row, found = tracker.run(kind, phi, z, theta, var, nis, flag)
        assert row == -1, core.status_name(status)
        parts.append(np.column_stack([theta[:, :2], np.sqrt(var[:, :2]), nis, flag]))
        events += [(index, *e) for e in found]
    outputs = np.concatenate(parts)
    worst = _relative(outputs[:, :5], table[TRACKER_OUTPUTS].to_numpy())
    assert worst <= data["tolerance"]["relative"]
    assert np.array_equal(outputs[:, 5], table["event"].to_numpy())
    assert [(e[0], e[1], e[2], e[3], e[4]) for e in events] == \
        [(e["log"], e["sample"], e["start"], e["parameter"], e["sign"]) for e in data["events"]]
    for e, ref in zip(events, data["events"]):
        worst = max(worst, _relative(e[5:], [ref["before"], ref["before_var"], ref["after"], ref["after_var"]]))
    state = [np.zeros(8), np.zeros((8, 8)), np.zeros(4), np.zeros(20), np.zeros((2, 2)), np.zeros((2, 2, 8, 8)),
             np.zeros((2, 2, 8)), np.zeros((2, 2))]
    tracker.store_state(*state)
    for key, value in zip(("theta", "P", "R", "n_rows", "g", "start"), state[:5] + state[7:]):
        worst = max(worst, _relative(np.ravel(value), data["final"][key]))
    assert worst <= data["tolerance"]["relative"]
    print(f"tracker vectors: {len(table)} samples, {len(events)} events, largest relative deviation {worst:.3g}")


def test_cpp_tracker_single_updates_and_refusals():
    core = ffcpp.extension()
    tracker = core.PayloadTracker((842.0, 286.0), (1.0, 1.0), 0.002, {})
    status, estimate, std, nis, event = tracker.update(1, 0.3, 0.01, 0.3 * 842.0 + 0.01 * 286.0)
    assert status == 0 and event == 0 and nis < 1e-9 and std[0] < 842.0 * 0.02 + 1e-9
    status, estimate, _, nis, _ = tracker.update(9, 0.3, 0.0, 1.0)
    assert core.status_name(status) == "unknown_row_kind" and math.isnan(nis)
    assert core.status_name(tracker.update(5, math.nan, 0.2, 1.0)[0]) == "non_finite_input"
    with pytest.raises(ValueError, match="invalid_model"):
        core.PayloadTracker((842.0, 286.0), (1.0, 1.0), 0.002, {"threshold": -1.0})
    with pytest.raises(ValueError, match="unknown"):
        core.PayloadTracker((842.0, 286.0), (1.0, 1.0), 0.002, {"thresh": 1.0})


@pytest.fixture(scope="module")
def payload_drive(tmp_path_factory) -> Path:
    """60 s of `driving` (seed 1) with a pick-up of 200 kg at 40 s."""
    out = tmp_path_factory.mktemp("track") / "drive.parquet"
    result = runner.invoke(app, ["simulate", "driving", "--duration", "60", "--seed", "1", "--payload", "40:200",
                                 "--quiet", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


def test_track_engines_agree_on_a_payload_step(tmp_path, payload_drive):
    """`agvdyn track --engine cpp` against `--engine python`: every row of the table and every event."""
    params = ROOT / "cpp" / "tests" / "data" / "params.yaml"
    tables, summaries = {}, {}
    for engine in ("python", "cpp"):
        out = tmp_path / f"track_{engine}.parquet"
        result = runner.invoke(app, ["track", str(payload_drive), "--params", str(params), "--out", str(out), "--rate",
                                     "50", "--json", "--engine", engine])
        assert result.exit_code == 0, result.output
        tables[engine], summaries[engine] = pd.read_parquet(out), json.loads(result.stdout)
    python, cpp = tables["python"], tables["cpp"]
    assert len(python) == len(cpp) > 2000
    assert np.array_equal(python["event"], cpp["event"])
    columns = ["t", "m_ch", "m_ch_std", "C_ch", "C_ch_std", "nis"]
    assert _relative(cpp[columns].to_numpy(), python[columns].to_numpy()) <= RELATIVE
    events = summaries["python"]["events"]
    assert [e["parameter"] for e in events][:1] == ["m_ch"] and 40.0 < events[0]["t_detected"] < 60.0
    for e, f in zip(events, summaries["cpp"]["events"], strict=True):
        assert (e["parameter"], e["sign"], e["t_detected"], e["t_change_estimate"]) == \
               (f["parameter"], f["sign"], f["t_detected"], f["t_change_estimate"])
        assert math.isclose(e["after"]["value"], f["after"]["value"], rel_tol=RELATIVE)
    for name in ("m_ch", "C_ch"):
        assert math.isclose(summaries["python"]["final"][name]["value"], summaries["cpp"]["final"][name]["value"],
                            rel_tol=RELATIVE)
    assert abs(summaries["cpp"]["final"]["m_ch"]["value"] - (842.0684 + 200.0)) < 0.02 * 1042.0


def test_track_engine_cpp_names_a_missing_extension(tmp_path, payload_drive, monkeypatch):
    def missing():
        raise ffcpp.CppEngineUnavailable("the C++ feed-forward engine is not available: test")

    monkeypatch.setattr(ffcpp, "extension", missing)
    result = runner.invoke(app, ["track", str(payload_drive), "--params", str(ROOT / "cpp" / "tests" / "data" / "params.yaml"),
                                 "--out", str(tmp_path / "t.csv"), "--engine", "cpp"])
    assert result.exit_code == 2 and "not available" in result.stderr
    assert not (tmp_path / "t.csv").exists()
