"""The plan checked on the simulator (agvdyn.plan_check, ``agvdyn plan --verify``): the choice among the
candidates follows the measured score, the JSON reports it, and the planner stays below the simulation."""
from __future__ import annotations

import ast
import json
import math
from pathlib import Path
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

import agvdyn.plan_check as pc
from agvdyn.cli import app
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE
from agvdyn.trajectories import planner as pl

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics

P = PAPER_PARAMETERS
SRC = Path(pc.__file__).resolve().parent


@pytest.fixture(scope="module")
def two_candidates():
    """A quick plan in 3 m x 2 m that keeps its two starts as candidates."""
    return pl.plan(PROTOTYPE, "3x2", settings=pl.PlanSettings(starts=2, workers=1, max_iterations=60, candidates=2))


def _check(rank: int, ratio: float, cond: float = 6.0, share: float = 0.5, default_cond: float = 17.0):
    r = {n: ratio for n in pl.FREE}
    return pc.CandidateCheck(rank, 10 + rank, float(rank), cond, r, cond, r, r, {n: 1.0 for n in pl.FREE}, share,
                             pc.measured_score(r, cond, default_cond, share))


def test_score_is_the_worst_share_of_the_bars():
    r = {n: 0.5 for n in pl.FREE}
    assert pc.measured_score({**r, "m_ch": 0.97}, 7.0, 17.0, 0.4) == pytest.approx(0.97)
    assert pc.measured_score(r, 9.9, 20.0, 0.4) == pytest.approx(1.1)  # bar 9
    assert pc.measured_score(r, 6.6, 10.0, 0.4) == pytest.approx(1.1)  # bar 0.6 x 10
    assert pc.measured_score(r, 6.0, 17.0, 1.3) == pytest.approx(1.3)  # an error beyond 5 % / 3 std


def test_choose_takes_the_smaller_measured_score_then_the_better_prediction():
    assert pc.choose([_check(0, 0.95), _check(1, 0.80)]) == 1
    assert pc.choose([_check(0, 0.80), _check(1, 0.95)]) == 0
    assert pc.choose([_check(0, 0.80, cond=9.5), _check(1, 0.95)]) == 1  # cond above the bar outweighs
    assert pc.choose([_check(0, 0.90), _check(1, 0.90)]) == 0
    # the best predicted start is kept unless another is better by more than prefer_predicted
    assert pc.choose([_check(0, 0.84), _check(1, 0.80)]) == 0
    assert pc.choose([_check(0, 0.84), _check(1, 0.80)], prefer_predicted=0.0) == 1
    assert pc.choose([_check(0, 0.86), _check(1, 0.80), _check(2, 0.78)]) == 2


def _fake_runs(monkeypatch, plan_, stds):
    """``_run`` replaced: the default sequence gives std 1 for all ten, candidate k gives ``stds[k]``."""
    by_traj = {id(c.trajectory): s for c, s in zip(plan_.candidates, stds)}

    def run(trajectory, plan, seed, settings, engine="ours"):
        std = 1.0 if trajectory is plan_.reference_trajectory else by_traj[id(trajectory)]
        values = P if trajectory is plan_.reference_trajectory else P.replace(C_r=0.97 * P.C_r)
        return SimpleNamespace(std={n: std for n in pl.FREE}, parameters=values,
                               condition_number=17.0 if std == 1.0 else 6.0)

    monkeypatch.setattr(pc, "_run", run)


@pytest.mark.parametrize("stds,expected", [((0.9, 0.7), 1), ((0.7, 0.9), 0), ((0.72, 0.7), 0)])
def test_verify_plan_keeps_the_candidate_measured_best(monkeypatch, two_candidates, stds, expected):
    _fake_runs(monkeypatch, two_candidates, stds)
    chosen, verification = pc.verify_plan(two_candidates, (7, 8))
    assert verification.chosen == expected and chosen.chosen == expected
    assert chosen.trajectory is two_candidates.candidates[expected].trajectory
    assert chosen.evaluation is two_candidates.candidates[expected].evaluation
    check = verification.chosen_check
    assert check.ratio["m_ch"] == pytest.approx(stds[expected])
    assert check.error["C_r"] == pytest.approx(3.0) and check.score == pytest.approx(stds[expected])
    assert verification.seeds == (7, 8) and verification.default_cond == 17.0
    data = chosen.to_dict()
    assert data["chosen_start"] == two_candidates.candidates[expected].start
    assert verification.warnings == ()  # every bar met (ratios < 1, cond 6 < 9, C_r 3 % off)


