"""Integrated autocorrelation time of the scores of a regression (Sokal's window), pooled over
recordings: the bandwidth of the HAC and the jackknife's block length (:mod:`.uncertainty`); and
the masked autocorrelation of a signal in pieces (the residuals' autocorrelation of the report),
both from one FFT autocovariance (:func:`autocovariance_sums`)."""
from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Iterator

import numpy as np

from agvdyn.identification._threads import ordered_map

__all__ = ["correlation_time", "autocovariance_sums", "masked_autocorrelation", "next_fast_length"]


def correlation_time(series: Iterable[np.ndarray | Callable[[], np.ndarray]], *, window: float = 5.0,
                     max_steps: int = 1 << 15, workers: int = 1, lengths: Iterable[int] | None = None) -> np.ndarray:
    """Integrated autocorrelation time (in steps) of each column, pooled over the recordings:
    ``1 + 2 sum_{l=1}^{M} rho(l)`` with Sokal's window (the smallest M >= window * tau(M)).

    Each recording contributes at most its first ``max_steps`` steps (65 s at 500 Hz), and
    recordings are pooled until ``4 * max_steps`` steps: the correlation times are tens to hundreds
    of steps, so this is plenty, and the cost does not grow with the length or number of the logs.
    ``workers``: threads taking the recordings' autocorrelations. ``series`` may hold callables
    that return a recording's array when called (in those threads); ``lengths`` then gives each
    one's number of rows.
    """
    def taken() -> Iterator[np.ndarray | Callable[[], np.ndarray]]:
        pooled = 0
        for x, n in zip(series, itertools.repeat(None) if lengths is None else lengths):
            if pooled >= 4 * max_steps:
                return
            pooled += min(x.shape[0] if n is None else n, max_steps)
            yield x

    acf = None
    for c in ordered_map(lambda x: autocovariance_sums((x() if callable(x) else x)[:max_steps]), taken(),
                         workers, "agvdyn-acf"):
        acf = c if acf is None else _pad_add(acf, c)
    p = acf.shape[1]
    rho = acf / np.where(acf[0] > 0, acf[0], 1.0)
    tau = np.ones(p)
    for j in range(p):
        cum = 1 + 2 * np.cumsum(rho[1:, j])
        m = np.arange(1, cum.size + 1)
        ok = np.flatnonzero(m >= window * cum)
        tau[j] = max(1.0, float(cum[ok[0]] if ok.size else cum[-1]))
    return tau


def autocovariance_sums(x: np.ndarray) -> np.ndarray:
    """Unnormalised autocovariance sums ``c[l, j] = sum_i x[i, j] x[i + l, j]``, lags ``0..n-1``,
    of the columns of ``x`` (n, p), by FFT in double precision zero-padded to at least ``2n`` (no
    wrap-around; the length :func:`next_fast_length`). The one autocorrelation of the package: the
    correlation time of the scores here, the residuals' autocorrelation of the report
    (:func:`masked_autocorrelation`). numpy's FFT (pocketfft, as scipy.fft's: the same values in double
    precision) without scipy.fft's import (~0.2 s of the start-up of every fitting command)."""
    n = x.shape[0]
    x = np.ascontiguousarray(x.T, dtype=np.float64)
    size = next_fast_length(2 * n)
    f = np.fft.rfft(x, size, axis=1)
    return np.fft.irfft(f * np.conj(f), size, axis=1)[:, :n].T.copy()


def next_fast_length(target: int) -> int:
    """The smallest ``2^a 3^b 5^c >= target`` (``scipy.fft.next_fast_len(target, real=True)``): a
    length whose real FFT factors into pocketfft's fast radices."""
    if target <= 6:
        return max(int(target), 1)
    best = 1 << (int(target) - 1).bit_length()  # the power of two at or above
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            p2 = 1 << max(0, (-(-int(target) // p35) - 1).bit_length())  # smallest power of 2 with p35 * p2 >= target
            best = min(best, p35 * p2)
            p35 *= 3
        p5 *= 5
    return best


def masked_autocorrelation(pieces: Iterable[tuple[np.ndarray, np.ndarray]], max_lag: int
                           ) -> tuple[np.ndarray, int]:
    """Autocorrelation ``rho(l)``, ``l = 0..max_lag``, of a series given in pieces ``(x, keep)``
    (the runs of one signal), where only pairs of kept samples count: the mean of the kept samples
    of all pieces is removed, and each lag's sum of products is divided by its number of kept pairs
    (masked sums), so that left-out samples neither add nor break correlation. Returns ``(rho,
    kept samples)``; NaN at lags without a pair."""
    pieces = [(np.asarray(x, dtype=float), np.asarray(k, dtype=bool)) for x, k in pieces]
    kept = sum(int(k.sum()) for _, k in pieces)
    mean = sum(float(x[k].sum()) for x, k in pieces) / kept if kept else 0.0
    num, pairs = np.zeros(max_lag + 1), np.zeros(max_lag + 1)
    for x, k in pieces:
        if not k.any():
            continue
        sums = autocovariance_sums(np.column_stack([np.where(k, x - mean, 0.0), k.astype(float)]))
        lags = min(max_lag + 1, x.size)
        num[:lags] += sums[:lags, 0]
        pairs[:lags] += np.rint(sums[:lags, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = np.where(pairs > 0, num / pairs, np.nan)
    return cov / cov[0], kept


def _pad_add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a + b`` padded to the longer, in place of one of them (both are fresh arrays of ours)."""
    if a.shape[0] < b.shape[0]:
        a, b = b, a
    a[: b.shape[0]] += b
    return a
