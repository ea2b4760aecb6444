"""Quantiles of the normal and of Student's t distribution, for the intervals of the estimates
(:meth:`agvdyn.identification.uncertainty.Uncertainty.quantile`: ``value +- q std``), without
scipy.special's import (~0.1 s of every fitting command's start-up).

* :func:`normal_quantile`: Wichura's algorithm AS 241 (PPND16, Appl. Statist. 37, 1988): within a
  few ulps (< 1e-15 relative) of ``scipy.special.ndtri``.
* :func:`student_t_quantile`: ``t`` with ``F_nu(t) = p`` for real degrees of freedom ``nu`` (the
  jackknife's Satterthwaite degrees of freedom are not integers): Hill's approximation (Algorithm
  396, Comm. ACM 13, 1970) refined by Halley's method on the distribution function, which is taken
  from the series or the continued fraction of the incomplete beta function
  ``I_y(1/2, nu/2)`` / ``I_x(nu/2, 1/2)`` (``y = t^2 / (nu + t^2) = 1 - x``), whichever converges
  fast, each written as the density ``f(t)`` times a series of positive terms or a continued fraction.
  Closed forms for ``nu = 1, 2``; for ``nu >= 1e4`` Fisher's expansion about the normal quantile
  (``nu = inf``: the normal quantile). Checked against
  ``scipy.special.stdtrit`` (Boost) to 1e-12 relative over ``nu`` in [1, 1e7] and ``p`` in
  [0.5, 0.9999] (tests/test_scipy_free_numerics.py; within ~1e-14 of 40-digit values where spot-checked,
  and accurate near ``p = 1/2``, where stdtrit's error is ~1e-16 absolute).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["normal_quantile", "student_t_quantile"]

#: AS 241's rational approximations: (numerator, denominator) coefficients, highest power first.
_CENTRAL = ((2509.0809287301226727, 33430.575583588128105, 67265.770927008700853, 45921.953931549871457,
             13731.693765509461125, 1971.5909503065514427, 133.14166789178437745, 3.387132872796366608),
            (5226.495278852545925, 28729.085735721942674, 39307.89580009271061, 21213.794301586595867,
             5394.1960214247511077, 687.1870074920579083, 42.313330701600911252, 1.0))
_NEAR = ((7.7454501427834140764e-4, 0.0227238449892691845833, 0.24178072517745061177, 1.27045825245236838258,
          3.64784832476320460504, 5.7694972214606914055, 4.6303378461565452959, 1.42343711074968357734),
         (1.05075007164441684324e-9, 5.475938084995344946e-4, 0.0151986665636164571966, 0.14810397642748007459,
          0.68976733498510000455, 1.6763848301838038494, 2.05319162663775882187, 1.0))
_FAR = ((2.01033439929228813265e-7, 2.71155556874348757815e-5, 0.0012426609473880784386, 0.026532189526576123093,
         0.29656057182850489123, 1.7848265399172913358, 5.4637849111641143699, 6.6579046435011037772),
        (2.04426310338993978564e-15, 1.4215117583164458887e-7, 1.8463183175100546818e-5, 7.868691311456132591e-4,
         0.0148753612908506148525, 0.13692988092273580531, 0.59983220655588793769, 1.0))
#: Stirling series of log Gamma(z): B_2k / (2k (2k - 1)) for k = 1..5 (next term < 1e-16 at z >= 16).
_STIRLING = (1.0 / 12, -1.0 / 360, 1.0 / 1260, -1.0 / 1680, 1.0 / 1188)
_STIRLING_FROM = 16.0
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
#: Longest series / continued fraction (converged long before inside the checked range).
_MAX_TERMS = 20000
#: From these degrees of freedom on, the quantile is the normal one's expansion (:func:`_expansion`).
_EXPANSION_FROM = 1e4


def _rational(coefficients: tuple[tuple[float, ...], tuple[float, ...]], r: np.ndarray) -> np.ndarray:
    num, den = (np.polyval(np.array(c), r) for c in coefficients)
    return num / den


def normal_quantile(p: np.ndarray | float) -> np.ndarray:
    """Standard normal quantile ``Phi^-1(p)`` (AS 241); ``-inf``/``inf`` at 0/1, NaN outside [0, 1]."""
    p = np.asarray(p, dtype=float)
    q = p - 0.5
    with np.errstate(divide="ignore", invalid="ignore"):
        central = q * _rational(_CENTRAL, 0.180625 - q * q)
        r = np.sqrt(-np.log(np.minimum(p, 1.0 - p)))
        tail = np.where(r <= 5.0, _rational(_NEAR, r - 1.6), _rational(_FAR, r - 5.0))
    out = np.where(np.abs(q) <= 0.425, central, np.copysign(np.where(np.isinf(r), np.inf, tail), q))
    return np.where((p >= 0) & (p <= 1), out, np.nan)


def _log_gamma_ratio(a: np.ndarray) -> np.ndarray:
    """``log(Gamma(a + 1/2) / Gamma(a)) - log(a) / 2`` (small: ``-1/(8a) + ...``) for ``a > 0``, to
    ~1e-16 absolute: Stirling's series at ``z = a + k >= 16``, brought down by ``Gamma(z + 1) = z Gamma(z)``."""
    k = np.maximum(np.ceil(_STIRLING_FROM - a), 0.0)
    z = a + k
    out = (z * np.log1p(0.5 / z) - 0.5) + np.where(k > 0, 0.5 * np.log(z / a), 0.0)
    for j, c in enumerate(_STIRLING):
        out += c * ((z + 0.5) ** -(2 * j + 1) - z ** -(2 * j + 1))
    for j in range(int(k.max(initial=0.0))):  # log(Gamma(z + 1/2) / Gamma(z)) = the same at z + 1 - log1p(1 / (2 z))
        below = j < k
        out -= np.where(below, np.log1p(0.5 / np.where(below, a + j, 1.0)), 0.0)
    return out


