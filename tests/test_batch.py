"""``agvdyn batch`` (issue 12): a manifest of several vehicles on Dask gives what ``identify`` gives alone on
each job; failed jobs are rows with their error; a separately started scheduler and worker on localhost;
``run_study`` on a scheduler."""
from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from agvdyn.batch import TABLE_COLUMNS, BatchJob, ManifestError, jobs_from_dict, read_manifest, run_batch
from agvdyn.cli import app
from agvdyn.identification import IdentificationSettings, identify, platform_for
from agvdyn.io import open_logs
from agvdyn.platform import PARAMETER_NAMES, PROTOTYPE, write_platform

pytest.importorskip("distributed")

WIDE = dataclasses.replace(PROTOTYPE, name="wide", l=1.44, b=0.88)
GOOD = ("agv-a", "agv-b", "wide")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """A manifest of five jobs: three vehicles on two platforms, a missing log, an unexcited log."""
    from agvdyn.simulation import simulate

    root = tmp_path_factory.mktemp("fleet")
    (root / "logs").mkdir()
    simulate("identification", platform=PROTOTYPE, seed=11).write(root / "logs" / "a.parquet")
    simulate("identification", platform=PROTOTYPE, seed=12).write(root / "logs" / "b.parquet")
    simulate("identification", platform=WIDE, seed=13).write(root / "logs" / "wide.parquet")
    simulate("lateral", platform=PROTOTYPE, seed=14).write(root / "logs" / "lateral.parquet")
    write_platform(root / "wide.yaml", WIDE)
    manifest = {
        "defaults": {"uncertainty": "hac"},
        "jobs": [
            {"name": "agv-a", "logs": ["logs/a.parquet"], "fix": {"B_w": 0.121}, "tags": {"fleet": "north"}},
            {"name": "agv-b", "logs": ["logs/b.parquet"], "estimator": "ols", "uncertainty": "classic",
             "tags": ["spare"]},
            {"name": "wide", "logs": ["logs/wide.parquet"], "platform": "wide.yaml", "fix": {"B_w": 0.13}},
            {"name": "missing", "logs": ["logs/nowhere.parquet"]},
            {"name": "unexcited", "logs": ["logs/lateral.parquet"]},
        ],
    }
    (root / "fleet.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False), encoding="utf-8")
    return root / "fleet.yaml"


def _alone(job: BatchJob):
    """identify() run alone on a job's inputs, the way a user would call it."""
    logs = open_logs(list(job.logs), mapping=job.mapping, platform=job.platform)
    return identify(logs, platform_for(logs, job.platform), fixed=job.fixed(),
                    settings=IdentificationSettings.from_flat(**{k: v for k, v in (("estimator", job.estimator),
                                                                         ("uncertainty", job.uncertainty)) if v}))


def _check_table(table: pd.DataFrame, jobs: list[BatchJob]) -> None:
    assert list(table.columns) == list(TABLE_COLUMNS)
    assert list(dict.fromkeys(table["job"])) == [j.name for j in jobs]  # the manifest's order
    for job in jobs:
        rows = table[table["job"] == job.name]
        if job.name not in GOOD:
            assert len(rows) == 1 and rows["error"].iloc[0] != ""
            continue
        assert (rows["error"] == "").all()
        assert list(rows["parameter"]) == list(PARAMETER_NAMES)
        ident = _alone(job)
        assert rows["rows"].iloc[0] == ident.n_rows
        assert rows["cond"].iloc[0] == pytest.approx(ident.condition_number, rel=1e-9)
        for _, row in rows.iterrows():
            assert row["value"] == pytest.approx(getattr(ident.parameters, row["parameter"]), rel=1e-9)
            assert row["fixed"] == (row["parameter"] in ident.fixed)
            if not row["fixed"]:
                assert row["std"] == pytest.approx(ident.std[row["parameter"]], rel=1e-9)
                assert row["ci_low"] < row["value"] < row["ci_high"]
    errors = dict(zip(table["job"], table["error"]))
    assert "nowhere.parquet" in errors["missing"]
    assert "UnidentifiableError" in errors["unexcited"] and "C_ch" in errors["unexcited"]


def test_manifest_paths_defaults_and_errors(fleet):
    jobs = read_manifest(fleet)
    assert [j.name for j in jobs] == ["agv-a", "agv-b", "wide", "missing", "unexcited"]
    assert jobs[0].logs == (str(fleet.parent / "logs" / "a.parquet"),)
    assert jobs[2].platform == str(fleet.parent / "wide.yaml") and jobs[2].fix == {"B_w": 0.13}
    assert jobs[0].uncertainty == "hac" and jobs[1].uncertainty == "classic"  # defaults, overridden per job
    assert jobs[0].tags == "fleet=north" and jobs[1].tags == "spare"
    assert jobs[3].fix is None and jobs[3].fixed() == {"B_w": 0.121}
    assert jobs_from_dict({"jobs": [{"logs": ["x.csv"], "fix": "none"}]})[0].fixed() == {}
    for bad, words in [({"jobs": []}, "non-empty"), ({"jobs": [{"logs": ["x"], "colour": 1}]}, "colour"),
                       ({"jobs": [{"name": "a", "logs": []}]}, "logs"),
                       ({"jobs": [{"name": "a", "logs": ["x"]}, {"name": "a", "logs": ["y"]}]}, "twice"),
                       ({"jobs": [{"logs": ["x"], "fix": {"B_w": "big"}}]}, "B_w"), ({"job": []}, "jobs")]:
        with pytest.raises(ManifestError, match=words):
            jobs_from_dict(bad)


def test_batch_on_a_local_cluster_equals_identify_alone(fleet, tmp_path):
    out = tmp_path / "results.parquet"
    res = CliRunner().invoke(app, ["batch", str(fleet), "--out", str(out), "--workers", "2", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    assert summary["jobs"] == 5 and summary["failed"] == 2 and set(summary["errors"]) == {"missing", "unexcited"}
    table = pd.read_parquet(out)
    _check_table(table, read_manifest(fleet))
    assert set(table.loc[table["job"] == "agv-b", "estimator"]) == {"ols"}
    assert set(table.loc[table["job"] == "agv-b", "uncertainty"]) == {"classic"}
    assert set(table.loc[table["job"] == "agv-a", "tags"]) == {"fleet=north"}


def test_batch_refuses_a_bad_manifest(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("jobs: [{name: a}]\n", encoding="utf-8")
    res = CliRunner().invoke(app, ["batch", str(bad), "--out", str(tmp_path / "r.parquet")])
    assert res.exit_code == 2 and "logs" in res.output
    assert not (tmp_path / "r.parquet").exists()


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory):
    """A ``dask scheduler`` and one ``dask worker`` (one thread) started as separate processes on 127.0.0.1."""
    from dask.distributed import Client

    folder = tmp_path_factory.mktemp("dask")
    info = folder / "scheduler.json"
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(info)],
                              cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not info.exists() or not info.read_text().strip():
            assert procs[0].poll() is None, "the dask scheduler exited"
            assert time.monotonic() < deadline, "the dask scheduler did not start in 60 s"
            time.sleep(0.1)
        time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--host",
                                       "127.0.0.1", "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                                      cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(1, timeout=60)
        yield address
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in reversed(procs):
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=20)


def test_batch_on_a_separate_scheduler_equals_identify_alone(fleet, scheduler, tmp_path):
    out = tmp_path / "results.parquet"
    res = CliRunner().invoke(app, ["batch", str(fleet), "--out", str(out), "--scheduler", scheduler, "--quiet"])
    assert res.exit_code == 0, res.output
    assert "3 of 5 jobs identified" in res.output
    _check_table(pd.read_parquet(out), read_manifest(fleet))


def test_run_batch_job_without_logs_is_a_row(scheduler):
    jobs = [BatchJob(name="empty", logs=())]
    table = run_batch(jobs, scheduler=scheduler)
    assert len(table) == 1 and table["error"].iloc[0].startswith("ValueError")


def test_montecarlo_on_a_scheduler_equals_the_process_pool(scheduler):
    from agvdyn.montecarlo import StudyCase, run_study

    cases = [StudyCase(i, 500 + i, "identification", {}, True, (("wls", "classic"),)) for i in range(2)]
    seen = []
    local = run_study(cases, workers=1)
    remote = run_study(cases, scheduler=scheduler, progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (2, 2)
    pd.testing.assert_frame_equal(local.drop(columns="seconds"), remote.drop(columns="seconds"), rtol=1e-12)
    assert (remote["error"] == "").all() and not remote["value"].isna().any()
    assert not math.isnan(remote["std"].iloc[0])


def test_montecarlo_command_takes_a_scheduler(scheduler, tmp_path):
    out = tmp_path / "study.parquet"
    res = CliRunner().invoke(app, ["montecarlo", "--out", str(out), "--runs", "2", "--ideal-plant",
                                   "--uncertainty", "classic", "--scheduler", scheduler])
    assert res.exit_code == 0, res.output
    table = pd.read_parquet(out)
    assert sorted(set(table["run"])) == [0, 1] and (table["error"] == "").all()
