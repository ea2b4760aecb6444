"""One row pass per log (issue 27): ``identify``, ``inspect`` (pre-flight) and ``report`` each pass
every log once through the row pipeline (stretches found and filtered once) and share the result. The
report's row check (stop 31, :mod:`agvdyn.identification.row_check`) refits on other rows: one more pass
of each log, with its own settings."""
from __future__ import annotations

import pytest
from typer.testing import CliRunner

import agvdyn.identification.rows as rows_module
import agvdyn.identification.stretches as stretches_module
from agvdyn.cli import app
from agvdyn.identification import identify, load_logs, row_passes
from agvdyn.io import open_logs, write_log
from agvdyn.platform import PROTOTYPE
from agvdyn.preflight import preflight
from agvdyn.report import make_report
from model_logs import identification_frame, lane_change_frame

SHORT = {"steer_left": 6.0, "steer_right": 6.0, "straight": 6.0, "rotation": 6.0}


@pytest.fixture(scope="module")
def paths(tmp_path_factory):
    root = tmp_path_factory.mktemp("passes")
    out = []
    for k in range(2):
        path = root / f"ident{k}.parquet"
        write_log(path, identification_frame(SHORT, align=0.5 * k)[0],
                  {"platform": PROTOTYPE.to_dict()})
        out.append(path)
    lane = root / "lane.parquet"
    write_log(lane, lane_change_frame(8.0)[0])
    return out, lane


@pytest.fixture
def passes(monkeypatch):
    """Counts of the row passes (``log_rows`` finds a log's stretches once, at its start) and of
    every other search for stretches (``stretch_bounds`` anywhere), and of the stretches filtered."""
    counts = {"row passes": 0, "other stretch searches": 0, "filtered": 0}

    def counted(key, real):
        def wrapper(*args, **kwargs):
            counts[key] += 1
            return real(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(rows_module, "stretches_of", counted("row passes", rows_module.stretches_of))
    monkeypatch.setattr(stretches_module, "stretches_of", counted("other stretch searches",
                                                                  stretches_module.stretches_of))
    monkeypatch.setattr(rows_module, "filtered_stretch", counted("filtered", rows_module.filtered_stretch))
    return counts


def _stretches(logs) -> int:
    return sum(r.counts.stretches for r in row_passes(logs, PROTOTYPE))


def test_identify_passes_each_log_once(paths, passes):
    files, _ = paths
    logs = load_logs(files)
    stretches = _stretches(logs)
    passes.update({k: 0 for k in passes})
    identify(logs, PROTOTYPE, keep_blocks=False)
    assert passes == {"row passes": 2, "other stretch searches": 0, "filtered": stretches}
    passes.update({k: 0 for k in passes})
    identify(open_logs(files), keep_blocks=False)  # files read when used
    assert passes == {"row passes": 2, "other stretch searches": 0, "filtered": stretches}


def test_inspect_passes_each_log_once(paths, passes):
    files, _ = paths
    logs = load_logs(files)
    stretches = _stretches(logs)
    passes.update({k: 0 for k in passes})
    checked = preflight(logs, PROTOTYPE)
    assert passes == {"row passes": 2, "other stretch searches": 0, "filtered": stretches}
    assert [f.gaps for f in checked.files] == [r.cuts for r in row_passes(logs, PROTOTYPE)]
    passes.update({k: 0 for k in passes})
    result = CliRunner().invoke(app, ["inspect", *map(str, files), "--json"])
    assert result.exit_code == 0, result.output
    assert passes["row passes"] == 2 and passes["other stretch searches"] == 0


def test_report_passes_each_log_once(paths, passes, tmp_path):
    files, lane = paths
    logs, (val,) = load_logs(files), load_logs([lane])
    stretches = _stretches(logs)
    passes.update({k: 0 for k in passes})
    report = make_report(logs, PROTOTYPE)
    assert report.identification is not None and report.preflight is not None
    assert passes == {"row passes": 2 + 2, "other stretch searches": 0, "filtered": 2 * stretches}
    assert report.cuts == tuple(f.rows.gaps for f in report.preflight.files)
    passes.update({k: 0 for k in passes})
    make_report(logs, PROTOTYPE, validation_log=val)  # the validation log: its own pass, once
    assert passes["row passes"] == 3 + 2 and passes["other stretch searches"] == 0
    passes.update({k: 0 for k in passes})
    result = CliRunner().invoke(app, ["report", "--ident", str(files[0]), "--ident", str(files[1]),
                                      "--out", str(tmp_path / "r.html"), "--json"])
    assert result.exit_code == 0, result.output
    assert passes["row passes"] == 2 + 2 and passes["other stretch searches"] == 0