def _density(nu: np.ndarray, t: np.ndarray, log_ratio: np.ndarray) -> np.ndarray:
    """Student's t density ``Gamma((nu + 1) / 2) / (sqrt(nu pi) Gamma(nu / 2)) (1 + t^2 / nu)^(-(nu + 1) / 2)``
    (``log_ratio``: :func:`_log_gamma_ratio` of ``nu / 2``)."""
    return np.exp(log_ratio - _HALF_LOG_2PI - 0.5 * (nu + 1.0) * np.log1p(t * t / nu))


def _central_sum(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``S = sum_n (a + 1/2)_n / (3/2)_n y^n``: ``F(t) - 1/2 = t f(t) S`` (the series of ``I_y(1/2, a) / 2``)."""
    total, term = np.ones_like(y), np.ones_like(y)
    for n in range(_MAX_TERMS):
        term = term * ((a + 0.5 + n) / (1.5 + n) * y)
        total = total + term
        if n % 8 == 7 and not np.any(term > 1e-17 * total):
            break
    return total


def _tail_fraction(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The continued fraction ``h`` of ``I_x(a, 1/2)`` (modified Lentz, Numerical Recipes' betacf):
    ``1 - F(t) = t f(t) h / nu``; fast where ``x < (a + 1) / (a + 5/2)``."""
    tiny, b = 1e-300, 0.5
    c = np.ones_like(x)
    d = 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / np.where(np.abs(d) < tiny, tiny, d)
    h = d
    going = np.ones(x.shape, dtype=bool)  # a converged fraction stays as it is (further factors 1 +- ulp would drift)
    for m in range(1, _MAX_TERMS):
        for coefficient in (m * (b - m) * x / ((a - 1.0 + 2 * m) * (a + 2 * m)),
                            -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 1.0 + 2 * m))):
            d = 1.0 + coefficient * d
            d = 1.0 / np.where(np.abs(d) < tiny, tiny, d)
            c = 1.0 + coefficient / c
            c = np.where(np.abs(c) < tiny, tiny, c)
            h = np.where(going, h * (d * c), h)
        going &= np.abs(d * c - 1.0) > 3e-16
        if not going.any():
            break
    return h


