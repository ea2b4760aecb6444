"""Sidecars kept as text until used (agvdyn.io.sidecar): one entry parsed on demand equals the
whole parse; texts that are not a plain block mapping are parsed when the log is read."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml

from agvdyn.io import LogError, read_log, write_log
from agvdyn.io.log import sidecar_value
from agvdyn.io.sidecar import LazySidecar, _entries, sidecar_text

PLAIN = """\
source: agvdyn.simulation
platform:
  name: prototype
  l: 1.2
  i_G: 25.0
# a comment
torque_lead: 0.5
tracking:
- segment: align
  t_start: 0.0
- segment: steer_left
  t_start: 1.0
empty: []
on: 3
when: 2024-01-02
"""


def test_one_entry_parsed_on_demand_equals_the_whole_parse(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(PLAIN)
    lazy = sidecar_text(path)
    assert isinstance(lazy, LazySidecar)
    full = yaml.safe_load(PLAIN)
    for key in ("source", "platform", "torque_lead", "tracking", "empty", "when"):
        assert lazy.get(key) == full[key]
    assert lazy.get("on") == full.get("on")  # a key YAML reads as the bool True: not "on"
    assert lazy.get("missing", 7) == 7
    assert lazy.parse() == full


@pytest.mark.parametrize("text", ['a: "x\n  y"\n', "a: &x 1\nb: *x\n", "a: {b: 1,\nc: 2}\n", "- 1\n- 2\n",
                                  "a: 1\na: 2\n", "--- \na: 1\n", "\ta: 1\n"])
def test_other_texts_are_not_split(text):
    assert _entries(text) is None


def test_a_log_reads_its_sidecar_on_demand(tmp_path):
    frame = pd.DataFrame({c: np.linspace(0, 0.1, 50) for c in
                          ("t", "alpha_l", "alpha_r", "beta_fl", "beta_rl", "beta_fr", "beta_rr",
                           "m_fl", "m_rl", "m_fr", "m_rr")})
    path = write_log(tmp_path / "run.parquet", frame, {"torque_lead": 0.5, "platform": {"l": 1.2}, "notes": ["a"]})
    log = read_log(path)
    assert sidecar_value(log, "torque_lead") == 0.5 and isinstance(log.__dict__["sidecar"], LazySidecar)
    assert log.sidecar == {"torque_lead": 0.5, "platform": {"l": 1.2}, "notes": ["a"]}
    assert isinstance(log.__dict__["sidecar"], dict)  # parsed once, kept
    (tmp_path / "run.parquet.yaml").write_text("[1, 2]\n")  # not a mapping: refused when read
    with pytest.raises(LogError, match="mapping at the top level"):
        read_log(path)


def test_an_entry_parsed_for_one_log_is_shared_but_not_mutable_through_another(tmp_path):
    """The parse of an entry's text is kept for the next sidecar with the same text; a mapping
    handed out is a copy, so changing it changes neither the other sidecar nor the next get."""
    one, two = tmp_path / "a.yaml", tmp_path / "b.yaml"
    one.write_text(PLAIN)
    two.write_text(PLAIN.replace("source: agvdyn.simulation", "source: another"))
    first, second = sidecar_text(one), sidecar_text(two)
    platform = first.get("platform")
    platform["l"] = -1.0
    platform["added"] = True
    assert second.get("platform") == yaml.safe_load(PLAIN)["platform"]
    assert first.get("platform") == yaml.safe_load(PLAIN)["platform"]
    assert first.get("source") == "agvdyn.simulation" and second.get("source") == "another"
