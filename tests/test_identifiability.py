"""Table 1 of the paper and the regrouping kappa of sec. 6.3."""
from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from agvdyn.cli import app
from agvdyn.identifiability import base_parameters, base_parameters_of, random_mode_regressor, table1
from agvdyn.kinematics import Mode
from agvdyn.platform import PARAMETER_NAMES, PROTOTYPE


def test_table1_ranks_and_groups():
    rows = {tuple(m.label for m in r.modes): r for r in table1(PROTOTYPE)}
    assert rows[("2",)].rank == 11
    for key in [("3",), ("4",), ("2s",)]:
        assert rows[key].rank == 3
    for key in [("3",), ("2s",)]:
        assert set(rows[key].identifiable) == {"m_ch", "d_vw", "d_cw"}
        assert rows[key].groups["m_ch"]["B_w"] == pytest.approx(4 / PROTOTYPE.r**2)
    rot = rows[("4",)]
    group = next(g for g in rot.groups.values() if "C_ch" in g)
    assert {"C_l", "C_r", "C_ch"} <= set(group)
    combined = rows[("1", "2s", "4")]
    assert combined.rank == 10
    assert combined.dependent == ("B_w",)
    assert set(combined.identifiable) == set(PARAMETER_NAMES) - {"B_w"}


def test_mode1_coulomb_separation_depends_on_tolerance():
    """d_cw differs from d_cl, d_cr only through the tanh scale a/r: a tolerance above it merges it."""
    row = base_parameters(PROTOTYPE, "1")
    assert row.rank == 7 and "d_cw" in row.identifiable
    separation = row.relative_r["d_cw"]
    assert 1e-3 < separation < 0.2
    merged = base_parameters(PROTOTYPE, "1", tolerance=2 * separation)
    assert merged.rank == 6 and "d_cw" in merged.dependent


def test_kappa_reproduces_dependent_columns():
    Y = random_mode_regressor(PROTOTYPE, Mode.ROTATION, 200, np.random.default_rng(0))
    row = base_parameters_of(Y)
    # p_B = p_1 + kappa p_2: the regressor of the base parameters predicts the same torques
    p = np.random.default_rng(1).uniform(0.1, 10, len(PARAMETER_NAMES))
    pB = np.array([sum(c * p[PARAMETER_NAMES.index(m)] for m, c in row.groups[name].items()) for name in row.identifiable])
    Y1 = Y[:, [PARAMETER_NAMES.index(n) for n in row.identifiable]]
    assert np.allclose(Y1 @ pB, Y @ p, rtol=1e-9)


def test_cli_table_and_json():
    runner = CliRunner()
    result = runner.invoke(app, ["identifiability"])
    assert result.exit_code == 0, result.output
    assert "{1, 2s, 4}" in result.output and "10" in result.output
    result = runner.invoke(app, ["identifiability", "--modes", "1,2s,4", "--json"])
    data = json.loads(result.output)
    assert data["rank"] == 10 and "B_w" not in data["identifiable"] and "groups" in data
    bad = runner.invoke(app, ["identifiability", "--modes", "1,9"])
    assert bad.exit_code == 2 and "unknown motion mode" in bad.output