def test_verify_plan_on_the_simulator(two_candidates):
    """Real runs (one seed): both candidates measured, the chosen one has the smallest score, and the
    measured cond follows the predicted one (within 5 %)."""
    chosen, verification = pc.verify_plan(two_candidates, 1)
    assert verification.seeds == (pc.VERIFY_SEED0,)
    assert len(verification.candidates) == 2
    scores = [c.score for c in verification.candidates]
    assert verification.chosen_check.score == min(scores)
    for c in verification.candidates:
        assert c.failure is None and set(c.ratio) == set(pl.FREE)
        assert c.cond == pytest.approx(c.predicted_cond, rel=0.05)
        assert c.score >= c.cond / min(9, 0.6 * verification.default_cond) - 1e-12
    data = verification.to_dict()
    json.dumps(data)
    assert {"seeds", "chosen_rank", "chosen_start", "score", "cond_bar", "default", "candidates",
            "warnings"} <= set(data)
    cand = data["candidates"][0]
    assert set(cand["measured"]) >= {"cond", "ratio", "ratio_max", "worst_ratio", "max_error_percent"}
    assert set(cand["predicted"]) >= {"cond", "ratio"}
    with pytest.raises(IndexError):
        two_candidates.choose(2)


def test_cli_plan_verify_json(tmp_path):
    out = tmp_path / "plan.yaml"
    res = CliRunner().invoke(app, ["plan", "--floor", "3x2", "--starts", "2", "--verify", "1", "--out", str(out),
                                   "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    ver = data["verification"]
    assert ver["seeds"] == [pc.VERIFY_SEED0] and len(ver["candidates"]) == 2
    assert ver["chosen_start"] == data["chosen_start"]
    chosen = next(c for c in ver["candidates"] if c["rank"] == ver["chosen_rank"])
    assert data["cond"] == pytest.approx(chosen["predicted"]["cond"])
    assert math.isfinite(chosen["measured"]["cond"]) and data["default"]["cond"] > data["cond"]
    off = CliRunner().invoke(app, ["plan", "--floor", "3x2", "--starts", "1", "--verify", "0", "--out", str(out),
                                   "--json"])
    assert off.exit_code == 0, off.output
    assert json.loads(off.output)["verification"] is None


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_layering_the_planner_does_not_import_the_check_nor_the_simulation():
    higher = ("agvdyn.simulation", "agvdyn.identification", "agvdyn.io", "agvdyn.signals", "agvdyn.validation",
              "agvdyn.plan_check", "agvdyn.report", "agvdyn.cli")
    files = sorted((SRC / "trajectories").rglob("*.py"))
    assert len(files) > 5
    for path in files:
        bad = {m for m in _imports(path) if m.startswith(higher)}
        assert not bad, f"{path.relative_to(SRC)} imports {bad}"
    check = {m for m in _imports(SRC / "plan_check.py") if m.startswith("agvdyn.")}
    assert not {m for m in check if m.startswith(("agvdyn.report", "agvdyn.cli"))}


def test_verification_warns_when_the_chosen_plan_misses_a_bar(monkeypatch, two_candidates):
    _fake_runs(monkeypatch, two_candidates, (1.2, 1.3))
    _, verification = pc.verify_plan(two_candidates, (7,))
    assert verification.chosen == 0
    assert len(verification.warnings) == 2 and "m_ch (1.20x)" in verification.warnings[0]
    assert "--seed" in verification.warnings[-1]


def test_a_refused_candidate_is_a_failure_not_an_error(monkeypatch, two_candidates):
    _fake_runs(monkeypatch, two_candidates, (0.7, 0.9))
    fake = pc._run

    def run(trajectory, plan, seed, settings, engine="ours"):
        if trajectory is two_candidates.candidates[0].trajectory and seed == 8:
            raise ValueError("weakly excited data: C_r")
        return fake(trajectory, plan, seed, settings)

    monkeypatch.setattr(pc, "_run", run)
    chosen, verification = pc.verify_plan(two_candidates, (7, 8))
    failed = verification.candidates[0]
    assert failed.failure == "ValueError: weakly excited data: C_r" and math.isinf(failed.score)
    assert verification.chosen == 1 and chosen.trajectory is two_candidates.candidates[1].trajectory
    data = json.loads(json.dumps(verification.to_dict(), allow_nan=False))  # strict JSON: null, not Infinity
    assert data["candidates"][0]["score"] is None and data["candidates"][0]["measured"]["cond"] is None


def test_plant_variants_scale_the_tyres_of_the_given_plant():
    from agvdyn.simulation import PlantSettings

    base = PlantSettings()
    soft, stiff = pc.plant_variant(base, "soft"), pc.plant_variant(base, "stiff")
    assert (soft.slip_stiffness_long, soft.slip_stiffness_lat, soft.mu) == pytest.approx((2.5e4, 2.0e4, 0.7))
    assert (stiff.slip_stiffness_long, stiff.slip_stiffness_lat, stiff.mu) == pytest.approx((1.6e5, 1.2e5, 1.0))
    assert pc.plant_variant(base, "breakaway").breakaway_ratio == 1.3
    assert pc.plant_variant(base, "radii").wheel_radius_error != base.wheel_radius_error
    assert pc.plant_variant(base, pc.NOMINAL) is base
    other = PlantSettings(slip_stiffness_long=8e4)
    assert pc.plant_variant(other, "soft").slip_stiffness_long == pytest.approx(5e4)  # relative to the given plant
    with pytest.raises(ValueError, match="plant variant"):
        pc.plant_variant(base, "icy")


def test_the_score_pools_the_plants(monkeypatch, two_candidates):
    """Candidate 0 is better on the nominal plant and worse on soft tyres: without the variants it is kept,
    with them candidate 1 (pooled mean ratio 0.8 against (0.6 + 1.4) / 2 = 1.0)."""
    plan_ = two_candidates
    cand = [c.trajectory for c in plan_.candidates]

    def run(trajectory, plan, seed, settings, engine="ours"):
        soft = settings.plant.slip_stiffness_long < 4e4
        if trajectory is plan_.reference_trajectory:
            std = 1.0
        elif trajectory is cand[0]:
            std = 1.4 if soft else 0.6
        else:
            std = 0.8
        return SimpleNamespace(std={n: std for n in pl.FREE}, parameters=P, condition_number=17.0 if std == 1 else 6.0)

    monkeypatch.setattr(pc, "_run", run)
    _, alone = pc.verify_plan(plan_, (7,))
    assert alone.chosen == 0 and alone.plants == ()
    chosen, both = pc.verify_plan(plan_, (7,), plants=("soft",), plant_seeds=(9,))
    assert both.chosen == 1 and chosen.trajectory is cand[1]
    first = both.candidates[0]
    assert first.ratio["m_ch"] == pytest.approx(0.6)  # the nominal plant's figures
    assert first.plants["soft"]["score"] == pytest.approx(1.4) and first.score == pytest.approx(1.0)
    data = json.loads(json.dumps(both.to_dict(), allow_nan=False))
    assert data["plants"] == [pc.NOMINAL, "soft"] and data["plant_seeds"] == [9]
    assert data["candidates"][0]["plants"]["soft"]["score"] == pytest.approx(1.4)
    # a chosen candidate above 1 on a variant is named in the warnings
    monkeypatch.setattr(pc, "_run", lambda t, p, s, st, engine="ours": run(cand[0] if t is cand[1] else t, p, s, st))
    _, worse = pc.verify_plan(plan_, (7,), plants=("soft",), plant_seeds=(9,))
    assert any("soft plant variant" in w for w in worse.warnings)


def test_verify_plan_in_two_processes_gives_the_same_figures(two_candidates):
    """Real runs on one seed, the nominal plant and stiff tyres: two worker processes give what one does."""
    kw = dict(plants=("stiff",), plant_seeds=(pc.VERIFY_SEED0,), candidates=1)
    _, one = pc.verify_plan(two_candidates, 1, **kw)
    _, two = pc.verify_plan(two_candidates, 1, workers=2, **kw)
    assert one.chosen == two.chosen
    for a, b in zip(one.candidates, two.candidates):
        assert a.score == pytest.approx(b.score, rel=1e-9) and a.ratio == pytest.approx(b.ratio, rel=1e-9)
        assert a.plants["stiff"]["cond"] == pytest.approx(b.plants["stiff"]["cond"], rel=1e-9)
    assert two.chosen_check.plants["stiff"]["cond"] == pytest.approx(two.chosen_check.cond, rel=0.05)


def test_cli_plan_rejects_an_unknown_plant_variant(tmp_path):
    res = CliRunner().invoke(app, ["plan", "--floor", "3x2", "--verify-plants", "soft,icy", "--out",
                                   str(tmp_path / "p.yaml")])
    assert res.exit_code == 2 and "icy" in res.output


def test_search_presets_and_their_errors():
    assert pl.PlanSettings.search("wide") == pl.PlanSettings()  # the default since stop 23
    wide = pl.PlanSettings.search("wide", seed=3)
    assert (wide.starts, wide.peak_exponent, wide.explore_iterations, wide.refine, wide.seed) == (12, 64.0, 80, 4, 3)
    narrow = pl.PlanSettings.search("narrow", seed=3)
    assert (narrow.starts, narrow.peak_exponent, narrow.explore_iterations, narrow.refine) == (6, math.inf, 300, 2)
    with pytest.raises(ValueError, match="search 'deep'"):
        pl.PlanSettings.search("deep")


def test_combine_keeps_the_first_plans_best_start_and_labels_the_searches(two_candidates):
    other = pl.plan(PROTOTYPE, "3x2", settings=pl.PlanSettings.search("wide", starts=1, workers=1, max_iterations=20,
                                                                        candidates=1))
    both = pl.combine([two_candidates, other], ["narrow", "wide"])
    assert [c.rank for c in both.candidates] == [0, 1, 2]
    assert [c.search for c in both.candidates] == ["narrow", "narrow", "wide"]
    assert both.chosen == 0 and both.trajectory is two_candidates.candidates[0].trajectory
    assert both.candidates[2].trajectory is other.candidates[0].trajectory
    assert len(both.starts) == 3 and {s["search"] for s in both.starts} == {"narrow", "wide"}
    assert both.to_dict()["chosen_search"] == "narrow" and both.choose(2).to_dict()["chosen_search"] == "wide"
    with pytest.raises(ValueError, match="one search name per plan"):
        pl.combine([two_candidates, other], ["narrow"])
    small_floor = pl.plan(PROTOTYPE, "3.2x2", settings=pl.PlanSettings(starts=1, workers=1, max_iterations=5))
    with pytest.raises(ValueError, match="differ"):
        pl.combine([two_candidates, small_floor], ["a", "b"])


def test_cli_plan_rejects_an_unknown_search(tmp_path):
    res = CliRunner().invoke(app, ["plan", "--floor", "3x2", "--search", "narrow,deep", "--out", str(tmp_path / "p.yaml")])
    assert res.exit_code == 2 and "deep" in res.output


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_forked_workers_run_one_blas_thread_and_the_count_is_restored():
    """The planner's and the check's worker processes run with one BLAS thread each (two processes with all
    cores' BLAS threads each took 1.7-2x the wall time); the parent's count is restored afterwards."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    from threadpoolctl import threadpool_limits

    from agvdyn.trajectories.planner.optimize import one_blas_thread

    with threadpool_limits(limits=2, user_api="blas"):  # a parent with more than one BLAS thread
        before = _blas_threads()
        assert before and max(before) == 2  # numpy's BLAS is found: the test can fail
        with one_blas_thread():
            with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("fork")) as ex:
                assert set(ex.submit(_blas_threads).result()) == {1}
        assert _blas_threads() == before
        with one_blas_thread(False):
            assert _blas_threads() == before


def test_verify_plan_on_mujoco(two_candidates):
    """``engine="mujoco"`` (``agvdyn plan --verify-engine mujoco``): the candidates and the default sequence
    simulated on the MuJoCo plant and identified (one seed); the engine is reported; the plant variants,
    which are our plant's, are refused with it."""
    pytest.importorskip("mujoco")
    chosen, verification = pc.verify_plan(two_candidates, 1, engine="mujoco")
    assert verification.engine == "mujoco" and verification.to_dict()["engine"] == "mujoco"
    assert len(verification.candidates) == 2
    for c in verification.candidates:
        assert c.failure is None and set(c.ratio) == set(pl.FREE)
        assert c.cond == pytest.approx(c.predicted_cond, rel=0.1)
    assert verification.chosen_check.score == min(c.score for c in verification.candidates)
    assert all("MuJoCo" in w for w in verification.warnings[:-1])
    with pytest.raises(ValueError, match="our plant's"):
        pc.verify_plan(two_candidates, 1, engine="mujoco", plants=("soft",))
    with pytest.raises(ValueError, match="engine='gazebo'"):
        pc.verify_plan(two_candidates, 1, engine="gazebo")


def test_cli_plan_verify_engine_is_checked(tmp_path):
    out = str(tmp_path / "p.yaml")
    res = CliRunner().invoke(app, ["plan", "--floor", "3x2", "--verify-engine", "gazebo", "--out", out])
    assert res.exit_code == 2 and "ours or mujoco" in res.output
    res = CliRunner().invoke(app, ["plan", "--floor", "3x2", "--verify-engine", "mujoco", "--verify-plants", "soft",
                                   "--out", out])
    assert res.exit_code == 2 and "our plant's" in res.output
