"""Identification by Gram blocks (pseudo-rows) against the row-stacked reference, the row store,
long logs read in pieces, unexcited parameters with unbounded intervals, torque alignment."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings as hsettings, strategies as st

import agvdyn.io.chunks as chunks
from agvdyn.identification import IdentificationSettings, UnidentifiableError, fit_blocks, identify
from agvdyn.identification.normal import RegressionData, RowIndex, RowStatistics, RowStore, RecordingRows
from agvdyn.identification.rows import log_rows
from agvdyn.identification.stretches import align_torque
from agvdyn.io import Log, open_logs, read_log, write_log
from agvdyn.platform import PARAMETER_NAMES, PROTOTYPE
from model_logs import identification_frame

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics

SHORT = {"steer_left": 10.0, "steer_right": 10.0, "straight": 10.0, "rotation": 10.0}


@pytest.fixture(scope="module")
def noisy_log():
    """A model log with torque noise, so that residuals and uncertainties are not round-off."""
    frame, _ = identification_frame(SHORT, align=0.5)
    rng = np.random.default_rng(3)
    for c in [c for c in frame.columns if c.startswith("M_")]:
        frame[c] = frame[c] + 0.02 * rng.standard_normal(len(frame))
    return Log.from_frame(frame)


def _vector(ident) -> np.ndarray:
    return np.array([ident.parameters.to_vector()[PARAMETER_NAMES.index(n)] for n in ident.std])


@pytest.mark.parametrize("estimator", ["ols", "wls", "bounded"])
@pytest.mark.parametrize("uncertainty", ["classic", "hac", "jackknife", "bootstrap"])
def test_gram_blocks_give_the_stacked_answer(noisy_log, estimator, uncertainty):
    settings = IdentificationSettings.from_flat(estimator=estimator, uncertainty=uncertainty, bootstrap_replicates=40)
    blocks = log_rows(noisy_log, PROTOTYPE, settings).blocks
    fast = fit_blocks(blocks, PROTOTYPE, settings=settings)
    ref = fit_blocks(blocks, PROTOTYPE, settings=settings, stacked=True)
    assert fast.n_rows == ref.n_rows
    np.testing.assert_allclose(_vector(fast), _vector(ref), rtol=1e-9)
    # the sandwich covariances sum scores of near-cancelling residuals (round-off shows at ~1e-8, up to
    # 1.4e-7 for a parameter near its bound);
    # the bootstrap re-solves normal equations per replicate (round-off times cond^2)
    np.testing.assert_allclose([fast.std[n] for n in ref.std], [ref.std[n] for n in ref.std],
                               rtol={"classic": 1e-9, "hac": 1e-6, "jackknife": 1e-6, "bootstrap": 1e-4}[uncertainty])
    np.testing.assert_allclose(fast.condition_number, ref.condition_number, rtol=1e-9)
    assert fast.residual_rms.keys() == ref.residual_rms.keys()
    # a residual of this near-exact fit (|r| ~ 1e-3 |y|) moves ~3e3x more than the parameters it comes from
    np.testing.assert_allclose(list(fast.residual_rms.values()), list(ref.residual_rms.values()), rtol=1e-8)


def test_identify_streams_logs_and_keeps_no_blocks_when_asked(noisy_log):
    kept = identify([noisy_log, noisy_log])
    lean = identify([noisy_log, noisy_log], keep_blocks=False)
    assert lean.blocks == () and len(kept.blocks) > 0
    np.testing.assert_allclose(_vector(lean), _vector(kept), rtol=1e-12)
    assert lean.n_samples == 2 * len(noisy_log.t) and lean.rows.samples == lean.n_samples


def test_threads_give_the_same_answer_and_the_default_follows_the_environment(noisy_log, monkeypatch):
    """Logs reduced and jackknife blocks summed in threads are merged in order: the same numbers, to
    the last bit; the default thread count is the cores (at most 2) unless AGVDYN_THREADS says."""
    from agvdyn.identification._threads import default_workers

    logs = [noisy_log] * 3
    one, three = identify(logs, keep_blocks=False, workers=1), identify(logs, keep_blocks=False, workers=3)
    assert np.array_equal(_vector(one), _vector(three))
    assert one.std == three.std and one.uncertainty == three.uncertainty
    monkeypatch.setenv("AGVDYN_THREADS", "3")
    assert default_workers() == 3
    monkeypatch.setenv("AGVDYN_THREADS", "0")
    with pytest.raises(ValueError, match="AGVDYN_THREADS='0'"):
        default_workers()
    monkeypatch.delenv("AGVDYN_THREADS")
    assert 1 <= default_workers() <= 2


def test_row_store_spills_to_disk_and_reads_back_the_same_rows():
    rng = np.random.default_rng(0)
    store = RowStore(budget=0)  # everything to disk
    recs = [RecordingRows(rng.standard_normal((50, 3)), rng.standard_normal(50), np.zeros(50, np.int8),
                          np.arange(50), np.zeros(50, np.int16)) for _ in range(3)]
    for r in recs:
        store.add(r)
    assert store.spilled == 3
    folder = store._folder
    for a, b in zip(store, recs):
        np.testing.assert_array_equal(a.A, b.A)
        np.testing.assert_array_equal(a.step, b.step)
    store.close()
    assert not folder.exists()


@hsettings(max_examples=25, deadline=None)
@given(st.integers(min_value=20, max_value=200), st.integers(min_value=2, max_value=5), st.integers(0, 2**31 - 1))
def test_pseudo_rows_have_the_normal_equations_of_the_rows(m, width, seed):
    """P^T P = [A y]^T [A y] for the pseudo-rows of random rows (and zero columns stay zero)."""
    rng = np.random.default_rng(seed)
    rows = rng.standard_normal((m, width + 1))
    rows[:, 0] = 0.0
    stats = RowStatistics(width)
    stats.add(("s", "x"), rows[: m // 2])
    stats.add(("s", "x"), rows[m // 2:])
    P = stats.factor(("s", "x"))
    np.testing.assert_allclose(P.T @ P, rows.T @ rows, atol=1e-9 * np.abs(rows.T @ rows).max())
    assert np.all(P[:, 0] == 0.0)


def test_from_rows_keeps_the_estimators_row_order():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((40, 2))
    index = RowIndex(np.zeros(40, np.int64), ("g",), np.tile([1, 0], 20), np.arange(40) // 2)
    data = RegressionData.from_rows(A, A @ [1.0, 2.0], index)
    assert data.row_order is not None and sorted(data.row_order) == list(range(40))
    assert sum(r.y.size for r in data.recordings()) == 40


@pytest.fixture(scope="module")
def long_log(tmp_path_factory):
    """Three copies of a model log joined in time as one continuous recording."""
    frame, _ = identification_frame(SHORT, align=0.5)
    dt = float(np.median(np.diff(frame["t"])))
    span = frame["t"].iloc[-1] - frame["t"].iloc[0] + dt
    parts = []
    for k in range(3):
        g = frame.copy()
        g["t"] = g["t"] + k * span
        for c in [c for c in g.columns if c.startswith("beta")]:
            g[c] = g[c] - g[c].iloc[0] + (parts[-1][c].iloc[-1] if parts else g[c].iloc[0])
        parts.append(g)
    path = tmp_path_factory.mktemp("long") / "long.parquet"
    write_log(path, pd.concat(parts, ignore_index=True), {"platform": PROTOTYPE.to_dict()})
    return path


def test_a_long_log_in_pieces_gives_the_whole_logs_answer(long_log, monkeypatch):
    settings = IdentificationSettings.from_flat(slip_threshold=math.inf)
    whole = identify(read_log(long_log), settings=settings, keep_blocks=False)
    monkeypatch.setattr(chunks, "CHUNK_ROWS", 7000)
    assert chunks.is_long_log(long_log)
    pieces = list(chunks.log_pieces(long_log))
    assert sum(core.stop - core.start for _, core in pieces) == len(whole.rows.to_dict() and read_log(long_log).t)
    chunked = identify(open_logs(long_log), settings=settings, keep_blocks=False)
    assert chunked.n_samples == whole.n_samples and chunked.n_rows == whole.n_rows
    assert chunked.sources == (str(long_log),)
    np.testing.assert_allclose(_vector(chunked), _vector(whole), rtol=1e-9)
    # the jackknife's blocks are cut at multiples of the block length of the log's sample index: with
    # the same bandwidth, pieces and whole log have the same blocks and the same std
    fixed_band = settings.replace(bandwidth=600)
    whole, chunked = identify(read_log(long_log), settings=fixed_band), identify(open_logs(long_log), settings=fixed_band)
    assert chunked.uncertainty.blocks == whole.uncertainty.blocks
    np.testing.assert_allclose([chunked.std[n] for n in whole.std], [whole.std[n] for n in whole.std], rtol=1e-6)
    # HAC windows are cut where the pieces meet: the std may move a little, never much
    hac = settings.replace(uncertainty="hac")
    whole, chunked = identify(read_log(long_log), settings=hac), identify(open_logs(long_log), settings=hac)
    np.testing.assert_allclose([chunked.std[n] for n in whole.std], [whole.std[n] for n in whole.std], rtol=0.05)


def test_a_long_csv_log_streams_in_pieces_too(long_log, tmp_path, monkeypatch):
    settings = IdentificationSettings.from_flat(slip_threshold=math.inf)
    log = read_log(long_log)
    csv = write_log(tmp_path / "long.csv", log.frame, log.sidecar)
    whole = identify(read_log(csv), settings=settings, keep_blocks=False)
    monkeypatch.setattr(chunks, "CHUNK_ROWS", 7000)
    assert chunks.is_long_log(csv, rows=100)
    monkeypatch.setattr(chunks, "is_long_log", lambda path, rows=None: True)
    chunked = identify(open_logs(csv), settings=settings, keep_blocks=False)
    assert chunked.n_samples == whole.n_samples
    np.testing.assert_allclose(_vector(chunked), _vector(whole), rtol=1e-9)


def test_bounded_on_one_segment_reports_what_it_cannot_identify(tmp_path):
    frame, _ = identification_frame({"steer_left": 10.0})
    log = Log.from_frame(frame)
    with pytest.raises(UnidentifiableError):
        identify(log)  # wls: refused, naming them
    ident = identify(log, settings=IdentificationSettings.from_flat(estimator="bounded"))
    values = ident.parameters.to_dict()
    assert all(values[n] >= 0 for n in PARAMETER_NAMES)
    unexcited = {n for n, s in ident.std.items() if not math.isfinite(s)}
    assert {"C_r", "d_vr", "d_cr", "m_ch", "C_ch"} <= unexcited and "C_l" not in unexcited
    assert all(any(n in w for w in ident.warnings) for n in unexcited)
    data = json.loads(json.dumps(ident.to_json_dict()))
    assert data["parameters"]["m_ch"]["std"] is None and data["parameters"]["m_ch"]["ci95"] == [None, None]
    assert data["parameters"]["m_ch"]["identified"] is False and data["parameters"]["C_l"]["identified"] is True
    assert abs(values["C_l"] / 0.3342 - 1) < 1e-3
    written = ident.write(tmp_path / "p.yaml")
    assert written.exists()
    report = identify(log, settings=IdentificationSettings.from_flat(unexcited="report"))
    assert math.isinf(report.std["m_ch"]) and report.parameters.m_ch == 0.0


def test_torque_alignment_of_a_zero_order_hold_drive():
    m = np.arange(6.0)[:, None] * np.ones((1, 4))
    out = align_torque(m, 0.5)
    np.testing.assert_allclose(out[1:, 0], np.arange(1, 6) - 0.5)
    assert out[0, 0] == 0.0 and align_torque(m, 0.0) is m
    with pytest.raises(ValueError, match="torque_lead"):
        IdentificationSettings.from_flat(torque_lead=2.0)


def test_the_kept_thread_pool_runs_nested_maps_inline_and_is_new_after_a_fork():
    """ordered_map's threads are kept between calls; a job that maps again runs that map itself (a
    full pool cannot deadlock), results stay in order, and a forked child starts its own pool."""
    import os

    from agvdyn.identification import _threads

    import threading

    def inner(k):  # runs in a pool thread: its own map must run there, not wait on the full pool
        outer = threading.get_ident()
        return list(_threads.ordered_map(lambda j: (k, j, threading.get_ident() == outer), range(3), 2))

    got = []
    runner = threading.Thread(target=lambda: got.append(list(_threads.ordered_map(inner, range(6), 2))), daemon=True)
    runner.start()
    runner.join(60)
    assert not runner.is_alive(), "nested ordered_map deadlocked on the kept pool"
    assert got == [[[(k, j, True) for j in range(3)] for k in range(6)]]
    pool = _threads._pool(2)
    assert list(_threads.ordered_map(lambda x: x * x, range(10), 2)) == [x * x for x in range(10)]
    assert _threads._pool(2) is pool
    if not hasattr(os, "fork"):
        return
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # pragma: no cover - the child
        try:
            ok = _threads._pool(2) is not pool and list(_threads.ordered_map(abs, [-1, -2, -3], 2)) == [1, 2, 3]
            os.write(write, b"1" if ok else b"0")
        finally:
            os._exit(0)
    os.close(write)
    assert os.read(read, 1) == b"1"
    os.waitpid(child, 0)
    os.close(read)