def _residual(nu: np.ndarray, t: np.ndarray, centre: np.ndarray, tail: np.ndarray, log_ratio: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """``(F(t) - p, f(t))`` for ``t >= 0``, ``p = 1/2 + centre = 1 - tail``: from the series where
    ``y <= min(1/2, 4.5 / (a + 5/2))`` (it converges fast there), else from the tail's continued
    fraction, then well inside its fast region ``y > 1.5 / (a + 5/2)`` (about ``t^2 > 9`` for large ``nu``;
    nearer, for large ``a``, its ``x`` close to 1 loses digits: ``nu >= 1e4`` takes :func:`_expansion`)."""
    f = _density(nu, t, log_ratio)
    a, tt = 0.5 * nu, t * t
    y = tt / (nu + tt)
    series = y <= np.minimum(0.5, 4.5 / (a + 2.5))
    out = np.empty_like(t)
    if series.any():
        s = series
        out[s] = t[s] * f[s] * _central_sum(a[s], y[s]) - centre[s]
    if not series.all():
        s = ~series
        out[s] = tail[s] - t[s] * f[s] * _tail_fraction(a[s], nu[s] / (nu[s] + tt[s])) / nu[s]
    return out, f


def _hill(nu: np.ndarray, tail: np.ndarray) -> np.ndarray:
    """Hill's approximation of the upper quantile ``t > 0`` with ``1 - F(t) = tail`` (Algorithm 396)."""
    a = 1.0 / (nu - 0.5)
    b = 48.0 / (a * a)
    c = ((20700.0 * a / b - 98.0) * a - 16.0) * a + 96.36
    d = ((94.5 / (b + c) - 3.0) / b + 1.0) * np.sqrt(a * math.pi / 2.0) * nu
    y = (d * 2.0 * tail) ** (2.0 / nu)
    x = normal_quantile(tail)  # negative
    c_normal = c + np.where(nu < 5, 0.3 * (nu - 4.5) * (x + 0.6), 0.0)
    c_normal = c_normal + (((0.05 * d * x - 5.0) * x - 7.0) * x - 2.0) * x + b
    near = (((((0.4 * x * x + 6.3) * x * x + 36.0) * x * x + 94.5) / c_normal - x * x - 3.0) / b + 1.0) * x
    near = np.expm1(a * near * near)
    far = (((1.0 / (((nu + 6.0) / (nu * y) - 0.089 * d - 0.822) * (nu + 2.0) * 3.0) + 0.5 / (nu + 4.0)) * y - 1.0)
           * (nu + 1.0) / (nu + 2.0) + 1.0 / y)
    return np.sqrt(nu * np.where(y > 0.05 + a, near, far))


def _upper_quantile(nu: np.ndarray, centre: np.ndarray, tail: np.ndarray) -> np.ndarray:
    """``t >= 0`` with ``F(t) = 1/2 + centre = 1 - tail`` for ``1 < nu < 1e4`` (not 2): Hill's start
    (the linear one near the centre), Halley's steps to 1e-13 relative, then one more."""
    log_ratio = _log_gamma_ratio(0.5 * nu)
    # near the centre Hill's start is far off (0.24 for t = 3e-12 at nu = 1): there F - 1/2 ~ f(0) t
    t = np.where(centre < 0.05, centre / _density(nu, np.zeros_like(nu), log_ratio), _hill(nu, tail))
    for _ in range(20):
        r, f = _residual(nu, t, centre, tail, log_ratio)
        newton = r / f
        # Halley's step, with f'/f = -(nu + 1) t / (nu + t^2)
        step = newton / (1.0 + newton * (nu + 1.0) * t / (2.0 * (nu + t * t)))
        t = np.maximum(t - step, 0.5 * t)
        if not np.any(np.abs(step) > 1e-13 * t):
            break
    return t


def _expansion(nu: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The quantile for large ``nu`` from the normal one ``z`` (Abramowitz & Stegun 26.7.5, Fisher's
    expansion to ``nu^-4``; the next term is below 1e-16 relative for ``nu >= 1e4``, ``|z| <= 4``)."""
    z2 = z * z
    g1 = (z2 + 1.0) * z / 4.0
    g2 = ((5.0 * z2 + 16.0) * z2 + 3.0) * z / 96.0
    g3 = (((3.0 * z2 + 19.0) * z2 + 17.0) * z2 - 15.0) * z / 384.0
    g4 = ((((79.0 * z2 + 776.0) * z2 + 1482.0) * z2 - 1920.0) * z2 - 945.0) * z / 92160.0
    return z + (g1 + (g2 + (g3 + g4 / nu) / nu) / nu) / nu


def student_t_quantile(dof: np.ndarray | float, p: np.ndarray | float) -> np.ndarray:
    """Quantile ``t`` with ``P(T <= t) = p`` of Student's t with ``dof`` degrees of freedom (real,
    >= 1; ``inf``: normal), broadcast; NaN where ``dof`` or ``p`` is NaN, ``-inf``/``inf`` at ``p`` = 0/1.

    Raises
    ------
    ValueError
        ``p`` outside [0, 1] or ``dof`` below 1 (the intervals take at least one degree of freedom;
        Hill's start is not made for fewer).
    """
    dof, p = np.broadcast_arrays(np.asarray(dof, dtype=float), np.asarray(p, dtype=float))
    if np.any((p < 0) | (p > 1)):
        raise ValueError(f"p = {float(p[(p < 0) | (p > 1)].ravel()[0]):.6g}: expected a probability in [0, 1]")
    if np.any(dof < 1):
        raise ValueError(f"dof = {float(dof[dof < 1].ravel()[0]):.6g}: expected degrees of freedom >= 1")
    centre = np.abs(p - 0.5)  # exact for p in [1/4, 1]; the other side by symmetry
    tail = np.where(p < 0.5, p, 1.0 - p)  # exact
    out = np.full(dof.shape, np.nan)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        one, two = dof == 1, dof == 2
        out[one] = np.where(centre[one] < 0.25, np.tan(math.pi * centre[one]), 1.0 / np.tan(math.pi * tail[one]))
        out[two] = centre[two] * np.sqrt(2.0 / (tail[two] * (1.0 - tail[two])))
        out[np.isposinf(dof)] = np.abs(normal_quantile(p[np.isposinf(dof)]))
        rest = np.isfinite(dof) & ~one & ~two & (tail > 0) & (centre > 0) & ~np.isnan(p)
        large = rest & (dof >= _EXPANSION_FROM)
        out[large] = _expansion(dof[large], np.abs(normal_quantile(p[large])))
        rest &= ~large
        if rest.any():
            out[rest] = _upper_quantile(dof[rest], centre[rest], tail[rest])
        out[(centre == 0) & ~np.isnan(dof)] = 0.0
        out[(tail == 0) & ~np.isnan(dof)] = np.inf
    return np.copysign(out, p - 0.5).reshape(dof.shape) if out.ndim else float(np.copysign(out, p - 0.5))
