"""Platform and parameter files: validation and round trips."""
from __future__ import annotations

import numpy as np
import pytest

from agvdyn.platform import (
    PAPER_PARAMETERS,
    PAPER_STD,
    PROTOTYPE,
    Geometry,
    ParameterFile,
    Parameters,
    PlatformFileError,
    read_parameters,
    read_platform,
    write_parameters,
    write_platform,
)


def test_table2_values():
    p = PAPER_PARAMETERS.to_vector()
    assert p.shape == (11,)
    assert PAPER_PARAMETERS.m_ch == 842.0684 and PAPER_PARAMETERS.B_w == 0.121
    assert Parameters.from_vector(p) == PAPER_PARAMETERS
    assert set(PAPER_STD) == set(PAPER_PARAMETERS.to_dict()) - {"B_w"}


def test_platform_round_trip(tmp_path):
    path = write_platform(tmp_path / "p.yaml", PROTOTYPE)
    assert read_platform(path) == PROTOTYPE


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_parameter_round_trip(tmp_path, suffix):
    content = ParameterFile(PAPER_PARAMETERS, std=dict(PAPER_STD), fixed=("B_w",), condition_number=11.56)
    back = read_parameters(write_parameters(tmp_path / f"params{suffix}", content))
    assert back.parameters == PAPER_PARAMETERS and back.std == PAPER_STD
    assert back.fixed == ("B_w",) and back.condition_number == 11.56


@pytest.mark.parametrize(
    "text, message",
    [
        ("l: 1.2\nb: 0.8\na: 0.05\nr: 0.1\n", "missing keys \\['i_G'\\]"),
        ("l: 1.2\nb: -0.8\na: 0.05\nr: 0.1\ni_G: 25\n", "b=-0.8"),
        ("l: 1.2\nb: 0.8\na: 0.05\nr: zero\ni_G: 25\n", "r='zero'"),
        ("- 1\n- 2\n", "mapping"),
    ],
)
def test_bad_platform_files(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    before = path.read_bytes()
    with pytest.raises(PlatformFileError, match=message) as info:
        read_platform(path)
    assert str(path) in str(info.value)
    assert path.read_bytes() == before


def test_geometry_invariants():
    with pytest.raises(ValueError, match="l=0"):
        Geometry(l=0, b=1, a=0.1, r=0.1, i_G=10)
    with pytest.raises(ValueError, match="a=0.6"):
        Geometry(l=1, b=1, a=0.6, r=0.1, i_G=10)
    with pytest.raises(ValueError, match="finite"):
        Parameters(*([1.0] * 10 + [np.nan]))
