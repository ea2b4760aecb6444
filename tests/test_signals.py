"""Properties of the zero-phase filters, derivative schemes, stiction masks and mode assignment."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from agvdyn.signals import (
    FilterSettings,
    filtered_derivatives,
    lowpass,
    modes_from_segments,
    parallel_filter,
    runs,
    stiction_mask,
    time_derivative,
    uniform_sample_time,
)

DT = 2e-3


def test_filter_settings_reject_bad_values():
    with pytest.raises(ValueError, match="cutoff"):
        FilterSettings(cutoff=-1.0)
    with pytest.raises(ValueError, match="order"):
        FilterSettings(order=0)
    with pytest.raises(ValueError, match="Nyquist"):
        FilterSettings(cutoff=2000.0).sos(DT)


def test_poles_stable():
    sos = FilterSettings().sos(DT)
    for section in sos:
        assert np.all(np.abs(np.roots(section[3:])) < 1.0)


@pytest.mark.parametrize("omega", [2.0, 10.0, 25.0])
def test_zero_lag_and_butterworth_gain(omega):
    """A sine passes with no phase shift and gain 1/(1+(w/wg)^(2n)) (forward-backward)."""
    s = FilterSettings(cutoff=40.0, order=4)
    t = np.arange(0.0, 20.0, DT)
    y = lowpass(np.sin(omega * t), DT, s)
    inner = slice(len(t) // 4, -len(t) // 4)
    # least-squares fit of y = A sin + B cos on the interior: B is the phase component
    basis = np.column_stack([np.sin(omega * t), np.cos(omega * t)])[inner]
    (a, b), *_ = np.linalg.lstsq(basis, y[inner], rcond=None)
    # digital Butterworth: prewarped frequency of the bilinear transform
    warp = np.tan(omega * DT / 2) / np.tan(s.cutoff * DT / 2)
    assert abs(b) < 1e-6
    assert a == pytest.approx(1.0 / (1.0 + warp ** (2 * s.order)), rel=1e-4)


def test_gain_at_cutoff_is_one_half():
    s = FilterSettings(cutoff=40.0, order=2)
    t = np.arange(0.0, 30.0, DT)
    y = lowpass(np.sin(40.0 * t), DT, s)
    inner = slice(len(t) // 4, -len(t) // 4)
    assert np.sqrt(2 * np.mean(y[inner] ** 2)) == pytest.approx(0.5, rel=2e-3)


def test_axis_argument():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((3, 500))
    assert np.allclose(lowpass(x, DT, axis=1), lowpass(x.T, DT, axis=0).T)
    xf, xd, xdd = filtered_derivatives(x, DT, axis=-1)
    assert xf.shape == xd.shape == xdd.shape == x.shape


@given(c=st.floats(-1e3, 1e3), k=st.floats(-10, 10))
@settings(max_examples=30, deadline=None)
def test_lowpass_keeps_constants_and_is_linear(c, k):
    t = np.arange(0.0, 2.0, DT)
    x = np.sin(3 * t)
    assert np.allclose(lowpass(np.full_like(t, c), DT), c, atol=1e-9 * max(1.0, abs(c)))
    assert np.allclose(lowpass(k * x + c, DT), k * lowpass(x, DT) + c, atol=1e-9 * max(1.0, abs(c), abs(k)))


def test_central_derivative_converges_at_second_order():
    errors = []
    steps = [1e-2, 5e-3, 2.5e-3]
    for dt in steps:
        t = np.arange(0.0, 2.0 + dt / 2, dt)
        d = time_derivative(np.sin(3 * t), dt)
        errors.append(np.max(np.abs(d - 3 * np.cos(3 * t))))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 1.9) and np.all(orders < 2.2)


def test_filtered_derivatives_match_analytic_below_cutoff():
    """Slow signal: filtered value and derivatives equal the analytic ones (no lag, no bias)."""
    t = np.arange(0.0, 10.0, DT)
    w = 1.5
    x = 0.3 * np.sin(w * t) + 0.1 * np.cos(2 * w * t)
    xd = 0.3 * w * np.cos(w * t) - 0.2 * w * np.sin(2 * w * t)
    xdd = -0.3 * w**2 * np.sin(w * t) - 0.4 * w**2 * np.cos(2 * w * t)
    f, d, dd = filtered_derivatives(x, DT)
    inner = slice(1000, -1000)
    assert np.max(np.abs(f - x)[inner]) < 1e-6
    assert np.max(np.abs(d - xd)[inner]) < 1e-5
    assert np.max(np.abs(dd - xdd)[inner]) < 1e-4


def test_derivative_of_filtered_equals_filtered_derivative():
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 6.0, DT)
    x = np.cumsum(rng.standard_normal(t.size)) * 1e-3 + np.sin(t)
    _, d, _ = filtered_derivatives(x, DT)
    d2 = lowpass(time_derivative(x, DT), DT)
    inner = slice(500, -500)
    scale = np.max(np.abs(d2[inner]))
    assert np.max(np.abs(d - d2)[inner]) < 1e-3 * scale


def test_filter_removes_noise_above_cutoff():
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 20.0, DT)
    noise = rng.standard_normal(t.size)
    y = lowpass(noise, DT)
    # white noise: the variance passed is the noise-equivalent bandwidth over Nyquist (~ 40/1571)
    assert np.var(y) < 0.05 * np.var(noise)


def test_too_short_signal_is_refused():
    with pytest.raises(ValueError, match="too short"):
        lowpass(np.zeros(10), DT)


def test_parallel_filter_runs_and_zero_columns():
    t = np.arange(0.0, 4.0, DT)
    x = np.zeros((t.size, 2, 2))
    x[:, 0, 0] = np.sign(np.sin(t))
    x[:1000, 1, 1] = 1.0
    y = parallel_filter(x, DT, bounds=[(0, 1000), (1000, t.size)], axis=0)
    assert np.all(y[:, 0, 1] == 0) and np.all(y[:, 1, 0] == 0)
    # the constant block stays exactly its value (zero columns of the second run untouched)
    assert np.allclose(y[:1000, 1, 1], 1.0) and np.all(y[1000:, 1, 1] == 0.0)
    # parallel filter of a column equals lowpass of that column within each run
    assert np.allclose(y[1000:, 0, 0], lowpass(x[1000:, 0, 0], DT))


def test_runs():
    assert runs(np.array(["a", "a", "b", "b", "b", "a"])) == [(0, 2), (2, 5), (5, 6)]
    assert runs(np.array([])) == []


def test_stiction_mask():
    s = np.array([[0.0, 1.0], [-0.2, 0.01], [0.05, -0.049]])
    assert stiction_mask(s, 0.05).tolist() == [[False, True], [True, False], [True, False]]
    with pytest.raises(ValueError):
        stiction_mask(s, -1.0)


def test_modes_from_segments():
    seg = np.array(["steer_left", "align", "straight", "rotation", "lateral", "lane_change", "steer_right"])
    assert modes_from_segments(seg).tolist() == ["1", "", "2s", "4", "3", "2", "1"]
    with pytest.raises(ValueError, match=r"'jump'.*row 2"):
        modes_from_segments(np.array(["straight", "straight", "jump"]))


def test_uniform_sample_time():
    t = np.arange(100) * DT
    assert uniform_sample_time(t) == pytest.approx(DT)
    t[50] += 0.5 * DT
    with pytest.raises(ValueError, match="row 50"):
        uniform_sample_time(t)


@given(mask=st.lists(st.booleans(), min_size=1, max_size=60), guard=st.integers(0, 5))
@settings(max_examples=60, deadline=None)
def test_guarded_mask_matches_definition(mask, guard):
    """Kept iff no dropped row and no end of the array within `guard` samples."""
    from agvdyn.signals import guarded_mask

    keep = np.array(mask)
    n = keep.size
    expected = [all(0 <= j < n and keep[j] for j in range(i - guard, i + guard + 1)) for i in range(n)]
    assert guarded_mask(keep, guard).tolist() == expected
    two = np.stack([keep, keep], axis=1)
    assert guarded_mask(two, guard).tolist() == [[e, e] for e in expected]


@pytest.mark.parametrize("order", [1, 2, 3, 4, 6])
def test_compiled_zero_phase_filter_equals_scipy(order):
    """The compiled forward-backward filter (two-section fast path for orders 3-4, the general
    cascade otherwise) gives scipy.signal.sosfiltfilt's result on many channels at once."""
    from scipy import signal

    from agvdyn._zero_phase import sosfiltfilt_columns

    s = FilterSettings(cutoff=40.0, order=order)
    sos = s.sos(DT)
    x = np.random.default_rng(order).standard_normal((3000, 7)).cumsum(axis=0)
    got = sosfiltfilt_columns(sos, signal.sosfilt_zi(sos), x, s.padlen(DT))
    want = signal.sosfiltfilt(sos, x, axis=0)
    assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_filter_designs_kept_on_disk_equal_scipy_and_spare_its_import(tmp_path):
    """A Butterworth design is scipy's (the same bits) whether computed or read back from the disk
    cache; a corrupt or unwritable cache is ignored; with a warm cache scipy.signal is not imported."""
    import json
    import os
    import subprocess
    import sys

    from scipy import signal

    code = ("import sys, json\nfrom agvdyn._filter_cache import butterworth_lowpass\n"
            "sos, zi = butterworth_lowpass(4, 0.025464790894703253)\n"
            "print(json.dumps([sos.tolist(), zi.tolist(), 'scipy.signal' in sys.modules]))")
    env = {**os.environ, "AGVDYN_CACHE_DIR": str(tmp_path / "cache")}

    def run(environment):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environment,
                             timeout=120, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    want_sos = signal.butter(4, 0.025464790894703253, btype="low", output="sos")
    want_zi = signal.sosfilt_zi(want_sos)
    cold, warm = run(env), run(env)
    for sos, zi, _ in (cold, warm):
        assert np.array_equal(np.array(sos), want_sos) and np.array_equal(np.array(zi), want_zi)
    assert cold[2] and not warm[2]  # designed once, then read back without scipy.signal
    (cache,) = (tmp_path / "cache").iterdir()
    cache.write_text("{not json", encoding="utf-8")
    sos, zi, _ = run(env)
    assert np.array_equal(np.array(sos), want_sos)
    blocked = tmp_path / "file"  # a file where the folder should be: nothing can be written
    blocked.write_text("", encoding="utf-8")
    sos, zi, _ = run({**os.environ, "AGVDYN_CACHE_DIR": str(blocked / "cache")})
    assert np.array_equal(np.array(zi), want_zi)
    work = tmp_path / "work"  # a relative cache folder is never written into the working directory
    work.mkdir()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True,
                         cwd=work, env={**os.environ, "AGVDYN_CACHE_DIR": "relative"})
    assert np.array_equal(np.array(json.loads(out.stdout.strip().splitlines()[-1])[0]), want_sos)
    assert list(work.iterdir()) == []
