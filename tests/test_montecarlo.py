"""agvdyn montecarlo: the study table and its summary."""
from __future__ import annotations

import pandas as pd
import pytest
from typer.testing import CliRunner

from agvdyn.cli import app
from agvdyn.montecarlo import TABLE_COLUMNS, StudyCase, run_study_case, summarize

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics


def test_cli_writes_the_table_and_prints_the_summary(tmp_path):
    out = tmp_path / "mc.parquet"
    result = CliRunner().invoke(app, ["montecarlo", "--runs", "2", "--ideal-plant", "--estimator", "ols",
                                      "--estimator", "robust", "--uncertainty", "hac", "--workers", "1",
                                      "--out", str(out)])
    assert result.exit_code == 0, result.output
    table = pd.read_parquet(out)
    assert tuple(table.columns) == TABLE_COLUMNS
    assert set(table["estimator"]) == {"ols", "robust"} and set(table["run"]) == {0, 1}
    assert len(table) == 2 * 2 * 10  # runs x estimators x free parameters
    assert (table["error"] == "").all()
    assert ((table["value"] / table["truth"] - 1).abs() < 0.05).all()
    assert "m_ch" in result.output and "2 runs of identification (ideal plant)" in result.output
    summary = summarize(table)
    assert summary.loc[("ols", "hac", "m_ch"), "runs"] == 2
    assert 0.0 <= summary["coverage"].min() <= summary["coverage"].max() <= 1.0
    assert (summary["coverage_low"] <= summary["coverage"]).all() and (summary["coverage"] <= summary["coverage_high"]).all()


def test_a_failed_identification_is_a_row_with_its_error():
    case = StudyCase(0, 1, "lane-change", {}, True, (("ols", "classic"),))
    rows = run_study_case(case)
    assert rows and all(r["error"] for r in rows)  # the lane change alone is refused


def test_bad_options_are_named(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["montecarlo", "--estimator", "lasso", "--out", str(tmp_path / "x.parquet")])
    assert result.exit_code == 2 and "--estimator 'lasso'" in result.output
    result = runner.invoke(app, ["montecarlo", "--out", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "expected a .parquet file" in result.output
